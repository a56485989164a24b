"""Odometry from hardware: encoder counts and gyro from the emulated STM32 over a pseudo-terminal,
through ``SerialDriver`` and ``WheelOdometry``, against closed-form motions and the simulator's truth.

Closed forms (source A): a straight run of length ``d`` turns every wheel by ``d / (2 pi r)``
revolutions; an in-place turn by ``phi`` rolls the left wheels ``-phi L / 2`` and the right wheels
``+phi L / 2``. Real time, a few seconds per test: each motion runs until it happened (``Run.until``),
so a starved emulator on a loaded machine only makes it take longer.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

from nav.types import Pose2D, Twist2D, wrap_angle
from robot.odometry import OdometryOptions, WheelOdometry
from robot.profiles import load_profile
from robot.serial.driver import SerialDriver, SerialOptions, wait_for
from robot.serial.emulate import EmulatorPair

PROFILE = load_profile("skid4")
TICKS_PER_M = PROFILE.ticks_per_rev / (2 * math.pi * PROFILE.wheel_radius)


@pytest.fixture
def pair(tmp_path) -> Iterator[EmulatorPair]:
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path, seed=7, lidar=False) as p:
        yield p


@pytest.fixture
def driver(pair: EmulatorPair) -> Iterator[SerialDriver]:
    d = SerialDriver(SerialOptions(pair.base_path, link_timeout=1.0), PROFILE)
    assert wait_for(lambda: d.telemetry is not None, timeout=5.0)
    yield d
    d.close()


class Run:
    """A 20 Hz control loop feeding fused (gyro) and encoder-only odometry, and tracking the truth."""

    def __init__(self, pair: EmulatorPair, driver: SerialDriver) -> None:
        self.pair, self.driver = pair, driver
        self.fused = WheelOdometry(PROFILE)
        self.encoders = WheelOdometry(PROFILE, OdometryOptions(use_imu=False))
        self.first: np.ndarray | None = None
        self.counts: np.ndarray | None = None
        self.truth0 = pair.pump.truth_pose
        self.truth_yaw = 0.0
        self._prev_th = self.truth0.theta
        self.slip_seen = 0
        self.unchanged = 0  # ticks of the loop since the counts last changed

    def until(self, cmd: Twist2D, done, timeout: float = 30.0) -> None:
        """Run the 20 Hz loop commanding ``cmd`` until ``done()`` (or ``timeout`` s, then fail)."""
        end = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < end, f"not done after {timeout} s"
            self.tick(cmd)

    def tick(self, cmd: Twist2D) -> None:
        self.driver.command(cmd)
        frame = self.driver.read()
        self.unchanged += 1
        if frame.ticks is not None:
            if self.first is None:
                self.first = frame.ticks.counts.copy()
            if self.counts is None or not np.array_equal(self.counts, frame.ticks.counts):
                self.unchanged = 0
            self.counts = frame.ticks.counts.copy()
            self.slip_seen += self.fused.update(frame.ticks, frame.imu).slipping
            self.encoders.update(frame.ticks)
        th = self.pair.pump.truth_pose.theta
        self.truth_yaw += float(wrap_angle(th - self._prev_th))
        self._prev_th = th
        time.sleep(0.05)

    def settle(self) -> None:
        """Stop and wait until the robot stands still and its counts stopped changing."""
        self.until(Twist2D(), lambda: self.pair.pump.sim.truth_velocity.is_zero() and self.unchanged >= 5)

    @property
    def dticks(self) -> np.ndarray:
        assert self.first is not None and self.counts is not None
        return self.counts - self.first

    @property
    def truth(self) -> Pose2D:
        """Ground-truth motion in the start pose's frame."""
        return self.pair.pump.truth_pose.relative_to(self.truth0)


def test_straight_line_counts_and_pose_match_closed_form(pair: EmulatorPair, driver: SerialDriver) -> None:
    run = Run(pair, driver)
    run.settle()  # a still reading first: the gyro bias and the zero of the counts
    run.until(Twist2D(0.2, 0.0, 0.0), lambda: run.truth.x > 0.25)
    run.settle()
    d = run.truth.x
    expected = np.full(4, d * TICKS_PER_M)
    # the simulator's 2 % multiplicative slip noise is all that separates counts from the truth
    np.testing.assert_allclose(run.dticks, expected, rtol=0.03, atol=3)
    for odo in (run.fused, run.encoders):
        assert odo.pose.x == pytest.approx(d, rel=0.03, abs=0.005)
        assert abs(odo.pose.y) < 0.01 and abs(odo.pose.theta) < 0.03
    assert run.slip_seen == 0


def test_pure_rotation_counts_and_heading_match_closed_form(pair: EmulatorPair, driver: SerialDriver) -> None:
    run = Run(pair, driver)
    run.settle()
    run.until(Twist2D(0.0, 0.0, 0.8), lambda: run.truth_yaw > 1.4)
    run.settle()
    phi = run.truth_yaw
    arc = phi * PROFILE.track_width / 2 * TICKS_PER_M
    np.testing.assert_allclose(run.dticks, [-arc, -arc, arc, arc], rtol=0.04, atol=3)
    assert run.fused.pose.theta == pytest.approx(phi, abs=0.05)  # gyro heading
    assert run.encoders.pose.theta == pytest.approx(phi, rel=0.04)  # encoder heading
    for odo in (run.fused, run.encoders):
        assert math.hypot(odo.pose.x, odo.pose.y) < 0.01  # in place
    assert math.hypot(run.truth.x, run.truth.y) < 0.01


def test_slip_detected_when_encoders_and_gyro_disagree(pair: EmulatorPair, driver: SerialDriver) -> None:
    """Right wheels spinning 0.15 m/s faster than the ground moves them while driving straight: the
    encoders claim a 0.4 rad/s turn the gyro does not see. The slip flag rises and the gyro-fused
    heading stays true while the encoder-only heading drifts."""
    run = Run(pair, driver)
    run.settle()
    run.until(Twist2D(0.15, 0.0, 0.0), lambda: run.truth.x > 0.06)
    assert run.slip_seen == 0
    pair.base.set_wheel_slip([0.0, 0.0, 0.15, 0.15])
    run.until(Twist2D(0.15, 0.0, 0.0), lambda: run.encoders.pose.theta > 0.3)
    pair.base.set_wheel_slip(None)
    assert run.slip_seen >= 3, run.slip_seen  # ~0.75 s of slipping: ~15 updates, fewer if starved
    assert abs(run.truth.theta) < 0.05
    assert abs(wrap_angle(run.fused.pose.theta - run.truth.theta)) < 0.05
    assert run.encoders.pose.theta > 0.25  # what encoder-only odometry would have believed
    flags_before = run.slip_seen
    x = run.truth.x
    run.until(Twist2D(0.15, 0.0, 0.0), lambda: run.truth.x > x + 0.07)  # off the slippery patch
    assert not run.fused.slipping
    assert run.slip_seen - flags_before <= 2
