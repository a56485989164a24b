"""Drive straight along the current heading for a distance (Nav2 ``DriveOnHeading``); back up is the
same motion backwards (Nav2 ``BackUp`` derives from it).

Each cycle the straight segment still ahead, up to ``simulate_ahead_time`` of motion, is
footprint-checked against the local costmap (Nav2's ``isCollisionFree``); the behaviour refuses to
start when the whole segment is blocked at the start and halts with FAILED as soon as an obstacle
appears ahead. The speed ramps up within ``acceleration_limit`` and down as
``sqrt(2 |deceleration_limit| remaining)`` so the robot stops on the target distance (Nav2 Jazzy's
``applyConstraints``), never below ``minimum_speed`` where the base would stall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav.behaviors.base import (
    BehaviorConfigError,
    BehaviorContext,
    Status,
    TimedBehavior,
    check_non_negative,
    check_positive,
    first_collision,
)
from nav.types import Pose2D, Twist2D


@dataclass(frozen=True)
class DriveOnHeadingOptions:
    """Nav2 behavior_server parameters for drive_on_heading, plus its goal's fields."""

    dist_to_travel: float = 0.15
    """Distance to drive forward, m (the BT's ``dist_to_travel``; Nav2 BT 0.15)."""
    speed: float = 0.025
    """Cruise speed, m/s (the BT's ``speed``; Nav2 BT 0.025)."""
    time_allowance: float = 10.0
    """Give up after this long, s (goal ``time_allowance``; Nav2 10.0)."""
    simulate_ahead_time: float = 2.0
    """How far ahead (s) the motion is collision-checked. Nav2 2.0."""
    acceleration_limit: float = 2.5
    """Speed-up limit, m/s^2. Nav2 2.5."""
    deceleration_limit: float = -2.5
    """Slow-down limit (negative), m/s^2. Nav2 -2.5."""
    minimum_speed: float = 0.10
    """Slowest speed commanded while moving, m/s. Nav2 0.10."""
    cycle_frequency: float = 10.0
    """Rate the behaviour runs at, Hz; also the collision-check step. Nav2 behavior_server 10.0."""

    _owner = "drive_on_heading"

    def __post_init__(self) -> None:
        o = self._owner
        check_non_negative(o, **{self._dist_field: self.distance, self._speed_field: self.cruise_speed})
        check_non_negative(o, simulate_ahead_time=self.simulate_ahead_time, minimum_speed=self.minimum_speed)
        check_positive(
            o,
            time_allowance=self.time_allowance,
            acceleration_limit=self.acceleration_limit,
            cycle_frequency=self.cycle_frequency,
        )
        if not (math.isfinite(self.deceleration_limit) and self.deceleration_limit < 0):
            raise BehaviorConfigError(
                f"{o}.deceleration_limit must be negative, got {self.deceleration_limit!r}"
            )

    _dist_field = "dist_to_travel"
    _speed_field = "speed"

    @property
    def distance(self) -> float:
        return self.dist_to_travel

    @property
    def cruise_speed(self) -> float:
        return self.speed


@dataclass(frozen=True)
class BackUpOptions(DriveOnHeadingOptions):
    """Nav2 back_up options: the BT's ``backup_dist``/``backup_speed`` (both given as positive
    magnitudes here; the motion is always backwards)."""

    backup_dist: float = 0.30
    """Distance to reverse, m (Nav2 BT 0.30)."""
    backup_speed: float = 0.15
    """Reversing speed, m/s (Nav2 BT 0.15)."""

    _owner = "back_up"
    _dist_field = "backup_dist"
    _speed_field = "backup_speed"

    @property
    def distance(self) -> float:
        return self.backup_dist

    @property
    def cruise_speed(self) -> float:
        return self.backup_speed


class DriveOnHeading(TimedBehavior):
    """Drive ``distance`` straight along the heading held at start; ``direction`` +1 or -1."""

    name = "drive_on_heading"
    direction = 1.0

    def __init__(self, options: DriveOnHeadingOptions | None = None) -> None:
        self.options = options or DriveOnHeadingOptions()
        super().__init__(self.options.time_allowance)
        self.initial: Pose2D = Pose2D()
        self.travelled = 0.0
        self._speed = 0.0
        self._last_t = 0.0

    def _speed_limit(self, ctx: BehaviorContext) -> float:
        lim = ctx.limits.max_vel_x if self.direction > 0 else -ctx.limits.min_vel_x
        return min(self.options.cruise_speed, max(lim, 0.0))

    def _segment_poses(self, along: np.ndarray) -> np.ndarray:
        """Poses at distances ``along`` from the start pose, in the direction of motion."""
        p = self.initial
        d = self.direction * along
        return np.column_stack(
            (p.x + d * math.cos(p.theta), p.y + d * math.sin(p.theta), np.full(along.shape, p.theta))
        )

    def _blocked(self, ctx: BehaviorContext, lo: float, hi: float) -> int:
        if hi <= lo:
            return -1
        step = 0.5 * ctx.costmap.geometry.resolution if ctx.costmap is not None else 0.025
        along = np.linspace(lo, hi, max(math.ceil((hi - lo) / step) + 1, 2))
        return first_collision(ctx, self._segment_poses(along))

    def start(self, ctx: BehaviorContext) -> Status:
        self._begin(ctx)
        self.initial = ctx.pose
        self.travelled = 0.0
        self._speed = 0.0
        self._last_t = ctx.now
        if ctx.costmap is None:
            return self._fail(f"{self.name}: no costmap to check the motion against")
        if self._speed_limit(ctx) <= 0.0 and self.options.distance > 0:
            return self._fail(f"{self.name}: the base's velocity limits do not allow this motion")
        if self._blocked(ctx, 0.0, self.options.distance) >= 0:
            return self._fail(f"{self.name}: refusing to start, the footprint hits an obstacle ahead")
        return self._step(ctx)

    def tick(self, ctx: BehaviorContext) -> Status:
        self._require_started()
        self.travelled = ctx.pose.distance_to(self.initial)
        return self._step(ctx)

    def _step(self, ctx: BehaviorContext) -> Status:
        o = self.options
        remaining = o.distance - self.travelled
        if remaining <= 1e-3:
            return self._succeed()
        if self._timed_out(ctx):
            return self._fail(f"{self.name}: time allowance {o.time_allowance:g} s exceeded")
        dt = max(ctx.now - self._last_t, 1.0 / o.cycle_frequency)
        self._last_t = ctx.now
        v = min(
            self._speed_limit(ctx),
            self._speed + o.acceleration_limit * dt,
            math.sqrt(2.0 * -o.deceleration_limit * remaining),
        )
        v = max(v, min(o.minimum_speed, self._speed_limit(ctx)))
        ahead = min(self.travelled + v * o.simulate_ahead_time, o.distance)
        if self._blocked(ctx, self.travelled, ahead) >= 0:
            self._speed = 0.0
            return self._fail(f"{self.name}: collision ahead, halted after {self.travelled:.2f} m")
        self._speed = v
        self.command = Twist2D(self.direction * v, 0.0, 0.0)
        return Status.RUNNING


class BackUp(DriveOnHeading):
    """Reverse ``backup_dist`` at ``backup_speed`` (Nav2 ``BackUp``)."""

    name = "back_up"
    direction = -1.0

    def __init__(self, options: BackUpOptions | None = None) -> None:
        super().__init__(options or BackUpOptions())


__all__ = ["BackUp", "BackUpOptions", "DriveOnHeading", "DriveOnHeadingOptions"]
