from __future__ import annotations

import pytest

from app.limits import CommandRefused, clamp_speed, limit_acceleration, sanity_bounds, sanity_check
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


def test_sanity_bound_is_twice_the_limit_per_component() -> None:
    lim = SKID.limits
    assert sanity_bounds(lim, omni=False) == pytest.approx(
        (
            2 * max(lim.max_vel_x, -lim.min_vel_x),
            2 * max(lim.max_vel_x, -lim.min_vel_x),
            2 * lim.max_vel_theta,
        )
    )
    assert sanity_bounds(OMNI.limits, omni=True)[1] == pytest.approx(2 * OMNI.limits.max_vel_y)
    # just inside: accepted (then clamped); the dashboard's full reverse (-max_vel_x) is inside too
    sanity_check(Twist2D(1.99 * lim.max_vel_x, 0.0, -1.99 * lim.max_vel_theta), lim, omni=False)
    sanity_check(Twist2D(-lim.max_vel_x, 0.0, 0.0), lim, omni=False)
    with pytest.raises(CommandRefused) as info:
        sanity_check(Twist2D(1e308, 0.0, float("inf")), lim, omni=False)
    assert set(info.value.beyond) == {"linear.x", "angular.z"}
    body = info.value.as_dict()
    assert body["status"] == 422 and body["refused"]["linear.x"]["bound"] == pytest.approx(0.52)
