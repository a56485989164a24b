"""Simulator fault switches: each corrupts exactly what the driver reports, and can be turned off."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.types import Pose2D, Twist2D
from robot.clock import VirtualClock
from robot.odometry import WheelOdometry
from robot.profiles import load_profile
from robot.sim import SimDriver, SimOptions, World
from robot.sim.faults import FaultSpecError, SimFaults

QUIET = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False)


def make(profile: str = "skid4", seed: int = 0) -> tuple[SimDriver, VirtualClock]:
    clock = VirtualClock()
    d = SimDriver(
        World.box(8, 8), load_profile(profile), clock, seed=seed, start_pose=Pose2D(4, 4, 0), options=QUIET
    )
    return d, clock


def run(driver: SimDriver, clock: VirtualClock, cmd: Twist2D, seconds: float) -> list:
    out = []
    for _ in range(round(seconds / 0.05)):
        driver.command(cmd)
        clock.advance(0.05)
        out.append(driver.read())
    return out


def test_lidar_off_stops_scans_and_on_resumes() -> None:
    d, clock = make()
    assert any(f.scan is not None for f in run(d, clock, Twist2D(), 1.0))
    d.lidar_enabled = False
    assert d.faults.lidar_enabled is False and d.faults.describe() == ["lidar_enabled=False"]
    assert all(f.scan is None for f in run(d, clock, Twist2D(), 2.0))
    d.lidar_enabled = True
    assert any(f.scan is not None for f in run(d, clock, Twist2D(), 1.0))


def test_lidar_garbage_holds_nan_inf_negative_and_huge_ranges() -> None:
    d, clock = make()
    d.faults.lidar_garbage = 0.5
    scans = [f.scan for f in run(d, clock, Twist2D(), 2.0) if f.scan is not None]
    r = np.concatenate([s.ranges for s in scans])
    clean = (r > 3.0) & (r < 6.0)  # walls are 3.9-5.6 m away in this box
    bad = ~clean
    assert 0.4 < bad.mean() < 0.6
    assert np.isnan(r).any() and np.isposinf(r).any() and (r < 0).any() and (r > 1e5).any()
    d.faults.clear()
    scan = [f.scan for f in run(d, clock, Twist2D(), 0.5) if f.scan is not None][-1]
    assert np.all((scan.ranges > 3.0) & (scan.ranges < 6.0))


def test_encoder_slip_scales_one_wheels_ticks_only() -> None:
    d, clock = make()
    base = run(d, clock, Twist2D(0.2, 0, 0), 1.0)[-1].ticks.counts.copy()
    d.faults.apply("encoder_slip=0:0.5")
    after = run(d, clock, Twist2D(0.2, 0, 0), 1.0)[-1].ticks.counts
    inc = after - base
    assert inc[0] == pytest.approx(0.5 * inc[1], rel=0.02)  # FL counts half of RL
    assert inc[1] == pytest.approx(inc[2], rel=0.01) == pytest.approx(inc[3], rel=0.01)
    # odometry fed by the slipping encoder turns although the robot drives straight
    odo = WheelOdometry(d.profile)
    d2, clock2 = make()
    d2.faults.slip_wheel, d2.faults.slip_factor = 0, 0.0  # a dead encoder
    for f in run(d2, clock2, Twist2D(0.2, 0, 0), 2.0):
        pose = odo.update(f.ticks, None).pose
    assert abs(d2.truth_pose.theta) < 1e-6 and abs(pose.theta) > 0.05


def test_gyro_bias_jump_and_battery_sag() -> None:
    d, clock = make()
    gyro = [f.imu.gyro_z for f in run(d, clock, Twist2D(), 0.5)]
    v0 = d.battery_v
    assert max(abs(g) for g in gyro) < 1e-9
    d.faults.apply("gyro_bias=0.05")
    d.faults.apply("battery_sag=1.5")
    frames = run(d, clock, Twist2D(), 0.5)
    assert all(f.imu.gyro_z == pytest.approx(0.05) for f in frames)
    assert frames[-1].battery_v == pytest.approx(v0 - 1.5, abs=1e-3)
    assert abs(d.truth_pose.theta) < 1e-9  # the body itself did not turn
    assert sorted(d.faults.describe()) == ["battery_sag=1.5", "gyro_bias_jump=0.05"]


@pytest.mark.parametrize(
    "spec",
    [
        "bogus",
        "lidar_garbage=2",
        "encoder_slip=x:0.5",
        "gyro_bias=nan",
        "encoder_slip=-1:0.5",
        "battery_sag=",
    ],
)
def test_bad_fault_specs_are_refused(spec: str) -> None:
    with pytest.raises(FaultSpecError):
        SimFaults().apply(spec)


def test_slip_on_a_missing_wheel_is_refused() -> None:
    f = SimFaults(slip_wheel=7, slip_factor=0.5)
    with pytest.raises(FaultSpecError, match="wheels"):
        f.tick_scale(4)
    assert math.isclose(SimFaults().tick_scale(4).sum(), 4.0)


def test_resting_robot_skips_physics_but_still_sees_new_obstacles_and_teleports() -> None:
    """The idle fast path must not hide a collision: an obstacle dropped on a resting robot, or a
    teleport into a wall, is still reported."""
    d, clock = make()
    run(d, clock, Twist2D(), 0.5)  # at rest: substeps are skipped from here on
    assert d.body._rest is not None and d.body._rest[0] is d.body.pose
    d.world.add_polygon([(3.9, 3.9), (4.1, 3.9), (4.1, 4.1), (3.9, 4.1)])
    assert any(f.collision for f in run(d, clock, Twist2D(), 0.2))
    d2, clock2 = make()
    run(d2, clock2, Twist2D(), 0.5)
    d2.teleport(Pose2D(0.05, 4.0, 0.0))  # straddling the west wall
    assert any(f.collision for f in run(d2, clock2, Twist2D(), 0.2))


def test_same_seed_same_run_with_or_without_a_pause_in_the_middle() -> None:
    """Noise is drawn while resting too, so pausing does not shift later random numbers."""
    out = []
    for pause in (Twist2D(), Twist2D(1e-12, 0, 0)):  # exact zero takes the fast path, 1e-12 does not
        clock = VirtualClock()
        d = SimDriver(World.box(8, 8), load_profile("skid4"), clock, seed=3, start_pose=Pose2D(4, 4, 0))
        run(d, clock, pause, 1.0)
        run(d, clock, Twist2D(0.2, 0, 0.3), 1.0)
        out.append(d.truth_pose)
    assert out[0].distance_to(out[1]) < 1e-9


def test_resting_lidar_reuses_its_cast_only_while_nothing_changes() -> None:
    d, clock = make()
    first = [f.scan.ranges for f in run(d, clock, Twist2D(), 1.0) if f.scan is not None]
    assert all(np.array_equal(first[0], r) for r in first[1:])  # noise-free: identical at rest
    d.world.add_polygon([(4.5, 3.8), (4.7, 3.8), (4.7, 4.2), (4.5, 4.2)])  # a box 0.5 m ahead
    scan = [f.scan for f in run(d, clock, Twist2D(), 0.5) if f.scan is not None][-1]
    assert scan.ranges[180] == pytest.approx(0.5, abs=0.01)
    d.people.add(4.0, 5.0)  # a person 1 m to the left
    scan = [f.scan for f in run(d, clock, Twist2D(), 0.5) if f.scan is not None][-1]
    assert scan.ranges[270] == pytest.approx(0.85, abs=0.01)
