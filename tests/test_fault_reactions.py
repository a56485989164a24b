"""Session fault reactions end to end (issue 9 part 3): a simulator fault switch is flipped under a
driving robot; the session must command zero in the tick it detects the fault, enter FAULT with the
reason, record a ``fault`` event in the run, refuse a reset while the cause holds and accept it after."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from app.db import make_engine, migrate
from app.fault_monitor import FaultMonitorOptions, classify_scan
from app.modes import Mode, TransitionRefused
from app.recorder import Recorder, RecorderOptions
from app.runs.store import RunFilters, RunsStore
from app.session import Session, SessionOptions
from nav.types import LaserScan, Pose2D, Twist2D
from robot.clock import RealClock, VirtualClock
from robot.profiles import load_profile
from robot.sim import SimDriver, World
from robot.sim.faults import FaultSpecError, SimFaults

STRAIGHT = Twist2D(0.2, 0.0, 0.0)


@pytest.fixture
def rig(tmp_path: Path):
    engine = make_engine(f"sqlite:///{tmp_path / 'runs.db'}")
    migrate(engine)
    clock = VirtualClock()
    world, start = World.box(14, 8), Pose2D(2.0, 4.0, 0.0)  # 11 m of free floor ahead
    driver = SimDriver(world, load_profile("skid4"), clock, seed=4, start_pose=start)
    session = Session(driver, clock=clock, grid=world.grid, start_pose=start)
    store = RunsStore(engine)
    rec = Recorder(session, store, RecorderOptions(idle_grace=60.0))
    rec.start()
    yield session, rec, store
    rec.close()
    session.close()
    engine.dispose()


def tick(s: Session, cmd: Twist2D | None) -> None:
    if cmd is not None:
        s.set_teleop(cmd, "test")
    s.run_for(s.period)


def drive_until_fault(s: Session, cmd: Twist2D, max_s: float) -> float:
    """Drive tick by tick; return the seconds until FAULT. In the detecting tick the command sent to
    the driver must already be zero (stopped within one control period of detection)."""
    for k in range(round(max_s / s.period)):
        tick(s, cmd)
        if s.fault is not None:
            assert s.modes.mode == Mode.FAULT
            assert s.last_command.is_zero() and s.driver._cmd == Twist2D()
            return (k + 1) * s.period
    raise AssertionError(f"no fault within {max_s} s (mode {s.modes.mode})")


def fault_events(rec: Recorder, store: RunsStore) -> list[dict]:
    rec.sync()
    _, runs = store.list(RunFilters())
    assert runs, "no run was recorded"
    return [e for e in store.detail(runs[0]["id"])["events"] if e["type"] == "fault"]


def reset_refused(s: Session, match: str) -> None:
    with pytest.raises(TransitionRefused, match=match):
        s.reset()
    assert s.modes.mode == Mode.FAULT


def drives_again(s: Session) -> None:
    assert s.reset() == Mode.IDLE
    s.request_mode("teleop")
    tick(s, Twist2D())  # the operator lets go first: a reset re-arms teleop only on a zero command
    start = s.pose
    for _ in range(20):
        tick(s, STRAIGHT)
    assert s.fault is None and s.pose.distance_to(start) > 0.1 and s.collisions == 0


def test_lidar_garbage_faults_stops_records_and_recovers(rig) -> None:
    s, rec, store = rig
    s.request_mode("teleop")
    for _ in range(20):
        tick(s, STRAIGHT)
    s.driver.faults.lidar_garbage = 0.9
    t = drive_until_fault(s, STRAIGHT, 2.0)
    assert t < 1.0 and s.fault.startswith("lidar garbage")  # 3 scans at 5.5 Hz
    assert any(e["reason"].startswith("lidar garbage") for e in fault_events(rec, store))
    reset_refused(s, "lidar garbage")
    s.driver.faults.lidar_garbage = 0.0
    s.run_for(0.5)  # a clean scan arrives
    drives_again(s)


def test_isolated_bad_beams_are_sanitized_without_a_fault(rig) -> None:
    s, _, _ = rig
    s.request_mode("teleop")
    s.driver.faults.lidar_garbage = 0.05
    for _ in range(60):
        tick(s, STRAIGHT)
    assert s.fault is None and s.modes.mode == Mode.TELEOP
    r = s.last_scan.ranges
    finite = r[np.isfinite(r)]
    assert (
        np.isnan(r).any() and finite.min() >= s.last_scan.range_min and finite.max() <= s.last_scan.range_max
    )
    assert s.fault_monitor.sanitized_beams > 0


def test_classify_scan_rules() -> None:
    def scan(r: list[float]) -> LaserScan:
        return LaserScan(0.0, 0.0, 0.1, np.asarray(r, dtype=float), 0.15, 6.0)

    clean, frac, garbage = classify_scan(scan([1.0, np.inf, -1.0, 2.0, 1e6, 3.0, -np.inf, 6.5]), 0.5)
    assert not garbage and frac == pytest.approx(2 / 8)
    assert np.isnan(clean.ranges[[2, 4]]).all() and np.isposinf(clean.ranges[1])
    assert np.isneginf(clean.ranges[6]) and clean.ranges[7] == 6.5  # REP-117 too close; a bit past spec
    assert classify_scan(scan([np.inf] * 8), 0.5)[2] is None  # nothing within range: open space (issue 16)
    assert "invalid beams" in classify_scan(scan([np.nan, -1.0, 1.0]), 0.5)[2]  # mostly invalid
    assert classify_scan(scan([]), 0.5)[2] == "empty scan (0 beams)"
    assert classify_scan(scan([1.0] * 8), 0.5, expected_beams=360)[2].startswith("wrong beam count")


def test_encoder_slip_faults_and_refaults_until_repaired(rig) -> None:
    s, rec, store = rig
    s.request_mode("teleop")
    for _ in range(20):
        tick(s, STRAIGHT)
    s.driver.faults.apply("encoder_slip=0:0")  # front-left encoder dead
    t = drive_until_fault(s, STRAIGHT, 3.0)
    assert t <= 1.5 and s.fault.startswith("encoder slip")
    assert any(e["reason"].startswith("encoder slip") for e in fault_events(rec, store))
    s.run_for(0.5)
    assert s.reset() == Mode.IDLE  # slip cannot be judged standing: reset allowed ...
    s.request_mode("teleop")
    tick(s, Twist2D())  # a fresh command after the reset (see drives_again)
    assert drive_until_fault(s, STRAIGHT, 3.0) <= 1.5  # ... and it faults again while the slip lasts
    s.driver.faults.clear()
    s.run_for(0.5)
    drives_again(s)


def test_imu_bias_jump_faults_until_the_bias_is_re_estimated(rig) -> None:
    s, rec, store = rig
    s.run_for(1.0)  # standing at start-up: the odometry learns the gyro bias
    s.request_mode("teleop")
    for _ in range(20):
        tick(s, STRAIGHT)
    s.driver.faults.gyro_bias_jump = 0.3  # rad/s
    t = drive_until_fault(s, STRAIGHT, 2.0)
    assert t <= 1.0 and s.fault.startswith("imu")
    assert any(e["reason"].startswith("imu") for e in fault_events(rec, store))
    s.run_for(0.3)
    reset_refused(s, "imu")  # standing, the gyro still turns against the old bias
    s.run_for(6.0)  # the zero-velocity update re-estimates the bias while standing
    drives_again(s)


def test_sim_fault_spec_loop_delay() -> None:
    f = SimFaults()
    f.apply("loop_delay=0.12")
    assert f.loop_delay == 0.12 and f.describe() == ["loop_delay=0.12"]
    for bad in ("loop_delay=-1", "loop_delay=nan", "loop_delay=60"):
        with pytest.raises(FaultSpecError, match="loop_delay"):
            SimFaults().apply(bad)


def poll(cond, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return False


def test_loop_overrun_faults_with_the_measured_period_and_recovers() -> None:
    """Real clock, real loop thread: every driver read blocks 0.15 s (3 periods)."""
    clock = RealClock()
    world = World.box(8, 8)
    driver = SimDriver(world, load_profile("skid4"), clock, seed=1, start_pose=world.start_pose)
    opts = SessionOptions(faults=FaultMonitorOptions(loop_overrun_ticks=5))
    s = Session(driver, clock=clock, grid=world.grid, start_pose=world.start_pose, options=opts)
    s.start()
    try:
        s.request_mode("teleop")
        driver.faults.loop_delay = 0.15
        assert poll(lambda: s.fault is not None, 20.0), "no loop overrun fault"
        assert s.fault.startswith("loop overrun") and "ms" in s.fault
        period_ms = float(s.fault.split("period ")[1].split(" ms")[0])
        # every tick of the run was late (> 2 x the 50 ms period); on a loaded machine the run may begin
        # with ticks the load made late before the injected 150 ms, so the mean is not always >= 150
        assert period_ms > 100.0
        assert s.modes.mode == Mode.FAULT
        assert poll(lambda: driver._cmd == Twist2D() and s.last_command.is_zero(), 2.0)
        assert any(e["type"] == "fault" and e["reason"].startswith("loop overrun") for e in s.events)
        with pytest.raises(TransitionRefused, match="loop overrun"):
            s.reset()
        driver.faults.loop_delay = 0.0

        def reset_ok() -> bool:
            try:
                return s.reset() == Mode.IDLE
            except TransitionRefused:
                return False

        assert poll(reset_ok, 10.0)
    finally:
        s.close()
