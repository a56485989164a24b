"""Errors shared by the runtime and the API layer (kept here so neither imports the other for them)."""

from __future__ import annotations


class FeatureUnavailable(LookupError):
    """A request needs a feature this server has not set up (the API answers 503)."""

    def __init__(self, kind: type) -> None:
        self.name = kind.__name__.lower()
        super().__init__(f"{self.name} is not running on this server")
