"""The host's link watchdog on a busy host: telemetry that reached the OS buffer but was not decoded
yet (the reader thread stalled: a blocked write, the GIL, a start-up import) makes the link DEGRADED
("late"), not LOST, so a busy server does not fault a healthy robot. A base that really stops sending
is LOST after 300 ms (test_hardware_stack.py, test_serial_driver.py)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from robot.base import LinkState, LinkStatus
from robot.profiles import load_profile
from robot.serial.driver import SerialDriver, SerialOptions, wait_for
from robot.serial.emulate import EmulatorPair

PROFILE = load_profile("skid4")


@pytest.fixture
def pair(tmp_path) -> Iterator[EmulatorPair]:
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path, lidar=False) as p:
        yield p


def test_stalled_reader_with_bytes_waiting_is_late_not_lost(pair: EmulatorPair) -> None:
    # a 1 s link timeout stalled for 1.5 s: "late" lasts up to 5 timeouts, so the check may come up
    # to 3.5 s after it on a loaded machine and still see the stall it is about
    driver = SerialDriver(SerialOptions(pair.base_path, link_timeout=1.0), PROFILE)
    try:
        assert wait_for(lambda: driver.read().link.rx_frames > 10, timeout=10.0)
        out: list[LinkStatus] = []
        # The reader thread blocks in its next keep-alive write (as on a USB adapter whose write
        # hangs for a while); the base keeps sending telemetry into the OS buffer meanwhile.
        with driver._base._write_lock:
            time.sleep(1.5)
            assert driver._base._backlog() > 0
            checker = threading.Thread(target=lambda: out.append(driver.read().link))
            checker.start()
            checker.join(timeout=2.0)  # entering LOST would try to send a stop and block here
        checker.join(timeout=2.0)
        assert out and out[0].state is LinkState.DEGRADED, out
        assert "late" in out[0].reason and "bytes waiting" in out[0].reason
        assert wait_for(lambda: driver.read().link.state is LinkState.OK, timeout=2.0)
    finally:
        driver.close()


def test_late_only_for_a_while_then_lost(pair: EmulatorPair) -> None:
    """Bytes waiting do not hold the link up forever: after 5 link timeouts it is LOST."""
    driver = SerialDriver(pair.base_path, PROFILE)
    try:
        assert wait_for(lambda: driver.read().link.rx_frames > 10, timeout=10.0)
        out: list[LinkStatus] = []
        with driver._base._write_lock:
            time.sleep(1.7)  # > 5 x 0.3 s
            checker = threading.Thread(target=lambda: out.append(driver.read().link))
            checker.start()
            checker.join(timeout=0.5)
        checker.join(timeout=2.0)
        assert out and out[0].state is LinkState.LOST, out
    finally:
        driver.close()
