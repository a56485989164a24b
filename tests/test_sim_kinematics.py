"""Kinematics and wheel odometry against closed-form motions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.types import Pose2D, Twist2D
from robot.base import ImuReading, WheelTicks
from robot.kinematics import (
    diff_forward,
    diff_inverse,
    integrate_exact,
    integrate_poses,
    integrate_small_angle,
    integrate_twist,
    omni_forward,
    omni_inverse,
    skid_forward,
    skid_inverse,
    virtual_wheels,
)
from robot.odometry import OdometryError, OdometryOptions, WheelOdometry
from robot.profiles import load_profile


def test_diff_and_skid_round_trip() -> None:
    rng = np.random.default_rng(0)
    v, w = rng.normal(size=50), rng.normal(size=50)
    vl, vr = diff_inverse(v, w, 0.19)
    np.testing.assert_allclose(diff_forward(vl, vr, 0.19), (v, w))
    wheels = skid_inverse(v, w, 0.19)
    assert wheels.shape == (50, 4)
    np.testing.assert_allclose(skid_forward(wheels, 0.19), (v, w))
    l, r = virtual_wheels(np.array([1.0, 3.0, 5.0, 7.0]))
    assert (l, r) == (2.0, 6.0)


def test_omni_round_trip_and_wheel_directions() -> None:
    rng = np.random.default_rng(1)
    vx, vy, w = rng.normal(size=(3, 40))
    wheels = omni_inverse(vx, vy, w, 0.25)
    np.testing.assert_allclose(omni_forward(wheels, 0.25), (vx, vy, w))
    # pure forward motion drives only the side wheels, in opposite rim directions
    np.testing.assert_allclose(omni_inverse(1.0, 0.0, 0.0, 0.25), [0.0, -1.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(omni_inverse(0.0, 0.0, 2.0, 0.25), [0.5] * 4)


def test_exact_arc_matches_circle_and_straight_limit() -> None:
    track, radius, phi = 0.2, 1.5, 0.8
    dl, dr = (radius - track / 2) * phi, (radius + track / 2) * phi
    p = integrate_exact(Pose2D(0, 0, 0), dl, dr, track)
    assert (p.x, p.y, p.theta) == pytest.approx((radius * math.sin(phi), radius * (1 - math.cos(phi)), phi))
    s = integrate_exact(Pose2D(1, 2, 0.5), 0.3, 0.3, track)
    assert (s.x, s.y, s.theta) == pytest.approx((1 + 0.3 * math.cos(0.5), 2 + 0.3 * math.sin(0.5), 0.5))
    # the small-angle form agrees to first order and differs for a big step
    small = integrate_small_angle(Pose2D(0, 0, 0), dl / 100, dr / 100, track)
    exact = integrate_exact(Pose2D(0, 0, 0), dl / 100, dr / 100, track)
    assert small.distance_to(exact) < 1e-4
    assert integrate_small_angle(Pose2D(), dl, dr, track).distance_to(p) > 0.1


def test_twist_integration_constant_arc_and_vectorized() -> None:
    # omni: constant (vx, vy, w) for 2 s equals many small steps
    tw = Twist2D(0.4, -0.2, 0.7)
    one = integrate_twist(Pose2D(1, 1, 0.3), tw, 2.0)
    many = Pose2D(1, 1, 0.3)
    for _ in range(2000):
        many = integrate_twist(many, tw, 0.001)
    assert one.distance_to(many) < 1e-9 and one.theta == pytest.approx(many.theta)
    poses = np.array([[1, 1, 0.3], [0, 0, 0]])
    out = integrate_poses(poses, np.array([[0.4, -0.2, 0.7], [1.0, 0.0, 0.0]]), 2.0)
    np.testing.assert_allclose(out[0], one.as_array())
    np.testing.assert_allclose(out[1], [2.0, 0.0, 0.0], atol=1e-12)


def _ticks(profile, travel: np.ndarray) -> np.ndarray:
    return np.floor(travel / (2 * math.pi * profile.wheel_radius) * profile.ticks_per_rev).astype(np.int64)


@pytest.mark.parametrize("name", ["skid4", "omni4"])
@pytest.mark.parametrize("motion", ["straight", "rotate", "arc"])
def test_odometry_closed_form_motions(name: str, motion: str) -> None:
    profile = load_profile(name)
    v, w = {"straight": (0.2, 0.0), "rotate": (0.0, 0.5), "arc": (0.2, 0.4)}[motion]
    twist = Twist2D(v, 0.0, w)
    if profile.is_omni:
        rim = omni_inverse(v, 0.0, w, profile.omni_radius)
    else:
        rim = skid_inverse(v, w, profile.track_width)
    odo = WheelOdometry(profile, OdometryOptions(use_imu=False))
    dt, steps = 0.05, 100
    for k in range(steps + 1):
        odo.update(WheelTicks(k * dt, _ticks(profile, rim * k * dt)))
    want = integrate_twist(Pose2D(), twist, steps * dt)
    tick = 2 * math.pi * profile.wheel_radius / profile.ticks_per_rev
    assert odo.pose.distance_to(want) < 5 * tick
    assert abs(odo.pose.theta - want.theta) < 5 * tick / 0.1
    assert odo.twist.vx == pytest.approx(v, abs=0.01)
    assert odo.twist.wz == pytest.approx(w, abs=0.1)


def test_gyro_fusion_fixes_skid_scrub_and_learns_bias() -> None:
    profile = load_profile("skid4")
    bias = 0.01
    odo = WheelOdometry(profile)
    enc_only = WheelOdometry(profile, OdometryOptions(use_imu=False))
    dt, t = 0.05, 0.0
    # stand still 4 s: the bias is learned
    for _ in range(80):
        t += dt
        for o in (odo, enc_only):
            o.update(WheelTicks(t, np.zeros(4, dtype=np.int64)), ImuReading(t, bias))
    assert odo.gyro_bias == pytest.approx(bias, rel=1e-6)
    assert odo.pose.theta == 0.0  # zero-velocity update: no drift while still
    # turn on the spot at a true 0.5 rad/s; the wheels scrub and claim 30 % more
    true_w, travel = 0.5, np.zeros(4)
    rim = skid_inverse(0.0, true_w * 1.3, profile.track_width)
    for _ in range(40):
        t += dt
        travel = travel + rim * dt
        ticks = WheelTicks(t, _ticks(profile, travel))
        imu = ImuReading(t, true_w + bias)
        odo.update(ticks, imu)
        enc_only.update(ticks, imu)
    assert odo.pose.theta == pytest.approx(true_w * 2.0, abs=1e-6)
    assert enc_only.pose.theta == pytest.approx(true_w * 2.0 * 1.3, abs=0.01)
    assert not odo.slipping  # 0.15 rad/s of scrub is below the 0.25 rad/s slip threshold
    # wheels spinning against a blocked body: encoders turn at 1 rad/s, the gyro sees nothing
    rim = skid_inverse(0.0, 1.0, profile.track_width)
    for _ in range(3):
        t += dt
        travel = travel + rim * dt
        odo.update(WheelTicks(t, _ticks(profile, travel)), ImuReading(t, bias))
        assert odo.slipping
    heading = odo.pose.theta
    assert heading == pytest.approx(true_w * 2.0, abs=1e-6)  # the gyro keeps the heading honest


def test_odometry_rejects_bad_input() -> None:
    odo = WheelOdometry(load_profile("skid4"))
    with pytest.raises(OdometryError, match="wheel counts"):
        odo.update(WheelTicks(0.0, np.zeros(3, dtype=np.int64)))
    odo.update(WheelTicks(1.0, np.zeros(4, dtype=np.int64)))
    with pytest.raises(OdometryError, match="backwards"):
        odo.update(WheelTicks(0.5, np.zeros(4, dtype=np.int64)))


def test_docs_example_profile_drives_in_the_simulator() -> None:
    """The minimal diff profile in docs/profiles.md loads, simulates and odometry follows it."""
    import re
    import tomllib
    from pathlib import Path

    from robot.clock import VirtualClock
    from robot.profiles import profile_from_dict
    from robot.sim import SimDriver, SimOptions, World

    text = (Path(__file__).parents[1] / "docs/profiles.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S)
    assert block is not None
    profile = profile_from_dict(tomllib.loads(block.group(1)))
    assert profile.kinematics == "diff" and profile.wheel_count == 2
    clock = VirtualClock()
    opts = SimOptions(slip_noise_std=0.0, gyro_noise=False, lidar_noise=False)
    d = SimDriver(World.box(6, 6), profile, clock, start_pose=Pose2D(1.0, 3.0, 0.0), options=opts)
    odo = WheelOdometry(profile)
    for _ in range(60):
        d.command(Twist2D(0.2, 0.0, 0.3))
        clock.advance(0.05)
        f = d.read()
        odo.update(f.ticks, f.imu)
    truth = d.truth_pose.relative_to(Pose2D(1.0, 3.0, 0.0))
    assert odo.pose.distance_to(truth) < 0.005 and abs(odo.pose.theta - truth.theta) < 0.01
