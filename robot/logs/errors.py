"""The one error type of the log readers."""

from __future__ import annotations


class LogError(ValueError):
    """A log that cannot be read or holds no usable scans."""
