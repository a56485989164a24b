"""``SimDriver``: the simulator behind the same ``Driver`` protocol as the serial base.

``read()`` steps the physics in fixed substeps up to ``clock.now()`` and returns everything new:
the latest lidar scan (scans are taken at the profile's rate, from the pose at their own stamp),
cumulative wheel ticks, the gyro averaged over the interval (an integrating IMU, as the base
firmware reports it), IR readings, battery voltage and whether the body collided. With a
``VirtualClock`` and a fixed seed every run is bit-for-bit repeatable.

People walk in the world (``driver.people``, a ``robot.sim.people.Crowd``) and are stepped with the
physics; fault switches (``driver.faults``, a ``robot.sim.faults.SimFaults``) corrupt what the
driver reports the way failing hardware would.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from nav.types import LaserScan, Pose2D, Twist2D
from robot.base import ImuReading, IrReading, SensorFrame, WheelTicks
from robot.clock import Clock
from robot.profiles import RobotProfile
from robot.sim.faults import SimFaults
from robot.sim.ir import SimIr
from robot.sim.lidar import SimLidar
from robot.sim.people import Crowd
from robot.sim.physics import SimBody, SimOptions
from robot.sim.world import World


class SimDriver:
    """A simulated robot base implementing ``robot.base.Driver``."""

    has_lidar = True  # the simulated lidar can fall silent (fault switch), but it is always expected

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
        self._next_people = self._t
        self._people_t = self._t
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
        self.faults = SimFaults()
        self._tick_offset = np.zeros(profile.wheel_count)  # radians of encoder slip so far, per wheel
        self._slip_angle = self.body.wheel_angle.copy()  # wheel angles when slip was last accounted
        self.collision_with: str | None = None  # what the latest collision was with
        world.people.robot_radius = float(np.max(np.hypot(*self.body.samples.T)))
        world.people.robot_front = float(np.max(self.body.samples[:, 0]))

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
        if self.faults.loop_delay > 0.0:
            time.sleep(self.faults.loop_delay)  # fault switch: a read that stalls the control loop
        now = self.clock.now()
        steps = math.floor((now - self._t) / self._dt + 1e-9)
        for _ in range(max(0, steps)):
            self._substep()
        self._maybe_scan()  # also covers a read at the very start (t0 has a scan)
        stamp = self._t
        imu = None
        if self._gyro_n:
            ax, ay = self.body.last_accel
            gyro = self._gyro_sum / self._gyro_n + self.faults.gyro_bias_jump
            imu = ImuReading(stamp, gyro, (ax, ay, 9.81))
            self._gyro_sum, self._gyro_n = 0.0, 0
        frame = SensorFrame(
            stamp=stamp,
            scan=self._scan,
            ticks=WheelTicks(stamp, self._ticks()),
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
    def people(self) -> Crowd:
        """The people walking in this world: ``add_loop``, ``add_random``, ``add_step_in``, ``add``,
        ``remove(id)``, ``list()``, ``poses()`` ((P, 3) x, y, heading for the 3D view)."""
        return self.world.people

    @property
    def lidar_enabled(self) -> bool:
        """Fault switch: False and the lidar stops publishing (see ``faults``)."""
        return self.faults.lidar_enabled

    @lidar_enabled.setter
    def lidar_enabled(self, value: bool) -> None:
        self.faults.lidar_enabled = bool(value)

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
        v = p.battery_empty_v + (p.battery_full_v - p.battery_empty_v) * self._charge
        return max(0.0, v - self.faults.battery_sag)

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

    def _ticks(self) -> np.ndarray:
        """Encoder counts as the base reports them: the true wheel angles plus any slip the
        ``faults.slip_*`` switches have caused since they were set (accounted once per read)."""
        angle = self.body.wheel_angle
        scale = self.faults.tick_scale(self.profile.wheel_count)
        self._tick_offset += (angle - self._slip_angle) * (scale - 1.0)
        self._slip_angle = angle.copy()
        counted = angle + self._tick_offset
        return np.floor(counted / (2 * math.pi) * self.profile.ticks_per_rev).astype(np.int64)

    def _substep(self) -> None:
        dt = self._dt
        if self._t + 1e-12 >= self._next_people:
            self._next_people += 1.0 / self.options.people_rate_hz
            if len(self.world.people):
                self.world.people.step(self._t - self._people_t, self.body.pose)
            self._people_t = self._t
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
            self.collision_with = self.body.last_hit
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
            if not self.faults.lidar_enabled:
                return  # a silent lidar: no scan (and no ray cast)
            scan = self.lidar.scan(self.world, self.body.pose, self._t)
            if self.faults.lidar_garbage > 0.0:
                scan = replace(scan, ranges=self.faults.corrupt(scan.ranges, self.rng))
            self._scan = scan
