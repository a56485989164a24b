"""Teleop reflex path on a real clock: an operator command reaches the driver between ticks, and a
step the acceleration ramp spreads is finished when the limit allows, not at the next tick. Both
ways: written by the caller's thread (a driver with ``command_thread_safe``, as ``SerialDriver``)
and by the woken loop thread (drivers that take commands from the loop thread only).

Timing-free assertions: the loop runs at 0.5 Hz and what is checked is the *order* of the driver's
calls (a command written before the next ``read``, i.e. the next tick), with polls of generous
deadlines, so a loaded machine cannot make them fail: a woken loop thread has the 2 s period to
write, where a 0.5 s period was once not enough with two busy loops and the suite on 2 cores."""

from __future__ import annotations

import itertools
import threading
import time
from dataclasses import replace

import pytest

from app.session import Session, SessionOptions
from nav.types import Twist2D
from robot.base import SensorFrame
from robot.profiles import RobotProfile, load_profile

ACC = 0.2  # rad/s^2: slow enough that a 0.05 rad/s step takes 0.25 s, an eighth of the 2 s control period
PERIOD_S = 2.0


class RecordingDriver:
    """A driver that logs ``read`` (one per tick) and ``command`` calls in order, with their times."""

    def __init__(self, profile: RobotProfile, thread_safe: bool) -> None:
        self.profile = profile
        self.command_thread_safe = thread_safe
        self.calls: list[tuple[str, float, Twist2D | None]] = []
        self._lock = threading.Lock()

    def _log(self, kind: str, cmd: Twist2D | None = None) -> None:
        with self._lock:
            self.calls.append((kind, time.monotonic(), cmd))

    def snapshot(self) -> list[tuple[str, float, Twist2D | None]]:
        with self._lock:
            return list(self.calls)

    def read(self) -> SensorFrame:
        self._log("read")
        return SensorFrame(stamp=time.monotonic())

    def command(self, cmd: Twist2D) -> None:
        self._log("command", cmd)

    def stop(self) -> None:
        self._log("command", Twist2D())

    def estop(self) -> None:
        self._log("estop")

    def reset(self) -> None:
        self._log("reset")

    def close(self) -> None:
        pass


def _poll(predicate, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.002)
    return bool(predicate())


@pytest.fixture(params=[True, False], ids=["caller-thread", "loop-thread"])
def session(request):
    base = load_profile("skid4")
    profile = replace(base, limits=replace(base.limits, acc_lim_theta=ACC, decel_lim_theta=-ACC))
    driver = RecordingDriver(profile, thread_safe=request.param)
    options = SessionOptions(rate_hz=1.0 / PERIOD_S, lidar_timeout=60.0, deadman_timeout=30.0)
    s = Session(driver, options=options)
    s.request_mode("teleop")
    s.start()
    yield s, driver
    s.close()


def _after_next_tick(driver: RecordingDriver) -> int:
    """Wait until a tick has just sent its command; return the number of calls logged by then."""
    n0 = len(driver.snapshot())
    assert _poll(lambda: any(k == "read" for k, _, _ in driver.snapshot()[n0:]))
    assert _poll(lambda: driver.snapshot()[-1][0] == "command")
    return len(driver.snapshot())


def test_teleop_command_is_written_before_the_next_tick(session) -> None:
    s, driver = session
    s.set_teleop(Twist2D(0.0, 0.0, 0.05), "op")  # ramp up from rest to 0.05 rad/s
    assert _poll(lambda: s.last_command.wz == pytest.approx(0.05))
    n = _after_next_tick(driver)
    s.set_teleop(Twist2D(0.0, 0.0, 0.10), "op")  # just after a tick: the ramp allows ~0 at once
    if driver.command_thread_safe:  # written before set_teleop returned, by this thread
        assert any(k == "command" for k, _, _ in driver.snapshot()[n:])
    assert _poll(lambda: any(c is not None and c.wz > 0.0999 for _, _, c in driver.snapshot()[n:]))
    after = driver.snapshot()[n:]
    kinds = [k for k, _, _ in after]
    first_write = kinds.index("command")
    exact = next(i for i, (_, _, c) in enumerate(after) if c is not None and c.wz > 0.0999)
    # the first frame that reflects the message (a ramp step up) precedes the next tick ...
    assert after[first_write][2].wz > 0.05
    assert "read" not in kinds[:first_write]
    # ... and so does the end of the ramp: 0.25 s after the first step, well before the next tick
    assert "read" not in kinds[:exact], "the ramp's end waited for the next tick"
    assert exact > first_write, "expected a ramp-limited first step (the step needs 0.25 s)"


def test_reflex_steps_respect_the_acceleration_limit(session) -> None:
    s, driver = session
    for target in (0.04, -0.02):
        _after_next_tick(driver)
        s.set_teleop(Twist2D(0.0, 0.0, target), "op")
        assert _poll(lambda t=target: s.last_command.wz == pytest.approx(t))
    writes = [(t, c.wz) for k, t, c in driver.snapshot() if k == "command" and c is not None]
    for (t0, w0), (t1, w1) in itertools.pairwise(writes):
        dt = min(max(t1 - t0, 1e-3), 0.5)
        # the session takes its time a moment before the write is logged (a preempted thread can
        # stretch that): 50 ms of slack still catches a reflex that skips the ramp (a 0.04-0.06 jump
        # a few ms after a tick, where the limit allows ~0.001)
        assert abs(w1 - w0) <= ACC * (dt + 0.05) + 1e-9
