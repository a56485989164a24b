"""A float timestamp that remembers the exact text it came from.

Log timestamps carry more digits (ROS: sec + 9-digit nanosec) than a float64 keeps, and the SLAM
benchmark's relations name scans by their printed stamp, so the text must survive unchanged.
"""

from __future__ import annotations


class Stamp(float):
    """``float`` seconds whose ``str()`` is the original log text (e.g. ``"976052905.167303"``)."""

    text: str

    def __new__(cls, text: str) -> Stamp:
        obj = super().__new__(cls, float(text))
        obj.text = text
        return obj

    @classmethod
    def from_ros(cls, sec: int, nanosec: int) -> Stamp:
        """From a builtin_interfaces/Time, printed as ``sec.nnnnnnnnn``."""
        return cls(f"{int(sec)}.{int(nanosec):09d}")

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return f"Stamp({self.text!r})"

    def __reduce__(self) -> tuple:
        return (Stamp, (self.text,))
