"""The session's control loop on a virtual clock: deterministic, limits enforced, deadman and faults."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from app.limits import CommandRefused
from app.modes import Mode
from app.session import Session, SessionOptions, _prioritize_this_thread
from nav.types import Twist2D
from robot.clock import RealClock, VirtualClock
from robot.profiles import load_profile
from robot.sim import SimDriver, World


def make_session(seed: int = 3, world: str = "apartment") -> Session:
    clock = VirtualClock()
    w = World.stock(world)
    driver = SimDriver(w, load_profile("skid4"), clock, seed=seed, start_pose=w.start_pose)
    return Session(driver, clock=clock, grid=w.grid, start_pose=w.start_pose)


def drive(session: Session, cmd: Twist2D, seconds: float) -> None:
    for _ in range(round(seconds / session.period)):
        session.set_teleop(cmd, "test")
        session.run_for(session.period)


def test_same_seed_same_trajectory() -> None:
    poses = []
    for _ in range(2):
        s = make_session(seed=11)
        s.request_mode("teleop")
        drive(s, Twist2D(0.2, 0.0, 0.3), 3.0)
        poses.append(s.pose)
    assert poses[0] == poses[1]


def test_teleop_drives_and_deadman_stops() -> None:
    s = make_session()
    s.request_mode("teleop")
    start = s.pose
    drive(s, Twist2D(0.2, 0.0, 0.0), 1.0)
    assert 0.15 < s.pose.distance_to(start) < 0.22
    s.run_for(0.6)  # no commands: deadman
    assert s.last_command.is_zero()
    stopped_at = s.pose
    s.run_for(1.0)
    assert s.pose.distance_to(stopped_at) < 0.01


def test_commands_beyond_limits_are_clamped() -> None:
    s = make_session()
    s.request_mode("teleop")
    lim = s.profile.limits
    # a little over the limits (within the 2x sanity bound): clamped and reported
    drive(s, Twist2D(1.5 * lim.max_vel_x, 0.3, 1.5 * lim.max_vel_theta), 1.0)
    assert s.last_command.vx == pytest.approx(lim.max_vel_x)
    assert s.last_command.vy == 0.0 and s.last_command.wz == pytest.approx(lim.max_vel_theta)
    assert set(s.last_clamped) == {"linear.x", "linear.y", "angular.z"}


def test_estop_stops_within_one_period_and_latches() -> None:
    s = make_session()
    s.request_mode("teleop")
    drive(s, Twist2D(0.2, 0.0, 0.0), 1.0)
    s.estop("test")
    s.set_teleop(Twist2D(0.2, 0.0, 0.0), "test")
    s.run_for(s.period)
    assert s.modes.mode == Mode.ESTOP and s.last_command.is_zero() and s.driver.estopped
    drive(s, Twist2D(0.2, 0.0, 0.0), 0.5)
    assert s.last_command.is_zero()
    s.reset()
    s.run_for(s.period)  # the driver's latch is released at the next tick
    assert s.modes.mode == Mode.IDLE and not s.driver.estopped


def test_lidar_silence_faults_and_stops() -> None:
    s = make_session()
    s.request_mode("teleop")
    drive(s, Twist2D(0.2, 0.0, 0.0), 0.5)
    s.driver.lidar_enabled = False  # the simulated lidar stops publishing
    drive(s, Twist2D(0.2, 0.0, 0.0), 2.0)
    assert s.modes.mode == Mode.FAULT and "lidar" in (s.fault or "")
    assert s.last_command.is_zero()
    with pytest.raises(Exception, match="lidar"):
        s.reset()
    s.driver.lidar_enabled = True
    s.run_for(0.5)
    assert s.reset() == Mode.IDLE


def test_real_time_loop_thread_asks_for_priority_and_workers_do_not_keep_it() -> None:
    """On a real clock the loop thread asks for ``loop_nice`` (granted to root / CAP_SYS_NICE) and
    the worker threads it starts go back to the process's nice value."""
    clock = RealClock()
    w = World.stock("apartment")
    driver = SimDriver(w, load_profile("skid4"), clock, seed=1, start_pose=w.start_pose)
    s = Session(
        driver, clock=clock, grid=w.grid, start_pose=w.start_pose, options=SessionOptions(loop_nice=-5)
    )
    process_nice = os.getpriority(os.PRIO_PROCESS, os.getpid())
    s.start()
    try:
        deadline = time.monotonic() + 5.0
        while s.stats.nice is None and time.monotonic() < deadline:
            time.sleep(0.01)
        privileged = os.geteuid() == 0
        assert s.stats.nice == (-5 if privileged else process_nice)
        # a worker thread is created by the thread that first submits: do that from a prioritized one
        futures = []

        def submit_from_prioritized_thread() -> None:
            _prioritize_this_thread(-5)
            futures.append(
                s.workers.submit(lambda: os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
            )

        t = threading.Thread(target=submit_from_prioritized_thread)
        t.start()
        t.join()
        assert futures[0].result(timeout=5.0) == process_nice
    finally:
        s.close()


@pytest.mark.parametrize(
    "cmd, component",
    [
        (Twist2D(1e308, 0.0, 0.0), "linear.x"),
        (Twist2D(200.0, 0.0, 0.0), "linear.x"),  # mm/s sent as m/s
        (Twist2D(-0.6, 0.0, 0.0), "linear.x"),
        (Twist2D(0.1, 0.0, 2.5), "angular.z"),
        (Twist2D(0.1, 5.0, 0.0), "linear.y"),
        (Twist2D(float("nan"), 0.0, 0.0), "linear.x"),
    ],
)
def test_command_beyond_sanity_bound_is_refused_and_stops(cmd: Twist2D, component: str) -> None:
    s = make_session()
    s.request_mode("teleop")
    drive(s, Twist2D(0.2, 0.0, 0.0), 1.0)
    assert s.last_command.vx > 0.15
    with pytest.raises(CommandRefused) as info:
        s.set_teleop(cmd, "test")
    assert list(info.value.beyond) == [component] and "refused" in str(info.value)
    assert s.events[-1]["type"] == "refused" and component in s.events[-1]["reason"]
    s.run_for(0.3)  # inside the 0.5 s deadman: only the refusal can have stopped it (2.5 m/s^2 ramp)
    assert s.last_command.is_zero() and s.modes.mode == Mode.TELEOP
    for _ in range(10):  # repeated at 20 Hz: refused every time, one event for the run
        with pytest.raises(CommandRefused):
            s.set_teleop(cmd, "test")
        s.run_for(s.period)
    assert sum(e["type"] == "refused" for e in s.events) == 1


def test_the_trail_is_one_array_until_it_gains_a_point() -> None:
    """Standing still, every snapshot carries the same read-only trail array (it used to be copied
    from the deque on every tick, and the 3D view, which redraws the trail when the array is a new
    object, redrew it at every snapshot); driving on adds points and gives a new array."""
    s = make_session()
    s.request_mode(Mode.TELEOP)
    drive(s, Twist2D(0.2, 0.0, 0.0), 1.0)
    drive(s, Twist2D(), 1.0)
    still = s.bus.latest.trail
    drive(s, Twist2D(), 0.5)
    assert s.bus.latest.trail is still and not still.flags.writeable
    drive(s, Twist2D(0.2, 0.0, 0.0), 1.0)
    moved = s.bus.latest.trail
    assert moved is not still and len(moved) > len(still)
    assert np.allclose(moved[: len(still)], still) or len(moved) == s.options.trail_length
