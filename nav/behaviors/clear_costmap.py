"""Clear costmaps (Nav2 ``ClearEntireCostmap`` service on the local, global or both costmaps).

Clearing drops obstacles that were marked and never cleared again (a person who walked away, a
ghost from a bad scan), which is the cheapest recovery and the first in Nav2's default tree. The
clearing itself happens through callbacks in the context, so this module stays pure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from nav.behaviors.base import BehaviorConfigError, BehaviorContext, Status, TimedBehavior

Which = Literal["local", "global", "both"]


@dataclass(frozen=True)
class ClearCostmapOptions:
    """Which costmap(s) to clear."""

    costmap: Which = "local"
    """``local``, ``global`` or ``both`` (Nav2 BT nodes ClearLocalCostmap / ClearGlobalCostmap)."""

    def __post_init__(self) -> None:
        if self.costmap not in ("local", "global", "both"):
            raise BehaviorConfigError(
                f"clear_costmap.costmap must be local, global or both, got {self.costmap!r}"
            )


class ClearCostmap(TimedBehavior):
    """Call the context's clear callback(s) once and succeed; fail if one is missing or raises."""

    def __init__(self, options: ClearCostmapOptions | None = None) -> None:
        self.options = options or ClearCostmapOptions()
        super().__init__(0.0)
        self.name = {"local": "clear_local_costmap", "global": "clear_global_costmap"}.get(
            self.options.costmap, "clear_costmaps"
        )
        self._status = Status.RUNNING

    def start(self, ctx: BehaviorContext) -> Status:
        self._begin(ctx)
        which = self.options.costmap
        callbacks = []
        if which in ("local", "both"):
            callbacks.append(("local", ctx.clear_local_costmap))
        if which in ("global", "both"):
            callbacks.append(("global", ctx.clear_global_costmap))
        for label, cb in callbacks:
            if cb is None:
                self._status = self._fail(f"{self.name}: no {label} costmap clear callback")
                return self._status
            try:
                cb()
            except Exception as exc:  # a callback failing is a behaviour failure, not a crash
                self._status = self._fail(f"{self.name}: clearing the {label} costmap failed: {exc}")
                return self._status
        self._status = self._succeed()
        return self._status

    def tick(self, ctx: BehaviorContext) -> Status:
        self._require_started()
        return self._status


__all__ = ["ClearCostmap", "ClearCostmapOptions"]
