"""Localization on a known map: Augmented MCL with KLD sampling (Nav2 ``amcl`` equivalent)."""

from nav.localization.amcl import (
    Amcl,
    AmclStatus,
    InvalidCovarianceError,
    LocalizationError,
    NoFreeSpaceError,
    NotInitializedError,
)
from nav.localization.options import AmclConfigError, AmclOptions

__all__ = [
    "Amcl",
    "AmclConfigError",
    "AmclOptions",
    "AmclStatus",
    "InvalidCovarianceError",
    "LocalizationError",
    "NoFreeSpaceError",
    "NotInitializedError",
]
