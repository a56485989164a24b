"""Local control: the DWA/DWB controller, its critics, and Nav2's goal and progress checkers."""

from __future__ import annotations

from typing import Any, Protocol

from nav.control.dwa import DwaController, DwaDebug
from nav.control.errors import ControllerError, InvalidPath, NoValidControl, PatienceExceeded
from nav.control.goal_checker import GoalChecker, GoalCheckerOptions
from nav.control.options import DWB_CRITICS, FOX_CRITICS, DwaOptions
from nav.control.progress_checker import ProgressChecker, ProgressCheckerOptions
from nav.types import Costmap, Path, Pose2D, Twist2D


class Controller(Protocol):
    """A local controller (``nav2_core::Controller``): follow a path, one command per cycle."""

    def set_path(self, path: Path) -> None: ...
    def compute(self, pose: Pose2D, velocity: Twist2D, costmap: Costmap) -> tuple[Twist2D, Any]: ...
    def reset(self) -> None: ...


def prepare_retry(controller: Controller) -> None:
    """Ready ``controller`` to follow the same goal again after a recovery (Nav2 sends a fresh
    FollowPath): DWA and TEB start their failure count (``failure_tolerance``) over and DWA re-arms
    its goal window (``prepare_retry``); a controller without these has nothing to ready."""
    prepare = getattr(controller, "prepare_retry", None)
    if callable(prepare):
        prepare()


__all__ = [
    "DWB_CRITICS",
    "FOX_CRITICS",
    "Controller",
    "ControllerError",
    "DwaController",
    "DwaDebug",
    "DwaOptions",
    "GoalChecker",
    "GoalCheckerOptions",
    "InvalidPath",
    "NoValidControl",
    "PatienceExceeded",
    "ProgressChecker",
    "ProgressCheckerOptions",
    "prepare_retry",
]
