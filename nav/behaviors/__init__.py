"""Recovery behaviours (Nav2 ``nav2_behaviors``): spin, spin until matched, relocalize, back up, drive on
heading, wait and clear costmaps, each behind the :class:`Behavior` interface, plus a registry that
builds them by name from plain parameters (what the recovery policy's configuration holds)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any

from nav.behaviors.base import (
    Behavior,
    BehaviorConfigError,
    BehaviorContext,
    BehaviorLimits,
    Status,
    collision_threshold,
    first_collision,
)
from nav.behaviors.clear_costmap import ClearCostmap, ClearCostmapOptions
from nav.behaviors.drive_on_heading import BackUp, BackUpOptions, DriveOnHeading, DriveOnHeadingOptions
from nav.behaviors.spin import (
    Relocalize,
    RelocalizeOptions,
    Spin,
    SpinOptions,
    SpinUntilMatched,
    SpinUntilMatchedOptions,
)
from nav.behaviors.wait import Wait, WaitForWalker, WaitForWalkerOptions, WaitOptions

#: name -> (options class, fixed option values, constructor)
REGISTRY: dict[str, tuple[type, dict[str, Any], Callable[[Any], Behavior]]] = {
    "clear_local_costmap": (ClearCostmapOptions, {"costmap": "local"}, ClearCostmap),
    "clear_global_costmap": (ClearCostmapOptions, {"costmap": "global"}, ClearCostmap),
    "clear_costmaps": (ClearCostmapOptions, {"costmap": "both"}, ClearCostmap),
    "spin": (SpinOptions, {}, Spin),
    "spin_until_matched": (SpinUntilMatchedOptions, {}, SpinUntilMatched),
    "relocalize": (RelocalizeOptions, {}, Relocalize),
    "wait": (WaitOptions, {}, Wait),
    "wait_for_walker": (WaitForWalkerOptions, {}, WaitForWalker),
    "back_up": (BackUpOptions, {}, BackUp),
    "drive_on_heading": (DriveOnHeadingOptions, {}, DriveOnHeading),
}

BEHAVIOR_NAMES: tuple[str, ...] = tuple(REGISTRY)


def behavior_options(name: str, params: Mapping[str, Any] | None = None, where: str = "") -> Any:
    """Validated options for behaviour ``name`` from plain ``params``.

    Raises :class:`BehaviorConfigError` naming the behaviour or field (prefixed by ``where``) for an
    unknown behaviour, an unknown parameter or an out-of-range value.
    """
    prefix = f"{where}." if where else ""
    if name not in REGISTRY:
        raise BehaviorConfigError(
            f"{prefix}behavior: unknown behaviour {name!r}; known: {', '.join(BEHAVIOR_NAMES)}"
        )
    cls, fixed, _ = REGISTRY[name]
    params = dict(params or {})
    known = {f.name for f in fields(cls)} - set(fixed)
    bad = sorted(set(params) - known)
    if bad:
        raise BehaviorConfigError(
            f"{prefix}{name}.{bad[0]}: unknown parameter; known: {', '.join(sorted(known))}"
        )
    try:
        return cls(**params, **fixed)
    except BehaviorConfigError as exc:
        raise BehaviorConfigError(f"{prefix}{exc}") from exc
    except TypeError as exc:
        raise BehaviorConfigError(f"{prefix}{name}: {exc}") from exc


def make_behavior(name: str, params: Mapping[str, Any] | None = None) -> Behavior:
    """A fresh behaviour by registry name (see :data:`BEHAVIOR_NAMES`)."""
    options = behavior_options(name, params)
    return REGISTRY[name][2](options)


__all__ = [
    "BEHAVIOR_NAMES",
    "REGISTRY",
    "BackUp",
    "BackUpOptions",
    "Behavior",
    "BehaviorConfigError",
    "BehaviorContext",
    "BehaviorLimits",
    "ClearCostmap",
    "ClearCostmapOptions",
    "DriveOnHeading",
    "DriveOnHeadingOptions",
    "Relocalize",
    "RelocalizeOptions",
    "Spin",
    "SpinOptions",
    "SpinUntilMatched",
    "SpinUntilMatchedOptions",
    "Status",
    "Wait",
    "WaitForWalker",
    "WaitForWalkerOptions",
    "WaitOptions",
    "behavior_options",
    "collision_threshold",
    "first_collision",
    "make_behavior",
]
