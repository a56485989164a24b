"""The simulator behind the Driver protocol: collisions, determinism, sensors, e-stop."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from nav.types import Pose2D, Twist2D
from robot.base import Driver
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.sim import SimDriver, SimOptions, World

QUIET = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False)


def run(driver: SimDriver, clock: VirtualClock, cmd: Twist2D, seconds: float, period: float = 0.05) -> list:
    frames = []
    for _ in range(round(seconds / period)):
        driver.command(cmd)
        clock.advance(period)
        frames.append(driver.read())
    return frames


def test_implements_driver_protocol() -> None:
    d = SimDriver(World.box(3, 3), load_profile("skid4"), VirtualClock())
    assert isinstance(d, Driver)


@pytest.mark.parametrize(("name", "cmd"), [("skid4", Twist2D(0.26, 0, 0)), ("omni4", Twist2D(0.0, 1.5, 0))])
def test_full_speed_into_a_wall_stops_outside_and_reports(name: str, cmd: Twist2D) -> None:
    profile = load_profile(name)
    world = World.box(4.0, 3.0)
    clock = VirtualClock()
    opts = SimOptions(ir_stop=False)
    d = SimDriver(world, profile, clock, seed=2, start_pose=Pose2D(2.0, 1.5, 0.0), options=opts)
    frames = run(d, clock, cmd, 12.0)
    assert any(f.collision for f in frames)
    assert d.body.penetration(world, d.truth_pose)[0] <= opts.contact_skin + 1e-9  # never into the wall
    assert d.truth_velocity.is_zero()
    # it got close: within a few centimetres of the wall face (x = 3.9 or y = 2.9)
    if cmd.vx:
        assert 3.9 - (d.truth_pose.x + 0.12) < 0.05
    else:
        assert 2.9 - (d.truth_pose.y + profile.robot_radius) < 0.05
    first = next(i for i, f in enumerate(frames) if f.collision)
    assert all(f.collision for f in frames[first:])  # pushing on keeps reporting contact


def test_ir_stop_halts_forward_motion_before_the_wall() -> None:
    clock = VirtualClock()
    d = SimDriver(World.box(4.0, 3.0), load_profile("skid4"), clock, seed=0, start_pose=Pose2D(2.0, 1.5, 0.0))
    frames = run(d, clock, Twist2D(0.26, 0, 0), 10.0)
    assert not any(f.collision for f in frames)
    assert frames[-1].base_stopped_by_obstacle
    ir = [f.ir for f in frames if f.ir is not None][-1]
    assert ir.triggered.all() and (ir.ranges <= 0.30).all()
    gap = 3.9 - (d.truth_pose.x + 0.12)
    assert 0.0 < gap < 0.30
    # turning away is still allowed
    before = d.truth_pose.theta
    run(d, clock, Twist2D(0.0, 0, 1.0), 1.0)
    assert abs(d.truth_pose.theta - before) > 0.5


def test_deterministic_for_a_seed() -> None:
    def trace(seed: int) -> tuple[list, Pose2D]:
        clock = VirtualClock()
        d = SimDriver(World.stock("apartment"), load_profile("skid4"), clock, seed=seed)
        out = []
        for k in range(60):
            d.command(Twist2D(0.2, 0, 0.6 * math.sin(k / 10)))
            clock.advance(0.05)
            f = d.read()
            out.append(
                (f.ticks.counts.tolist(), None if f.scan is None else f.scan.ranges.tolist(), f.imu.gyro_z)
            )
        return out, d.truth_pose

    a, pa = trace(7)
    b, pb = trace(7)
    c, _ = trace(8)
    assert a == b and pa == pb
    assert a != c


def test_lidar_ranges_match_box_geometry_with_mount_offset() -> None:
    base = load_profile("skid4")
    lidar = dataclasses.replace(base.lidar, mount_x=0.05, mount_y=-0.02, mount_yaw=0.3, range_max=10.0)
    profile = dataclasses.replace(base, lidar=lidar)
    clock = VirtualClock()
    pose = Pose2D(1.7, 1.2, 0.4)
    d = SimDriver(World.box(4.0, 3.0), profile, clock, seed=0, start_pose=pose, options=QUIET)
    scan = d.read().scan  # the first scan is taken at t = 0
    assert scan is not None and scan.ranges.shape == (360,)
    laser = pose.compose(Pose2D(0.05, -0.02, 0.3))
    a = laser.theta + scan.angles
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (3.9 - laser.x) / c, (0.1 - laser.x) / c)
        ty = np.where(s > 0, (2.9 - laser.y) / s, (0.1 - laser.y) / s)
    np.testing.assert_allclose(scan.ranges, np.minimum(tx, ty), atol=1e-9)
    assert scan.angle_min == pytest.approx(-math.pi) and scan.frame_id == "laser"


def test_lidar_noise_dropouts_and_rate() -> None:
    clock = VirtualClock()
    profile = load_profile("skid4")
    d = SimDriver(World.box(4.0, 3.0), profile, clock, seed=1, start_pose=Pose2D(2.0, 1.5, 0.0))
    truth = d.lidar.true_ranges(d.world, d.truth_pose)
    scans = [f.scan for f in run(d, clock, Twist2D(), 4.0) if f.scan is not None]
    assert len(scans) == pytest.approx(4.0 * profile.lidar.rate_hz, abs=1.5)
    r = np.array([s.ranges for s in scans])
    finite = np.isfinite(r)
    assert 0.0 < (~finite).mean() < 0.05  # ~1 % dropouts
    err = (r - truth)[finite]
    assert abs(err.std() - profile.lidar.range_noise_std) < 0.002


def test_encoders_gyro_and_battery() -> None:
    profile = load_profile("skid4")
    clock = VirtualClock()
    d = SimDriver(World.box(6, 6), profile, clock, seed=3, start_pose=Pose2D(1.0, 3.0, 0.0), options=QUIET)
    frames = run(d, clock, Twist2D(0.2, 0, 0), 5.0)
    counts = frames[-1].ticks.counts
    assert counts.shape == (4,) and len(set(counts.tolist())) == 1
    travelled = d.truth_pose.x - 1.0
    assert counts[0] == pytest.approx(
        travelled / (2 * math.pi * profile.wheel_radius) * profile.ticks_per_rev, abs=1
    )
    assert all(abs(f.imu.gyro_z) < 1e-12 for f in frames)
    assert frames[-1].battery_v < frames[0].battery_v <= profile.battery_full_v
    noisy = SimDriver(World.box(6, 6), profile, VirtualClock(), seed=3)
    noisy.clock.advance(10.0)
    assert noisy.read().imu.gyro_z == pytest.approx(profile.imu.gyro_bias, abs=0.001)


def test_acceleration_limits_and_estop() -> None:
    profile = load_profile("omni4")
    clock = VirtualClock()
    d = SimDriver(World.box(10, 10), profile, clock, seed=0, start_pose=Pose2D(5, 5, 0), options=QUIET)
    d.command(Twist2D(1.0, 0, 0))
    clock.advance(0.5)
    d.read()
    assert d.truth_velocity.vx == pytest.approx(profile.limits.acc_lim_x * 0.5, abs=0.011)
    d.estop()
    run(d, clock, Twist2D(1.0, 0, 0), 1.0)
    assert d.truth_velocity.is_zero() and d.estopped
    d.reset()
    run(d, clock, Twist2D(1.0, 0, 0), 1.0)
    assert d.truth_velocity.vx > 0.9


def test_teleport_and_stock_start() -> None:
    clock = VirtualClock()
    world = World.stock("office")
    d = SimDriver(world, load_profile("skid4"), clock)
    assert d.truth_pose == world.start_pose
    d.teleport(Pose2D(20.0, 10.0, 1.0))
    clock.advance(0.1)
    d.read()
    assert d.truth_pose.distance_to(Pose2D(20.0, 10.0, 1.0)) < 1e-9
    with pytest.raises(ValueError, match="non-finite"):
        d.command(Twist2D(math.nan, 0, 0))


def test_polygon_obstacle_blocks_lidar() -> None:
    world = World.box(4.0, 3.0)
    world.add_polygon([(2.5, 1.0), (3.0, 1.0), (3.0, 2.0), (2.5, 2.0)])
    clock = VirtualClock()
    d = SimDriver(world, load_profile("skid4"), clock, start_pose=Pose2D(1.5, 1.5, 0.0), options=QUIET)
    ahead = d.read().scan.ranges[180]  # angle 0
    assert ahead == pytest.approx(1.0, abs=0.051)


def test_options_are_validated() -> None:
    with pytest.raises(ValueError, match="physics_rate_hz"):
        SimOptions(physics_rate_hz=0)
    with pytest.raises(ValueError, match="slip_noise_std"):
        SimOptions(slip_noise_std=-1)


def test_obstacle_wholly_inside_the_footprint_is_a_collision() -> None:
    world = World.box(4.0, 4.0)
    world.add_polygon([(2.0, 2.0), (2.05, 2.0), (2.05, 2.05), (2.0, 2.05)])  # one 5 cm post
    clock = VirtualClock()
    d = SimDriver(world, load_profile("omni4"), clock, start_pose=Pose2D(1.0, 1.0, 0.0), options=QUIET)
    d.teleport(Pose2D(2.1, 2.0, 0.0))  # the post is 7 cm from the centre, well inside r = 0.25 m
    deep = d.body.penetration(world, d.truth_pose)[0]
    assert deep > 0.0
    frames = run(d, clock, Twist2D(0.3, 0.0, 0.0), 0.5)
    assert all(f.collision for f in frames)
    # it may move (the overlap is not its doing: something was set down on it), never further in
    assert d.body.penetration(world, d.truth_pose)[0] <= deep + 1e-9


def test_odometry_tracks_the_simulator_and_gyro_corrects_skid_scrub() -> None:
    from robot.odometry import OdometryOptions, WheelOdometry

    profile = load_profile("skid4")
    opts = dataclasses.replace(QUIET, skid_track_factor=1.4, gyro_noise=True)
    clock = VirtualClock()
    start = Pose2D(3.0, 3.0, 0.0)
    d = SimDriver(World.box(6, 6), profile, clock, seed=4, start_pose=start, options=opts)
    fused, wheels_only = WheelOdometry(profile), WheelOdometry(profile, OdometryOptions(use_imu=False))
    for k in range(200):
        still = k < 60  # stand still first: the gyro bias is learned
        d.command(Twist2D() if still else Twist2D(0.15, 0.0, 0.6))
        clock.advance(0.05)
        f = d.read()
        fused.update(f.ticks, f.imu)
        wheels_only.update(f.ticks, f.imu)
    truth = d.truth_pose.relative_to(start)
    assert abs(fused.pose.theta - truth.theta) < 0.02
    assert fused.pose.distance_to(truth) < 0.03
    # the encoders alone over-count the turn by the scrub factor
    assert abs(wheels_only.pose.theta - truth.theta) > 0.5


def test_omni_odometry_follows_holonomic_motion() -> None:
    from robot.odometry import WheelOdometry

    profile = load_profile("omni4")
    clock = VirtualClock()
    start = Pose2D(5.0, 5.0, 0.5)
    d = SimDriver(World.box(10, 10), profile, clock, seed=0, start_pose=start, options=QUIET)
    odo = WheelOdometry(profile)
    for _ in range(80):
        d.command(Twist2D(0.3, -0.4, 0.2))
        clock.advance(0.05)
        f = d.read()
        odo.update(f.ticks, f.imu)
    truth = d.truth_pose.relative_to(start)
    assert truth.distance_to(Pose2D()) > 1.0
    assert odo.pose.distance_to(truth) < 0.01 and abs(odo.pose.theta - truth.theta) < 0.01
