"""Optional pipeline features (mapping, localization, navigation, recording...).

Each module here defines ``setup(runtime)`` that adds its stages to ``runtime.session``, its command
sources and mode guards, and returns an object with ``close()`` (or None). ``ORDER`` (int, default
100) orders the set-up, which is also the order stages run in each tick: lower first.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType


def discover() -> list[ModuleType]:
    mods = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)]
    mods = [m for m in mods if hasattr(m, "setup")]
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.__name__))
