"""Velocity limiting: every command to the driver passes through here, whoever produced it.

The profile's speed limits are clamped, then its acceleration limits are applied per control period
(the dynamic window the base can actually follow). Each limited component is reported so the
operator sees why the robot is slower than asked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nav.types import Twist2D
from robot.profiles import Limits

SANITY_FACTOR = 2.0
"""A command component beyond this many times the profile's limit is refused, not clamped: it is a
mistake (mm/s sent as m/s, an overflow, a bug), and driving at top speed on it would be a guess."""


class CommandRefused(ValueError):
    """A velocity command beyond the sanity bound (``sanity_check``); the robot was stopped."""

    def __init__(self, beyond: dict[str, tuple[float, float]]) -> None:
        self.beyond = beyond  # component -> (value, bound)
        parts = ", ".join(f"{k} = {v:.6g} (bound ±{b:.3g})" for k, (v, b) in beyond.items())
        super().__init__(
            f"{parts} is beyond {SANITY_FACTOR:g}x the profile's limit (units are m/s and rad/s): "
            "command refused, robot stopped"
        )

    def as_dict(self) -> dict:
        return {
            "error": str(self),
            "status": 422,
            "refused": {k: {"value": v, "bound": b} for k, (v, b) in self.beyond.items()},
        }


def sanity_bounds(limits: Limits, omni: bool) -> tuple[float, float, float]:
    """(|vx|, |vy|, |wz|) beyond which a command is refused: ``SANITY_FACTOR`` x the top speed of each
    component, forwards or backwards. A base without a y axis clamps vy to 0 (reported, as any clamp)
    and refuses it only beyond the bound of its linear speed."""
    top_x = max(limits.max_vel_x, abs(limits.min_vel_x))
    top_y = limits.max_vel_y if omni and limits.max_vel_y > 0 else top_x
    return SANITY_FACTOR * top_x, SANITY_FACTOR * top_y, SANITY_FACTOR * limits.max_vel_theta


def sanity_check(cmd: Twist2D, limits: Limits, omni: bool) -> None:
    """Raise ``CommandRefused`` naming every component beyond its sanity bound (NaN and inf included)."""
    beyond = {
        name: (value, bound)
        for name, value, bound in zip(
            ("linear.x", "linear.y", "angular.z"), _xyz(cmd), sanity_bounds(limits, omni), strict=True
        )
        if not abs(value) <= bound  # NaN compares false: refused too
    }
    if beyond:
        raise CommandRefused(beyond)


def clamp_speed(cmd: Twist2D, limits: Limits, omni: bool) -> tuple[Twist2D, tuple[str, ...]]:
    clamped: list[str] = []
    vx = min(max(cmd.vx, limits.min_vel_x if limits.min_vel_x < 0 else -limits.max_vel_x), limits.max_vel_x)
    if vx != cmd.vx:
        clamped.append("linear.x")
    max_vy = limits.max_vel_y if omni else 0.0
    vy = min(max(cmd.vy, -max_vy), max_vy)
    if vy != cmd.vy:
        clamped.append("linear.y")
    wz = min(max(cmd.wz, -limits.max_vel_theta), limits.max_vel_theta)
    if wz != cmd.wz:
        clamped.append("angular.z")
    return Twist2D(vx, vy, wz), tuple(clamped)


def _ramp(target: float, current: float, acc: float, decel: float, dt: float) -> float:
    """Move ``current`` toward ``target`` by at most acc*dt when speeding up, |decel|*dt when slowing."""
    speeding_up = abs(target) > abs(current) and (target * current >= 0)
    step = (acc if speeding_up else abs(decel) or acc) * dt
    if step <= 0 or not math.isfinite(step):
        return target
    return current + min(max(target - current, -step), step)


def _xyz(v: Twist2D) -> tuple[float, float, float]:
    return v.vx, v.vy, v.wz


def _axes(limits: Limits) -> tuple[tuple[float, float], ...]:
    """(acceleration, deceleration) per axis vx, vy, wz; vy falls back to the x limits."""
    return (
        (limits.acc_lim_x, limits.decel_lim_x),
        (limits.acc_lim_y or limits.acc_lim_x, limits.decel_lim_y or limits.decel_lim_x),
        (limits.acc_lim_theta, limits.decel_lim_theta),
    )


def limit_acceleration(cmd: Twist2D, previous: Twist2D, limits: Limits, dt: float) -> Twist2D:
    return Twist2D(
        *(
            _ramp(target, current, acc, decel, dt)
            for target, current, (acc, decel) in zip(_xyz(cmd), _xyz(previous), _axes(limits), strict=True)
        )
    )


def ramp_duration(target: Twist2D, current: Twist2D, limits: Limits) -> float:
    """Seconds :func:`limit_acceleration` needs at most to bring ``current`` to ``target`` (each axis at
    the slower of its two rates, so the ramp is certainly complete by then)."""
    return max(
        (
            abs(t - c) / rate
            for t, c, (acc, decel) in zip(_xyz(target), _xyz(current), _axes(limits), strict=True)
            if (rate := min(acc, abs(decel) or acc)) > 0
        ),
        default=0.0,
    )


@dataclass(frozen=True)
class SpeedLimit:
    """A linear speed limit in force (a speed zone, Nav2 SpeedFilter) and why, for telemetry."""

    linear: float
    """m/s, >= 0: the largest |linear velocity| allowed."""
    reason: str
    """What imposes it, for the operator (e.g. ``speed zone 'aisle': 30 % of 0.50 m/s``)."""


def apply_speed_limit(cmd: Twist2D, limit: SpeedLimit | None) -> tuple[Twist2D, bool]:
    """Scale the whole command so its linear speed is within ``limit`` (True when it was scaled).
    Linear and angular parts scale together so the commanded arc (the path's curvature) is kept."""
    if limit is None:
        return cmd, False
    speed = math.hypot(cmd.vx, cmd.vy)
    if speed <= limit.linear:
        return cmd, False
    k = limit.linear / speed
    return Twist2D(cmd.vx * k, cmd.vy * k, cmd.wz * k), True
