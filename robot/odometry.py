"""Wheel odometry: cumulative encoder ticks (+ optional gyro) -> odom-frame pose and body twist.

Pipeline (source A): tick deltas -> wheel travel (``2 pi r dticks / ticks_per_rev``) -> virtual
wheels (skid) -> exact arc update (source B). When a gyro is present its yaw increment replaces the
encoder one: skid-steer wheels scrub when turning, so the encoder yaw is unreliable while the
linear travel is fine ("linear speed from encoders, angular speed from the IMU gyro"). The gyro
bias is estimated while the wheels stand still (a zero-velocity update), and a wheel-slip flag is
raised when the encoder yaw rate and the gyro disagree. Omni bases use the least-squares forward
kinematics and the exact SE(2) update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav.types import Pose2D, Twist2D, wrap_angle
from robot.base import ImuReading, WheelTicks
from robot.kinematics import integrate_arc, integrate_twist, omni_forward, virtual_wheels
from robot.profiles import RobotProfile


class OdometryError(ValueError):
    """Ticks do not match the profile (wrong wheel count) or time went backwards."""


@dataclass(frozen=True)
class OdometryOptions:
    """Options for ``WheelOdometry``."""

    use_imu: bool = True
    """Take the yaw increment from the gyro when an ImuReading is given (source A). Default True."""
    bias_time_constant: float = 2.0
    """Seconds; time constant of the running gyro-bias estimate while standing still. Default 2.0."""
    slip_threshold: float = 0.25
    """rad/s; encoder-vs-gyro yaw rate disagreement above which ``slipping`` is raised. Default 0.25."""
    max_dt: float = 1.0
    """Seconds; a gap longer than this between tick readings is integrated but not used for
    velocity or bias estimation (link hiccup). Default 1.0."""


@dataclass(frozen=True)
class OdometryState:
    """Result of one update: odom-frame pose, body twist, and health flags."""

    stamp: float
    pose: Pose2D
    twist: Twist2D
    slipping: bool = False
    gyro_bias: float = 0.0
    interval: float = 0.0  # seconds since the previous reading (0 for the first)
    encoder_yaw_rate: float | None = None  # rad/s from the wheels over ``interval`` (None: not measured)
    gyro_yaw_rate: float | None = None  # rad/s from the gyro minus the bias, whether or not fused


class WheelOdometry:
    """Integrates cumulative ``WheelTicks`` (and optionally the gyro) for one robot profile."""

    def __init__(
        self, profile: RobotProfile, options: OdometryOptions | None = None, pose: Pose2D | None = None
    ) -> None:
        self.profile = profile
        self.options = options or OdometryOptions()
        self._metres_per_tick = 2.0 * math.pi * profile.wheel_radius / profile.ticks_per_rev
        self.pose = pose or Pose2D()
        self.twist = Twist2D()
        self.gyro_bias = 0.0
        self.slipping = False
        self._last: WheelTicks | None = None
        self._bias_seeded = False
        self._rates: tuple[float, float | None, float | None] = (0.0, None, None)  # interval, enc, gyro

    def reset(self, pose: Pose2D | None = None) -> None:
        """Restart integration at ``pose`` (odom origin by default); keeps the gyro bias."""
        self.pose = pose or Pose2D()
        self.twist = Twist2D()
        self._last = None

    @property
    def state(self) -> OdometryState:
        stamp = self._last.stamp if self._last is not None else 0.0
        return OdometryState(stamp, self.pose, self.twist, self.slipping, self.gyro_bias, *self._rates)

    def update(self, ticks: WheelTicks, imu: ImuReading | None = None) -> OdometryState:
        """Fold in a new cumulative tick reading. ``imu.gyro_z`` is taken as the mean yaw rate over
        the interval since the previous reading (the simulator and the base firmware report that)."""
        counts = np.asarray(ticks.counts, dtype=np.int64)
        expected = self.profile.wheel_count
        if counts.shape != (expected,):
            raise OdometryError(
                f"expected {expected} wheel counts for {self.profile.kinematics}, got {counts.shape}"
            )
        last, self._last = self._last, WheelTicks(ticks.stamp, counts)
        self._rates = (0.0, None, None)
        if last is None:
            return self.state
        dt = ticks.stamp - last.stamp
        if dt < 0:
            raise OdometryError(f"tick stamp went backwards by {-dt:.6f} s")
        travel = (counts - last.counts).astype(float) * self._metres_per_tick
        gyro_ok = imu is not None and self.options.use_imu and math.isfinite(imu.gyro_z)
        timing_ok = 0 < dt <= self.options.max_dt
        still = not np.any(counts != last.counts)
        if gyro_ok and timing_ok and still:
            self._update_bias(imu.gyro_z, dt)  # type: ignore[union-attr]
        if self.profile.kinematics == "omni":
            dx, dy, dth_enc = omni_forward(travel, self.profile.omni_radius)
            dx, dy, dth_enc = float(dx), float(dy), float(dth_enc)
        else:
            dl, dr = virtual_wheels(travel)
            dx, dy, dth_enc = (
                (float(dl) + float(dr)) / 2.0,
                0.0,
                (float(dr) - float(dl)) / self.profile.track_width,
            )
        if timing_ok:  # the raw yaw rates, for fault monitors comparing wheels with the gyro
            gyro = imu.gyro_z - self.gyro_bias if imu is not None and math.isfinite(imu.gyro_z) else None
            self._rates = (dt, dth_enc / dt, gyro)
        dth = dth_enc
        if gyro_ok and dt > 0:
            dth = 0.0 if still else (imu.gyro_z - self.gyro_bias) * dt  # type: ignore[union-attr]
            self.slipping = timing_ok and abs(dth_enc - dth) / dt > self.options.slip_threshold
        else:
            self.slipping = False
        if self.profile.kinematics == "omni":
            if dt > 0:
                self.pose = integrate_twist(self.pose, Twist2D(dx / dt, dy / dt, dth / dt), dt)
            else:
                self.pose = integrate_twist(self.pose, Twist2D(dx, dy, dth), 1.0)
        else:
            self.pose = integrate_arc(self.pose, dx, dth)
        self.pose = Pose2D(self.pose.x, self.pose.y, float(wrap_angle(self.pose.theta)))
        if timing_ok:
            self.twist = Twist2D(dx / dt, dy / dt, dth / dt)
        return self.state

    def _update_bias(self, gyro_z: float, dt: float) -> None:
        if not self._bias_seeded:
            self.gyro_bias, self._bias_seeded = gyro_z, True
            return
        alpha = min(1.0, dt / self.options.bias_time_constant)
        self.gyro_bias += alpha * (gyro_z - self.gyro_bias)
