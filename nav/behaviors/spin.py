"""Spin in place: by a given angle (Nav2 ``nav2_behaviors::Spin``), until the scan matches the
map again (source A's recovery when odometry drift makes the scan disagree with the map), or after
restarting localization from scratch (a kidnapped robot: AMCL's ``reinitialize_global_localization``
service, then the same spin).

Speed profile and collision check follow Nav2's ``Spin::onCycleUpdate``: the commanded rate is
``sqrt(2 * rotational_acc_lim * remaining_yaw)`` clamped to [min_rotational_vel,
max_rotational_vel], so the robot decelerates into the target angle, and the rotation over the next
``simulate_ahead_time`` seconds is footprint-checked against the local costmap every cycle. Nav2
checks a pose every 1 / cycle_frequency s; here the whole swept footprint is (poses close enough that
no footprint point moves more than half a cell between them): a rectangular base's corner moves
6 cm in 0.1 s at 1 rad/s (0.51 x 0.43 m base) and would pass a 5 cm post between two checked poses.
The angle turned is accumulated from wrapped yaw differences, so turns larger than pi are measured
correctly.
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
from nav.control.footprint import swept_turn
from nav.types import Twist2D, wrap_angle


@dataclass(frozen=True)
class SpinOptions:
    """Nav2 behavior_server parameters for spin, plus the Spin action goal's fields."""

    spin_dist: float = 1.57
    """Angle to turn, rad; positive is counter-clockwise (the BT's ``spin_dist``; Nav2 BT 1.57)."""
    time_allowance: float = 10.0
    """Give up after this long, s (Spin goal ``time_allowance``; Nav2 10.0)."""
    simulate_ahead_time: float = 2.0
    """How far ahead (s) the rotation is collision-checked. Nav2 2.0."""
    max_rotational_vel: float = 1.0
    """Fastest turn rate, rad/s. Nav2 1.0."""
    min_rotational_vel: float = 0.4
    """Slowest turn rate (below it the base stalls), rad/s. Nav2 0.4."""
    rotational_acc_lim: float = 3.2
    """Deceleration used to approach the target angle, rad/s^2. Nav2 3.2."""
    cycle_frequency: float = 10.0
    """Rate the behaviour runs at, Hz; also the collision-check step. Nav2 behavior_server 10.0."""

    def __post_init__(self) -> None:
        if not math.isfinite(self.spin_dist):
            raise BehaviorConfigError(f"spin.spin_dist must be finite, got {self.spin_dist!r}")
        check_non_negative("spin", simulate_ahead_time=self.simulate_ahead_time)
        check_positive(
            "spin",
            time_allowance=self.time_allowance,
            max_rotational_vel=self.max_rotational_vel,
            min_rotational_vel=self.min_rotational_vel,
            rotational_acc_lim=self.rotational_acc_lim,
            cycle_frequency=self.cycle_frequency,
        )
        if self.min_rotational_vel > self.max_rotational_vel:
            raise BehaviorConfigError("spin.min_rotational_vel must not exceed spin.max_rotational_vel")


@dataclass(frozen=True)
class SpinUntilMatchedOptions(SpinOptions):
    """Spin options for "spin until the scan matches the map again" (source A)."""

    spin_dist: float = 2.0 * math.pi
    """Largest turn, rad: one full turn by default, after which the behaviour fails."""
    time_allowance: float = 30.0
    """Give up after this long, s (a full turn at min_rotational_vel takes ~16 s)."""
    match_score_threshold: float = 0.6
    """Stop (succeed) once the scan-to-map match score reaches this, in [0, 1]..."""
    min_turn: float = 0.0
    """...after turning at least this far (rad): one view can fit a look-alike place (the
    apartment's rooms), and the turn shows the filter the rest of the room first."""

    _owner = "spin_until_matched"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 <= self.match_score_threshold <= 1.0:
            raise BehaviorConfigError(
                f"{self._owner}.match_score_threshold must be in [0, 1], got {self.match_score_threshold!r}"
            )
        if not (math.isfinite(self.min_turn) and 0.0 <= self.min_turn <= abs(self.spin_dist)):
            raise BehaviorConfigError(
                f"{self._owner}.min_turn must be in [0, |spin_dist|], got {self.min_turn!r}"
            )


class Spin(TimedBehavior):
    """Turn in place by ``options.spin_dist`` (sign gives the direction)."""

    name = "spin"

    check_collisions = True
    """Test the turn against the costmap at the estimated pose (Nav2 Spin::isCollisionFree)."""

    def __init__(self, options: SpinOptions | None = None) -> None:
        self.options = options or SpinOptions()
        super().__init__(self.options.time_allowance)
        self.turned = 0.0  # signed angle turned since start, rad
        self._prev_yaw = 0.0

    @property
    def target(self) -> float:
        return self.options.spin_dist

    def start(self, ctx: BehaviorContext) -> Status:
        self._begin(ctx)
        self.turned = 0.0
        self._prev_yaw = ctx.pose.theta
        return self._step(ctx)

    def tick(self, ctx: BehaviorContext) -> Status:
        self._require_started()
        self.turned += float(wrap_angle(ctx.pose.theta - self._prev_yaw))
        self._prev_yaw = ctx.pose.theta
        return self._step(ctx)

    def _done(self, ctx: BehaviorContext) -> Status | None:
        """Hook for subclasses: a terminal status, or None to keep turning."""
        return None

    def _step(self, ctx: BehaviorContext) -> Status:
        o = self.options
        done = self._done(ctx)
        if done is not None:
            return done
        remaining = abs(self.target) - abs(self.turned)
        if remaining < 1e-3:
            return self._succeed()
        if self._timed_out(ctx):
            return self._fail(f"spin: time allowance {o.time_allowance:g} s exceeded")
        vmax = min(o.max_rotational_vel, ctx.limits.max_vel_theta)
        vel = min(max(math.sqrt(2.0 * o.rotational_acc_lim * remaining), o.min_rotational_vel), vmax)
        wz = math.copysign(vel, self.target)
        # Nav2 Spin::isCollisionFree over simulate_ahead_time, never beyond the target angle, on the
        # swept footprint
        if self.check_collisions and ctx.costmap is not None:
            ahead = min(vel * max(o.simulate_ahead_time, 1.0 / o.cycle_frequency), remaining)
            reach = float(np.max(np.hypot(*ctx.footprint.T))) if ctx.footprint is not None else 0.0
            step = 0.5 * ctx.costmap.geometry.resolution
            poses = swept_turn(ctx.pose.as_array(), math.copysign(ahead, wz), reach, step)[1:]
            if first_collision(ctx, poses) >= 0:
                return self._fail("spin: collision ahead")
        self.command = Twist2D(0.0, 0.0, wz)
        return Status.RUNNING


class SpinUntilMatched(Spin):
    """Turn in place until ``ctx.scan_match_score()`` reaches ``match_score_threshold`` (success) or
    ``spin_dist`` (a full turn) has been turned without a match (failure). Source A: "when odometry
    drifts and the scan no longer matches the map, the robot spins in place until the scan matches
    the map best again"; turning shows the lidar new structure and lets the particle filter update.
    """

    name = "spin_until_matched"

    def __init__(self, options: SpinUntilMatchedOptions | None = None) -> None:
        super().__init__(options or SpinUntilMatchedOptions())
        self.best_score = -math.inf
        self.best_angle = 0.0

    def start(self, ctx: BehaviorContext) -> Status:
        if ctx.scan_match_score is None:
            self._begin(ctx)
            return self._fail("spin_until_matched: no scan match score in the context")
        self.best_score, self.best_angle = -math.inf, 0.0
        return super().start(ctx)

    def _done(self, ctx: BehaviorContext) -> Status | None:
        assert ctx.scan_match_score is not None
        score = float(ctx.scan_match_score())
        if score > self.best_score:
            self.best_score, self.best_angle = score, self.turned
        o = self.options
        assert isinstance(o, SpinUntilMatchedOptions)
        if score >= o.match_score_threshold and abs(self.turned) >= o.min_turn - 1e-3:
            return self._succeed()
        if abs(self.turned) >= abs(self.target) - 1e-3:
            return self._fail(
                f"spin_until_matched: no match after {abs(self.turned):.2f} rad "
                f"(best score {self.best_score:.2f} < {o.match_score_threshold:g})"
            )
        return None


@dataclass(frozen=True)
class RelocalizeOptions(SpinUntilMatchedOptions):
    """Options of "relocalize": up to two turns, matched only after a whole one."""

    spin_dist: float = 4.0 * math.pi
    """Largest turn, rad (two turns)."""
    time_allowance: float = 45.0
    """Give up after this long, s."""
    match_score_threshold: float = 0.75
    """Succeed once the match score reaches this (a localized robot: 0.77-1.0 in the scenario
    sets)..."""
    min_turn: float = 2.0 * math.pi
    """...after a whole turn: the filter starts from the whole map, and a look-alike place wins
    on one view more often than on all of them."""

    _owner = "relocalize"


class Relocalize(SpinUntilMatched):
    """Restart localization over the whole map (``ctx.reinitialize_localization``, Nav2 amcl's
    ``reinitialize_global_localization`` service), then turn in place until the scan matches the
    map again. For a robot carried somewhere else (kidnapped): particles near the old estimate,
    where spin_until_matched searches, cannot explain where it is now."""

    name = "relocalize"
    check_collisions = False
    """After the reinitialize the estimate says nothing about where the walls are (a lost robot's
    estimate may even sit inside one); the safety layer in the driver path, on the real ranges,
    still stops a turn that would touch something."""

    def __init__(self, options: RelocalizeOptions | None = None) -> None:
        super().__init__(options or RelocalizeOptions())

    def start(self, ctx: BehaviorContext) -> Status:
        if ctx.reinitialize_localization is None:
            self._begin(ctx)
            return self._fail("relocalize: no way to reinitialize localization in the context")
        ctx.reinitialize_localization()
        return super().start(ctx)


__all__ = [
    "Relocalize",
    "RelocalizeOptions",
    "Spin",
    "SpinOptions",
    "SpinUntilMatched",
    "SpinUntilMatchedOptions",
]
