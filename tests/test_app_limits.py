from __future__ import annotations

import pytest

from app.limits import clamp_speed, limit_acceleration
from nav.types import Twist2D
from robot.profiles import load_profile

SKID = load_profile("skid4")
OMNI = load_profile("omni4")


def test_clamp_reports_each_component() -> None:
    lim = SKID.limits
    out, clamped = clamp_speed(Twist2D(5.0, 1.0, -9.0), lim, omni=False)
    assert out == Twist2D(lim.max_vel_x, 0.0, -lim.max_vel_theta)
    assert clamped == ("linear.x", "linear.y", "angular.z")
    out, clamped = clamp_speed(Twist2D(-5.0, 0.0, 0.1), lim, omni=False)
    assert out.vx == lim.min_vel_x and clamped == ("linear.x",)
    out, clamped = clamp_speed(Twist2D(0.1, 0.0, 0.1), lim, omni=False)
    assert clamped == () and out == Twist2D(0.1, 0.0, 0.1)


def test_omni_allows_strafe_within_limits() -> None:
    out, clamped = clamp_speed(Twist2D(0.0, 2.0, 0.0), OMNI.limits, omni=True)
    assert out.vy == OMNI.limits.max_vel_y and clamped == ("linear.y",)


def test_acceleration_ramps_up_and_down() -> None:
    lim = SKID.limits
    dt = 0.05
    v = Twist2D()
    v = limit_acceleration(Twist2D(0.26, 0, 1.0), v, lim, dt)
    assert v.vx == pytest.approx(lim.acc_lim_x * dt)
    assert v.wz == pytest.approx(lim.acc_lim_theta * dt)
    for _ in range(20):
        v = limit_acceleration(Twist2D(0.26, 0, 1.0), v, lim, dt)
    assert v.vx == pytest.approx(0.26) and v.wz == pytest.approx(1.0)
    v2 = limit_acceleration(Twist2D(), v, lim, dt)
    assert v2.vx == pytest.approx(0.26 + lim.decel_lim_x * dt)
