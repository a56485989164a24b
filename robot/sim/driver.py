"""``SimDriver``: the simulator behind the same ``Driver`` protocol as the serial base.

``read()`` steps the physics in fixed substeps up to ``clock.now()`` and returns everything new:
the latest lidar scan (scans are taken at the profile's rate, from the pose at their own stamp),
cumulative wheel ticks, the gyro averaged over the interval (an integrating IMU, as the base
firmware reports it), IR readings, battery voltage and whether the body collided. With a
``VirtualClock`` and a fixed seed every run is bit-for-bit repeatable.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import LaserScan, Pose2D, Twist2D
from robot.base import ImuReading, IrReading, SensorFrame, WheelTicks
from robot.clock import Clock
from robot.profiles import RobotProfile
from robot.sim.ir import SimIr
from robot.sim.lidar import SimLidar
from robot.sim.physics import SimBody, SimOptions
from robot.sim.world import World


class SimDriver:
    """A simulated robot base implementing ``robot.base.Driver``."""

    def __init__(
        self,
        world: World,
        profile: RobotProfile,
        clock: Clock,
        seed: int = 0,
        start_pose: Pose2D | None = None,
        options: SimOptions | None = None,
    ) -> None:
        self.world = world
        self.profile = profile
        self.clock = clock
        self.options = options or SimOptions()
        self.rng = np.random.default_rng(seed)
        pose = start_pose if start_pose is not None else world.start_pose
        self.body = SimBody(profile, self.options, self.rng, pose)
        self.lidar = SimLidar(profile.lidar, self.rng, noise=self.options.lidar_noise)
        self.ir = SimIr(profile.ir)
        self._dt = 1.0 / self.options.physics_rate_hz
        self._t0 = clock.now()
        self._k = 0  # substeps taken; simulated time is t0 + k dt (no accumulated rounding)
        self._t = self._t0
        self._next_scan = self._t
        self._next_ir = self._t
        self._cmd = Twist2D()
        self._estop = False
        self._ir_blocked = False
        self._ir_reading: IrReading | None = None
        self._gyro_sum = 0.0
        self._gyro_n = 0
        self._collision = False
        self._scan: LaserScan | None = None
        self._charge = 1.0
        bias = profile.imu.gyro_bias if self.options.gyro_noise else 0.0
        self._gyro_bias = bias
        self._gyro_std = profile.imu.gyro_noise_std if self.options.gyro_noise else 0.0

    # ----------------------------------------------------------------------------- Driver API

    def command(self, cmd: Twist2D) -> None:
        if not cmd.is_finite():
            raise ValueError(f"non-finite velocity command {cmd}")
        self._cmd = Twist2D(float(cmd.vx), float(cmd.vy), float(cmd.wz))

    def stop(self) -> None:
        self._cmd = Twist2D()

    def estop(self) -> None:
        self._estop = True
        self._cmd = Twist2D()
        self.body.velocity = Twist2D()

    def reset(self) -> None:
        self._estop = False

    def close(self) -> None:
        self._cmd = Twist2D()

    @property
    def estopped(self) -> bool:
        return self._estop

    def read(self) -> SensorFrame:
        """Step physics to ``clock.now()`` and return everything new since the last call."""
        now = self.clock.now()
        steps = math.floor((now - self._t) / self._dt + 1e-9)
        for _ in range(max(0, steps)):
            self._substep()
        self._maybe_scan()  # also covers a read at the very start (t0 has a scan)
        stamp = self._t
        imu = None
        if self._gyro_n:
            ax, ay = self.body.last_accel
            imu = ImuReading(stamp, self._gyro_sum / self._gyro_n, (ax, ay, 9.81))
            self._gyro_sum, self._gyro_n = 0.0, 0
        frame = SensorFrame(
            stamp=stamp,
            scan=self._scan,
            ticks=WheelTicks(stamp, self.body.ticks()),
            imu=imu,
            ir=self._ir_reading,
            battery_v=self.battery_v,
            base_stopped_by_obstacle=self._ir_blocked,
            collision=self._collision,
        )
        self._scan, self._ir_reading, self._collision = None, None, False
        return frame

    # -------------------------------------------------------------------------- simulation API

    @property
    def truth_pose(self) -> Pose2D:
        """Ground-truth pose of base_link in the map frame."""
        return self.body.pose

    @property
    def truth_velocity(self) -> Twist2D:
        return self.body.velocity

    @property
    def sim_time(self) -> float:
        return self._t

    @property
    def battery_v(self) -> float:
        p = self.profile
        return p.battery_empty_v + (p.battery_full_v - p.battery_empty_v) * self._charge

    def teleport(self, pose: Pose2D) -> None:
        """Move the body instantly (kidnapping); velocities are zeroed, encoders do not notice."""
        self.body.pose = pose
        self.body.velocity = Twist2D()

    # ------------------------------------------------------------------------------- internals

    def _target(self) -> Twist2D:
        if self._estop:
            return Twist2D()
        cmd = self._cmd
        if self._ir_blocked and cmd.vx > 0:
            cmd = Twist2D(0.0, cmd.vy, cmd.wz)
        return cmd

    def _substep(self) -> None:
        dt = self._dt
        if self._t + 1e-12 >= self._next_ir:
            self._next_ir += 1.0 / self.options.ir_rate_hz
            reading = self.ir.read(self.world, self.body.pose, self._t)
            self._ir_reading = reading
            self._ir_blocked = self.options.ir_stop and bool(np.any(reading.triggered))
            if self._ir_blocked and self.body.velocity.vx > 0:  # the interrupt cuts the motors
                v = self.body.velocity
                self.body.velocity = Twist2D(0.0, v.vy, v.wz)
        if self._estop:
            self.body.velocity = Twist2D()
        if self.body.step(self.world, self._target(), dt):
            self._collision = True
        self._k += 1
        self._t = self._t0 + self._k * dt
        noise = self._gyro_std * self.body.noise.next() if self._gyro_std > 0 else 0.0
        self._gyro_sum += self.body.true_yaw_rate + self._gyro_bias + noise
        self._gyro_n += 1
        speed = abs(self.body.velocity.vx) + abs(self.body.velocity.vy)
        load = 0.5 + 0.5 * min(1.0, speed / max(self.profile.limits.max_vel_x, 1e-6))
        self._charge = max(0.0, self._charge - load * dt / self.options.battery_life_s)
        self._maybe_scan()

    def _maybe_scan(self) -> None:
        if self._t + 1e-12 >= self._next_scan:
            self._next_scan += self.lidar.period
            self._scan = self.lidar.scan(self.world, self.body.pose, self._t)
