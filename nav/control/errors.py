"""Typed controller failures, named after Nav2's ``nav2_core`` controller exceptions.

The navigator reacts to *why* the controller failed: a single ``NoValidControl`` cycle is tolerated
(the robot is stopped and the path replanned), ``PatienceExceeded`` (failures lasting longer than
``failure_tolerance``) hands over to recovery behaviours.
"""

from __future__ import annotations


class ControllerError(Exception):
    """Base of every controller failure (``nav2_core::ControllerException``)."""


class InvalidPath(ControllerError):
    """The path given to ``set_path`` is empty or not finite (``nav2_core::InvalidPath``)."""


class NoValidControl(ControllerError):
    """Every sampled trajectory was rejected by a critic, e.g. all of them collide
    (``nav2_core::NoValidControl``; DWB's ``NoLegalTrajectoriesException``).

    ``rejections`` counts rejected trajectories per critic name, so the caller can say why.
    """

    def __init__(self, message: str, rejections: dict[str, int] | None = None) -> None:
        super().__init__(message)
        self.rejections: dict[str, int] = dict(rejections or {})


class PatienceExceeded(NoValidControl):
    """No valid control for longer than ``failure_tolerance`` (``nav2_core::PatienceExceeded``)."""


__all__ = ["ControllerError", "InvalidPath", "NoValidControl", "PatienceExceeded"]
