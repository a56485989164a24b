"""Open space is not a fault (issue 16): a scan with no return within range is valid data; the fault
monitor tells it apart from a broken lidar (stuck frames, all-zero frames, wrong beam count, mostly
invalid beams, no scans at all) and names the kind it saw."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from app.fault_monitor import FaultMonitor, FaultMonitorOptions, classify_scan
from app.modes import Mode
from app.session import Session
from nav.types import LaserScan, Pose2D, Twist2D
from robot.clock import VirtualClock
from robot.profiles import PROFILE_DIR, RobotProfile, profile_from_dict
from robot.sim import SimDriver, World


def wide_lidar_robot() -> RobotProfile:
    """A 0.51 x 0.43 m robot with a 270-degree, 30 m lidar (the issue's field robot)."""
    data = tomllib.loads((PROFILE_DIR / "skid4.toml").read_text())
    data["name"] = "field"
    data["footprint"] = [[0.255, 0.215], [-0.255, 0.215], [-0.255, -0.215], [0.255, -0.215]]
    data["lidar"].update(beams=1081, fov_deg=270, angle_min_deg=-135, range_max=30.0, rate_hz=10.0)
    data["ir"] = []
    return profile_from_dict(data, source="test")


def drive(session: Session, cmd: Twist2D, seconds: float) -> list[str]:
    """Teleop ``cmd`` for ``seconds`` of simulated time; the fault reasons seen on the way."""
    seen = []
    for _ in range(round(seconds / session.period)):
        session.set_teleop(cmd, "test")
        session.run_for(session.period)
        if session.fault is not None:
            seen.append(session.fault)
    return seen


def test_robot_driving_out_of_a_field_with_a_30m_lidar_does_not_fault() -> None:
    """Posts around the start, nothing else within 30 m once the robot is out: every scan of the
    last stretch is +inf on every beam, and the robot keeps driving."""
    world = World.box(120.0, 80.0, resolution=0.1)
    rng = np.random.default_rng(16)
    for x, y in rng.uniform((4.0, 30.0), (22.0, 50.0), size=(40, 2)):
        if abs(y - 40.0) > 1.0:  # a lane along y = 40
            world.add_polygon(
                [(x + dx, y + dy) for dx, dy in ((-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1))]
            )
    clock = VirtualClock()
    start = Pose2D(10.0, 40.0, 0.0)
    profile = wide_lidar_robot()
    driver = SimDriver(world, profile, clock, seed=3, start_pose=start)
    session = Session(driver, clock=clock, grid=world.grid, start_pose=start)
    try:
        session.request_mode("teleop")
        faults = drive(session, Twist2D(profile.limits.max_vel_x, 0.0, 0.0), 150.0)
        assert faults == [] and session.modes.mode == Mode.TELEOP
        end = driver.truth_pose
        assert end.x > 45.0  # out of the field: the posts are > 30 m behind, outside the 270 deg
        ranges = session.last_scan.ranges
        assert np.isposinf(ranges).all()  # the open-space scans were seen, not withheld
    finally:
        session.close()


def test_empty_world_standing_and_turning_does_not_fault() -> None:
    world = World.box(120.0, 120.0, resolution=0.1)
    clock = VirtualClock()
    start = Pose2D(60.0, 60.0, 0.0)
    driver = SimDriver(world, wide_lidar_robot(), clock, seed=1, start_pose=start)
    session = Session(driver, clock=clock, grid=world.grid, start_pose=start)
    try:
        session.request_mode("teleop")
        assert drive(session, Twist2D(0.0, 0.0, 0.5), 10.0) == []
        assert drive(session, Twist2D(), 10.0) == []  # standing: +inf frames repeat, still not stuck
        assert np.isposinf(session.last_scan.ranges).all()
    finally:
        session.close()


def scan(ranges: np.ndarray | list[float], range_max: float = 6.0) -> LaserScan:
    r = np.asarray(ranges, dtype=float)
    return LaserScan(0.0, -math.pi, 2 * math.pi / max(r.size, 1), r, 0.15, range_max)


def feed(monitor: FaultMonitor, frames: list[np.ndarray]) -> str | None:
    reason = None
    for f in frames:
        _, reason = monitor.check_scan(scan(f))
    return reason


def noisy(rng: np.random.Generator, n: int = 360) -> np.ndarray:
    return 2.0 + rng.normal(0.0, 0.01, n)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda rng, k: np.full(360, np.inf), None),  # open space
        (lambda rng, k: np.where(rng.random(360) < 0.9, np.inf, noisy(rng)), None),  # a few returns
        (lambda rng, k: noisy(rng), None),  # a room
        (lambda rng, k: np.zeros(360), "all-zero frame"),
        (lambda rng, k: noisy(rng, 180), "wrong beam count (180 beams, the lidar has 360)"),
        (lambda rng, k: np.where(rng.random(360) < 0.8, np.nan, noisy(rng)), "invalid beams"),
        (lambda rng, k: np.full(360, -np.inf), "every beam closer than range_min"),
        (lambda rng, k: noisy(np.random.default_rng(0)), "lidar stuck: the same frame"),
    ],
)
def test_each_lidar_fault_kind_has_its_own_message(make, message: str | None) -> None:
    rng = np.random.default_rng(5)
    monitor = FaultMonitor(0.05, FaultMonitorOptions(), expected_beams=360)
    reason = feed(monitor, [make(rng, k) for k in range(40)])
    if message is None:
        assert reason is None and monitor.present() is None
    else:
        assert reason is not None and message in reason, reason
        assert "0 % invalid" not in reason and "0% invalid" not in reason
        assert monitor.present() == reason  # blocks a reset while it holds
        assert feed(monitor, [noisy(rng) for _ in range(3)]) is None  # a healthy sensor clears it


def test_bad_scans_are_withheld_and_open_space_is_passed_on() -> None:
    monitor = FaultMonitor(0.05, expected_beams=360)
    empty = scan(np.full(360, np.inf))
    clean, reason = monitor.check_scan(empty)
    assert clean is empty and reason is None
    assert monitor.check_scan(scan(np.zeros(360)))[0] is None
    assert classify_scan(empty, 0.5)[2] is None
    assert classify_scan(scan(np.zeros(360)), 0.5)[2] == "all-zero frame"
