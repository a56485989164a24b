"""The behaviour interface shared by every recovery behaviour (Nav2 ``nav2_behaviors``).

Nav2 runs each behaviour as an action server that publishes ``cmd_vel`` at ``cycle_frequency``
until it succeeds, fails or times out. Here a behaviour is a small state machine the navigator ticks
once per control cycle: ``start(ctx)`` once, then ``tick(ctx)`` until it stops returning RUNNING,
sending ``behavior.command`` to the base after every tick. Everything the behaviour may look at or
act on arrives in a :class:`BehaviorContext` (poses, the local costmap, callbacks that clear the
costmaps or score the scan against the map), so ``nav/`` stays pure: no I/O, no app imports.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any, Protocol

import numpy as np

from nav.costmap.footprint import footprint_cost
from nav.types import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    ZERO_TWIST,
    Costmap,
    Pose2D,
    Twist2D,
)


class Status(Enum):
    """A behaviour's state after a tick (BT.CPP's ``NodeStatus`` without IDLE)."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class BehaviorConfigError(ValueError):
    """A behaviour or recovery option is invalid; the message names the field."""


@dataclass(frozen=True)
class BehaviorLimits:
    """The base's velocity limits the behaviours must respect (SI units; a subset of the profile's
    Nav2 DWB limits)."""

    max_vel_x: float = 0.26
    """Largest forward speed, m/s."""
    min_vel_x: float = -0.26
    """Most negative (backward) speed, m/s."""
    max_vel_theta: float = 1.0
    """Largest |angular velocity|, rad/s."""
    acc_lim_x: float = 2.5
    """Forward acceleration limit, m/s^2."""
    acc_lim_theta: float = 3.2
    """Angular acceleration limit, rad/s^2."""

    @classmethod
    def from_profile(cls, profile: Any) -> BehaviorLimits:
        """Limits of a robot profile (duck-typed ``robot.profiles.RobotProfile``)."""
        lim = profile.limits
        return cls(
            max_vel_x=lim.max_vel_x,
            min_vel_x=lim.min_vel_x,
            max_vel_theta=lim.max_vel_theta,
            acc_lim_x=lim.acc_lim_x,
            acc_lim_theta=lim.acc_lim_theta,
        )


@dataclass
class BehaviorContext:
    """What a behaviour sees each tick. Mutable: the navigator refreshes it every cycle.

    ``pose`` is in the odom frame (behaviours measure their own motion, like Nav2's behaviours do
    through the odom->base_link transform); ``costmap`` is the local costmap in the same frame.
    """

    now: float
    """Current time, s (the robot clock)."""
    pose: Pose2D
    """Robot pose in the odom frame."""
    velocity: Twist2D = ZERO_TWIST
    """Measured body velocity."""
    costmap: Costmap | None = None
    """Local costmap for collision checks; None disables them (behaviours that move refuse)."""
    footprint: np.ndarray | None = None
    """Footprint polygon (K, 2) in base_link; None: a circle scored by its centre cell."""
    limits: BehaviorLimits = BehaviorLimits()
    """Velocity limits of the base."""
    scan_match_score: Callable[[], float] | None = None
    """Scan-to-map match score in [0, 1] (e.g. AMCL's ``quality``), for spin-until-matched."""
    clear_local_costmap: Callable[[], None] | None = None
    """Clears the local costmap's obstacle layer (Nav2 ``ClearEntireCostmap`` on local)."""
    clear_global_costmap: Callable[[], None] | None = None
    """Clears the global costmap's obstacle layer."""
    reinitialize_localization: Callable[[], None] | None = None
    """Restarts localization over the whole map (AMCL ``reinitialize_global_localization``)."""
    walker_on_path: Callable[[], bool] | None = None
    """Whether a tracked walker stands on the path ahead now (for ``wait_for_walker``)."""


class Behavior(Protocol):
    """One recovery behaviour (``nav2_core::Behavior``)."""

    name: str
    command: Twist2D
    """Velocity to send after the last ``start``/``tick``; zero once stopped."""
    reason: str
    """Why the behaviour failed (empty while running or after success)."""

    def start(self, ctx: BehaviorContext) -> Status: ...
    def tick(self, ctx: BehaviorContext) -> Status: ...


def collision_threshold(footprint: np.ndarray | None) -> int:
    """Cost at or above which a pose collides. A polygon is scored by its outline, so only lethal
    cells collide; a circle is scored by its centre cell, which the inflation layer marks
    INSCRIBED_INFLATED_OBSTACLE when the disc touches an obstacle (Nav2's convention)."""
    return LETHAL_OBSTACLE if footprint is not None and len(footprint) else INSCRIBED_INFLATED_OBSTACLE


def first_collision(ctx: BehaviorContext, poses: np.ndarray) -> int:
    """Index of the first of (M, 3) odom-frame poses whose footprint hits an obstacle, or -1.

    Cells off the local costmap read NO_INFORMATION (255) and count as collisions, as in Nav2's
    ``CostmapTopicCollisionChecker`` (a pose it cannot score is not collision-free).
    """
    if ctx.costmap is None or len(poses) == 0:
        return -1
    costs = footprint_cost(ctx.costmap, poses, ctx.footprint)
    hit = costs >= collision_threshold(ctx.footprint)
    return int(np.argmax(hit)) if hit.any() else -1


def check_non_negative(owner: str, **values: float) -> None:
    """Raise :class:`BehaviorConfigError` naming the first negative or non-finite value."""
    for name, v in values.items():
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise BehaviorConfigError(f"{owner}.{name} must be a non-negative number, got {v!r}")


def check_positive(owner: str, **values: float) -> None:
    """Raise :class:`BehaviorConfigError` naming the first value that is not > 0."""
    for name, v in values.items():
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise BehaviorConfigError(f"{owner}.{name} must be a positive number, got {v!r}")


class TimedBehavior:
    """Shared bookkeeping: start time, ``time_allowance`` (Nav2's per-goal timeout), command and
    failure reason."""

    name = "behavior"

    def __init__(self, time_allowance: float) -> None:
        self.time_allowance = time_allowance
        self.command: Twist2D = ZERO_TWIST
        self.reason = ""
        self.started_at: float | None = None

    def _begin(self, ctx: BehaviorContext) -> None:
        self.started_at = ctx.now
        self.command = ZERO_TWIST
        self.reason = ""

    def _fail(self, reason: str) -> Status:
        self.command = ZERO_TWIST
        self.reason = reason
        return Status.FAILED

    def _succeed(self) -> Status:
        self.command = ZERO_TWIST
        self.reason = ""
        return Status.SUCCEEDED

    def _timed_out(self, ctx: BehaviorContext) -> bool:
        return self.started_at is not None and ctx.now - self.started_at > self.time_allowance

    def _require_started(self) -> None:
        if self.started_at is None:
            raise RuntimeError(f"{self.name}: tick called before start")


__all__ = [
    "Behavior",
    "BehaviorConfigError",
    "BehaviorContext",
    "BehaviorLimits",
    "Status",
    "TimedBehavior",
    "check_non_negative",
    "check_positive",
    "collision_threshold",
    "first_collision",
]
