"""The safety filter alone (synthetic frames) and through a Session on a virtual clock."""

from __future__ import annotations

import dataclasses
import math
import sys
import threading

import numpy as np
import pytest

from app.session import Session
from nav.types import LaserScan, Pose2D, Twist2D
from robot.base import IrReading, SensorFrame
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.safety import SafetyConfigError, SafetyFilter, SafetyOptions
from robot.sim import SimDriver, SimOptions, World

SKID = load_profile("skid4")
OMNI = load_profile("omni4")


def wall_scan(stamp: float, x: float | None = None, y: float | None = None, beams: int = 360) -> LaserScan:
    """A scan (laser at base_link) of an infinite wall at x = ``x`` (ahead) or y = ``y`` (left)."""
    a = -math.pi + 2 * math.pi / beams * np.arange(beams)
    r = np.full(beams, np.inf)
    with np.errstate(divide="ignore"):
        if x is not None:
            rx = x / np.cos(a)
            r = np.where((np.cos(a) > 0) & (rx < 6.0), rx, r)
        if y is not None:
            ry = y / np.sin(a)
            r = np.minimum(r, np.where((np.sin(a) > 0) & (ry < 6.0), ry, np.inf))
    return LaserScan(stamp, -math.pi, 2 * math.pi / beams, r, 0.15, 6.0)


def frame(stamp: float, scan: LaserScan | None = None, ir: IrReading | None = None) -> SensorFrame:
    return SensorFrame(stamp=stamp, scan=scan, ir=ir)


def test_stop_zone_blocks_forward_but_allows_turning_and_backing() -> None:
    f = SafetyFilter(SKID)
    fr = frame(0.0, wall_scan(0.0, x=0.12 + 0.03))  # wall 3 cm ahead of the front edge
    out, reason = f(Twist2D(0.26, 0.0, 0.0), fr)
    assert out.is_zero() and reason and reason.startswith("stop: lidar") and "0.03 m" in reason
    back, reason = f(Twist2D(-0.15, 0.0, 0.0), frame(0.05))
    assert back == Twist2D(-0.15, 0.0, 0.0) and reason is None  # backing away untouched
    turn, _ = f(Twist2D(0.2, 0.0, 0.1), frame(0.1))
    assert turn.vx == 0.0 and turn.wz > 0.0  # still turns (slowly: the corners approach the wall)


def test_clear_path_is_untouched_and_slowdown_zone_scales() -> None:
    f = SafetyFilter(SKID)
    cmd = Twist2D(0.26, 0.0, 0.2)
    assert f(cmd, frame(0.0, wall_scan(0.0, x=3.0))) == (cmd, None)
    g = SafetyFilter(SKID, SafetyOptions(approach_enabled=False))
    out, reason = g(cmd, frame(0.0, wall_scan(0.0, x=0.12 + 0.2)))
    assert out.vx == pytest.approx(0.26 * 0.3) and out.wz == pytest.approx(0.2 * 0.3)
    assert reason.startswith("slowdown: lidar")
    # a wall alongside (not approached) does not slow a straight drive
    out, reason = g(Twist2D(0.26, 0.0, 0.0), frame(0.1, wall_scan(0.1, y=0.10 + 0.1)))
    assert out == Twist2D(0.26, 0.0, 0.0) and reason is None


def test_approach_scales_by_time_to_collision() -> None:
    f = SafetyFilter(SKID, SafetyOptions(slowdown_enabled=False))
    # front edge 0.13 m from the wall: at 0.26 m/s contact after 0.5 s -> scaled by 0.5 / 1.2
    out, reason = f(Twist2D(0.26, 0.0, 0.0), frame(0.0, wall_scan(0.0, x=0.12 + 0.13)))
    assert out.vx == pytest.approx(0.26 * 0.5 / 1.2) and reason.startswith("approach: collision in 0.5 s")


def test_omni_slides_along_a_wall_but_not_into_it() -> None:
    f = SafetyFilter(OMNI, SafetyOptions(slowdown_enabled=False, approach_enabled=False))
    fr = frame(0.0, wall_scan(0.0, y=0.25 + 0.03))  # wall 3 cm to the left
    out, reason = f(Twist2D(1.0, 0.5, 0.0), fr)
    assert out.vx > 0.9 and out.vy <= 1e-6 and reason.startswith("stop")  # slides along
    out, reason = f(Twist2D(0.0, -0.5, 0.0), frame(0.05))
    assert out == Twist2D(0.0, -0.5, 0.0) and reason is None


def test_ir_alone_stops_and_a_few_garbage_ranges_are_ignored() -> None:
    f = SafetyFilter(SKID)
    r = np.full(360, np.inf)
    r[::10] = np.tile([np.nan, -1.0, -np.inf, 1e6], 9)  # 10 % odd values: filtered, not trusted
    scan = LaserScan(0.0, -math.pi, 2 * math.pi / 360, r, 0.15, 6.0)
    assert f(Twist2D(0.2, 0, 0), frame(0.0, scan)) == (Twist2D(0.2, 0, 0), None)
    ir = IrReading(0.05, np.array([True, False]), np.array([0.02, np.inf]))
    out, reason = f(Twist2D(0.2, 0, 0), frame(0.05, ir=ir))
    assert out.is_zero() and reason.startswith("stop: IR 0")
    # the IR reading expires after ir_timeout
    out, _ = f(Twist2D(0.2, 0, 0), frame(0.05 + 0.6))
    assert out.vx > 0


def test_scan_is_remembered_and_shifted_between_frames() -> None:
    f = SafetyFilter(SKID, SafetyOptions(slowdown_enabled=False, approach_enabled=False))
    f(Twist2D(0.26, 0, 0), frame(0.0, wall_scan(0.0, x=0.12 + 0.2)))  # 0.2 m: clear of the stop zone
    stopped_at = None
    for k in range(1, 20):  # no new scan: the wall comes closer by the robot's own motion
        out, _ = f(Twist2D(0.26, 0, 0), frame(0.05 * k))
        if out.is_zero():
            stopped_at = 0.05 * k
            break
    # 0.15 m to go at 0.26 m/s: the stop zone (0.05 m) is reached after ~0.6 s
    assert stopped_at == pytest.approx(0.6, abs=0.06)


def test_a_garbage_spewing_lidar_stops_the_robot_until_it_recovers() -> None:
    clock = VirtualClock()
    world = World.box(6.0, 4.0)
    d = SimDriver(world, SKID, clock, seed=0, start_pose=Pose2D(2.0, 2.0, 0.0))
    f = SafetyFilter(SKID)
    d.faults.lidar_garbage = 0.5
    outs = []
    for _ in range(10):
        clock.advance(0.05)
        outs.append(f(Twist2D(0.2, 0, 0), d.read()))
    assert outs[-1][0].is_zero() and "garbage" in outs[-1][1]
    d.faults.clear()
    for _ in range(10):
        clock.advance(0.05)
        out, reason = f(Twist2D(0.2, 0, 0), d.read())
    assert out.vx == 0.2 and reason is None


def test_a_pause_in_calls_is_not_integrated_as_motion() -> None:
    """After the session stopped the robot without the filter (e-stop), the last forward command must
    not move the remembered scan: a wall 0.2 m ahead stays 0.2 m ahead."""
    f = SafetyFilter(SKID, SafetyOptions(slowdown_enabled=False, approach_enabled=False))
    f(Twist2D(0.26, 0, 0), frame(0.0, wall_scan(0.0, x=0.12 + 0.2)))
    out, reason = f(Twist2D(0.26, 0, 0), frame(1.0))  # 1 s later: 0.26 m of phantom motion otherwise
    assert out.vx == 0.26 and reason is None


def test_stale_or_missing_scan_stops() -> None:
    f = SafetyFilter(SKID)
    out, reason = f(Twist2D(0.2, 0, 0), frame(0.0))
    assert out.is_zero() and reason == "stop: no lidar scan yet"
    f(Twist2D(0.2, 0, 0), frame(0.1, wall_scan(0.1, x=3.0)))
    out, reason = f(Twist2D(0.2, 0, 0), frame(2.5))
    assert out.is_zero() and "old" in reason
    assert f(Twist2D(), frame(2.6)) == (Twist2D(), None)


def test_a_robot_without_a_lidar_is_not_stopped_for_want_of_scans_but_ir_still_stops_it() -> None:
    """Issue 23 item 2: a base served without a lidar drives by teleop; its IR sensors still count."""
    f = SafetyFilter(SKID, lidar=False)
    assert f(Twist2D(0.2, 0, 0), frame(0.0)) == (Twist2D(0.2, 0, 0), None)
    assert f(Twist2D(0.2, 0, 0), frame(5.0)) == (Twist2D(0.2, 0, 0), None)
    ir = IrReading(5.05, np.array([True, False]), np.array([0.02, np.inf]))
    out, reason = f(Twist2D(0.2, 0, 0), frame(5.05, ir=ir))
    assert out.is_zero() and reason.startswith("stop: IR 0")


@pytest.mark.parametrize(
    "kwargs",
    [{"stop_margin": -1.0}, {"slowdown_ratio": 1.5}, {"min_points": 0}, {"time_before_collision": 0.0}],
)
def test_bad_options_are_refused(kwargs: dict) -> None:
    with pytest.raises(SafetyConfigError):
        SafetyOptions(**kwargs)


# --------------------------------------------------------------------------- through a Session


def session_at_wall(profile_name: str, ir: bool, seed: int = 1) -> Session:
    """A robot 1.5 m from the east wall of a 6 x 4 m room, facing it; the base's own IR motor stop
    is off so only the safety filter can stop it."""
    profile = load_profile(profile_name)
    if not ir:
        profile = dataclasses.replace(profile, ir=())
    clock = VirtualClock()
    world = World.box(6.0, 4.0)
    start = Pose2D(6.0 - 0.1 - 1.5, 2.0, 0.0)
    driver = SimDriver(world, profile, clock, seed=seed, start_pose=start, options=SimOptions(ir_stop=False))
    s = Session(driver, clock=clock, grid=world.grid, start_pose=start)
    s.safety = SafetyFilter(profile)
    s.request_mode("teleop")
    return s


@pytest.mark.parametrize(("profile_name", "ir"), [("skid4", True), ("skid4", False), ("omni4", False)])
def test_full_speed_at_a_wall_stops_without_collision(profile_name: str, ir: bool) -> None:
    s = session_at_wall(profile_name, ir)
    lim = s.profile.limits
    for _ in range(round(15.0 / s.period)):
        s.set_teleop(Twist2D(lim.max_vel_x, 0.0, 0.0), "test")
        s.run_for(s.period)
    truth = s.driver.truth_pose
    front = truth.x + s.profile.circumscribed_radius if s.profile.is_omni else truth.x + 0.12
    gap = 6.0 - 0.1 - front
    assert s.collisions == 0
    assert 0.0 < gap <= 0.08  # stopped within the stop zone's reach, not metres short
    assert s.last_command.vx == 0.0 and s.safety_stop and s.safety_stop.startswith("stop")
    # backing away is still allowed
    for _ in range(round(1.0 / s.period)):
        s.set_teleop(Twist2D(lim.min_vel_x, 0.0, 0.0), "test")
        s.run_for(s.period)
    assert s.driver.truth_pose.x < truth.x - 0.1 and s.safety_stop is None


def test_zero_command_within_one_cycle_of_the_crossing_reading() -> None:
    """A person steps in front of a moving robot: the first frame whose readings put the person in
    the stop zone produces a zero forward command at the driver in that same control cycle."""
    s = session_at_wall("skid4", ir=False)
    s.safety = SafetyFilter(s.profile, SafetyOptions(slowdown_enabled=False, approach_enabled=False))
    for _ in range(10):
        s.set_teleop(Twist2D(0.2, 0.0, 0.0), "test")
        s.run_for(s.period)
    assert s.last_command.vx > 0.15
    truth = s.driver.truth_pose
    s.driver.people.add(truth.x + 0.12 + 0.04 + 0.15 + 0.05, truth.y)  # steps in just ahead
    crossed = None
    for k in range(20):
        s.set_teleop(Twist2D(0.2, 0.0, 0.0), "test")
        s.run_for(s.period)
        scan = s._last_frame.scan
        if crossed is None and scan is not None:
            pts = scan.points()
            gap = pts[(np.abs(pts[:, 1]) < 0.09) & (pts[:, 0] > 0)][:, 0].min() - 0.12
            if gap <= 0.05:
                crossed = k
                assert s.last_command.vx == 0.0  # the same cycle's command
        if crossed is not None:
            assert s.last_command.vx == 0.0
    assert crossed is not None and s.collisions == 0


def test_readings_stay_consistent_while_another_thread_ingests_scans() -> None:
    """The dashboard's contact report reads the filter from the control thread while a teleop reflex
    command ingests a new scan on the websocket's thread: the reader must never see one scan's points
    with another scan's velocities (seen in CI: "operands could not be broadcast (214,2) (357,2)")."""
    f = SafetyFilter(SKID)
    near = [wall_scan(0.0, x=0.3, beams=360), wall_scan(0.0, x=0.3, y=0.25, beams=720)]
    errors: list[BaseException] = []
    stop = threading.Event()

    def ingest() -> None:
        k = 0
        while not stop.is_set():
            t = 0.05 * k
            scan = dataclasses.replace(near[k % 2], stamp=t)
            f(Twist2D(), frame(t, scan))
            k += 1

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as possible: the window is a few bytecodes
    writer = threading.Thread(target=ingest, daemon=True)
    writer.start()
    try:
        for i in range(1500):
            try:
                f.nearest_reading(0.05 * i)
                f.free_motions(0.05 * i)
            except Exception as exc:
                errors.append(exc)
                break
    finally:
        stop.set()
        writer.join(10.0)
        sys.setswitchinterval(old)
    assert errors == []
