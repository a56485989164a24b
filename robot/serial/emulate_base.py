"""An emulated STM32 base speaking the navdeck base protocol on a pseudo-terminal.

It plays source A's firmware on top of the simulator: a link task decoding host frames, a
telemetry task at ``TELEMETRY_RATE`` (50 Hz default) reporting encoders (int32, wrapping), gyro,
accelerometer, IR bits, battery and status, the e-stop latch, a 200 ms command watchdog that
stops the motors when VELOCITY frames stop coming, and the IR obstacle interrupt (modelled inside
the simulator's physics substeps, switchable with ``OBSTACLE_STOP_ENABLE``). Parameters behave
like the firmware's: a wrong ``WHEEL_RADIUS`` makes the robot drive at the wrong speed, which is
what the calibration procedure in docs/hardware.md measures.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from nav.types import Twist2D
from robot.base import SensorFrame
from robot.serial.faults import LineFaults
from robot.serial.protocol import (
    PARAM_SAVE_ID,
    ErrorCode,
    ErrorReport,
    EStop,
    Heartbeat,
    Message,
    MessageDecoder,
    ParamGet,
    ParamId,
    ParamSave,
    ParamSet,
    ParamStatus,
    ParamValue,
    Reset,
    ResetMode,
    Sequencer,
    Severity,
    Status,
    Telemetry,
    VelocityCommand,
)
from robot.serial.pty import PtyPort
from robot.serial.simlink import SimPump

# Allowed ranges of the writable parameters (inclusive).
PARAM_RANGES: dict[ParamId, tuple[float, float]] = {
    ParamId.WHEEL_RADIUS: (0.005, 0.5),
    ParamId.TRACK_WIDTH: (0.02, 2.0),
    ParamId.WHEEL_BASE: (0.0, 2.0),
    ParamId.TICKS_PER_REV: (1.0, 1e6),
    ParamId.PID_KP: (0.0, 1e3),
    ParamId.PID_KI: (0.0, 1e3),
    ParamId.PID_KD: (0.0, 1e3),
    ParamId.CMD_TIMEOUT: (0.05, 2.0),
    ParamId.TELEMETRY_RATE: (10.0, 200.0),
    ParamId.OBSTACLE_STOP_ENABLE: (0.0, 1.0),
    ParamId.OMNI_RADIUS: (0.02, 2.0),
    ParamId.BATTERY_CUTOFF: (0.0, 60.0),
}


@dataclass
class _Sensors:
    """Sensor state accumulated from the simulator between two telemetry frames."""

    counts: np.ndarray
    gyro_integral: float = 0.0  # rad turned since the last telemetry frame
    gyro_time: float = 0.0  # s of IMU samples in that integral
    gyro_last: float = 0.0  # rate of the newest sample, repeated when no new sample came
    imu_stamp: float | None = None
    accel: tuple[float, float, float] = (0.0, 0.0, 9.81)
    ir_bits: int = 0
    battery_v: float = 12.0
    obstacle_stop: bool = False


class BaseEmulator:
    """Firmware emulator bound to a ``SimPump`` and a ``PtyPort`` (``path`` is what the host opens)."""

    def __init__(self, pump: SimPump, port: PtyPort | None = None, faults: LineFaults | None = None) -> None:
        self.pump = pump
        self.profile = pump.profile
        self.port = port or PtyPort(name="base")
        self.faults = faults or LineFaults()
        p = self.profile
        self.defaults: dict[int, float] = {
            ParamId.WHEEL_RADIUS: p.wheel_radius,
            ParamId.TRACK_WIDTH: p.track_width,
            ParamId.WHEEL_BASE: p.wheel_base,
            ParamId.TICKS_PER_REV: float(p.ticks_per_rev),
            ParamId.PID_KP: 1.2,
            ParamId.PID_KI: 8.0,
            ParamId.PID_KD: 0.0,
            ParamId.CMD_TIMEOUT: 0.2,
            ParamId.TELEMETRY_RATE: 50.0,
            ParamId.OBSTACLE_STOP_ENABLE: 1.0,
            ParamId.OMNI_RADIUS: p.omni_radius,
            ParamId.BATTERY_CUTOFF: p.battery_empty_v,
        }
        self.params = dict(self.defaults)
        # the parameter record in flash: written only by PARAM_SAVE, loaded at (re)boot
        self.flash: dict[int, float] | None = None
        self._lock = threading.Lock()
        self._sensors = _Sensors(np.zeros(4, dtype=np.int64))
        self._enc_offset = np.zeros(4, dtype=np.int64)
        self._slip_speed = np.zeros(4)  # m/s of rim speed the ground does not take (fault switch)
        self._slip_angle = np.zeros(4)  # rad of wheel rotation added by slip so far
        self._last_stamp: float | None = None
        self._decoder = MessageDecoder()
        self._seq = Sequencer()
        self._t0 = time.monotonic()
        self._last_cmd = -1e9
        self._moving = False
        self.estopped = False
        self.watchdog_fired = False
        self.last_command: VelocityCommand | None = None
        # (monotonic time the bytes were read, message) of every host frame: tests and the latency
        # benchmark see exactly what reached the "firmware" and when
        self.message_log: deque[tuple[float, Message]] = deque(maxlen=8192)
        self.heartbeats = 0
        self.telemetry_sent = 0
        self._last_telemetry: float | None = None  # monotonic time of the last telemetry frame
        self._gyro_claimed = 0.0  # rad reported by frames that repeated the last rate, not yet measured
        self._last_raw: np.ndarray | None = None  # encoder counts of the last telemetry frame
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        pump.subscribe(self._on_frame)

    @property
    def path(self) -> str:
        return self.port.path

    # ---- simulator side --------------------------------------------------------------------------
    def _on_frame(self, frame: SensorFrame) -> None:
        with self._lock:
            s = self._sensors
            if frame.ticks is not None:
                n = frame.ticks.counts.size
                if self._last_stamp is not None and np.any(self._slip_speed):
                    dt = max(0.0, frame.ticks.stamp - self._last_stamp)
                    self._slip_angle += self._slip_speed * (dt / self.profile.wheel_radius)
                self._last_stamp = frame.ticks.stamp
                slip = np.floor(self._slip_angle / (2 * np.pi) * self.profile.ticks_per_rev).astype(np.int64)
                s.counts[:n] = frame.ticks.counts + slip[:n]
            if frame.imu is not None:
                # the simulator's gyro is the mean rate since its previous IMU reading: weight by
                # that interval so the telemetry carries the true mean rate of its own period
                if s.imu_stamp is not None and frame.imu.stamp > s.imu_stamp:
                    dt = frame.imu.stamp - s.imu_stamp
                    s.gyro_integral += frame.imu.gyro_z * dt
                    s.gyro_time += dt
                s.imu_stamp = frame.imu.stamp
                s.gyro_last = frame.imu.gyro_z
                s.accel = frame.imu.accel
            if frame.ir is not None:
                bits = frame.ir.triggered.astype(np.int64)
                s.ir_bits = int(np.sum(bits << np.arange(bits.size)))
            if frame.battery_v is not None:
                s.battery_v = frame.battery_v
            s.obstacle_stop = frame.base_stopped_by_obstacle

    # ---- firmware loop ---------------------------------------------------------------------------
    def start(self) -> BaseEmulator:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="emulate-base", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        next_telemetry = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            data = self.port.read(timeout=min(max(next_telemetry - now, 0.0), 0.005))
            if data:
                t_read = time.monotonic()
                for msg in self._decoder.feed(data):
                    self.message_log.append((t_read, msg))
                    self._handle(msg)
            now = time.monotonic()
            self._watchdog(now)
            if now >= next_telemetry:
                next_telemetry = max(next_telemetry + 1.0 / self.params[ParamId.TELEMETRY_RATE], now - 0.1)
                self._send_telemetry(now)
            if not self.port.plugged:
                self._stop.wait(0.01)

    def _send(self, msg: Message) -> None:
        self.port.write(self.faults.apply(self._seq.encode(msg)))

    def _handle(self, msg: Message) -> None:
        now = time.monotonic()
        if isinstance(msg, VelocityCommand):
            self.last_command = msg
            if self.estopped:
                return
            self._last_cmd = now
            self.watchdog_fired = False
            self._moving = not Twist2D(msg.vx, msg.vy, msg.wz).is_zero()
            self.pump.command(self._actual_twist(msg))
        elif isinstance(msg, Heartbeat):
            self.heartbeats += 1
        elif isinstance(msg, EStop):
            self.estopped = True
            self._moving = False
            self.pump.estop()
        elif isinstance(msg, Reset):
            self._reset(msg.mode)
        elif isinstance(msg, ParamGet):
            value = self.params.get(msg.param_id)
            status = ParamStatus.OK if value is not None else ParamStatus.UNKNOWN_ID
            self._send(ParamValue(msg.param_id, value or 0.0, status))
        elif isinstance(msg, ParamSet):
            self._send(self._set_param(msg.param_id, msg.value))
        elif isinstance(msg, ParamSave):
            self.flash = dict(self.params)
            self._send(ParamValue(PARAM_SAVE_ID, float(len(self.flash)), ParamStatus.OK))
        else:
            self._send(ErrorReport(ErrorCode.UNKNOWN_MESSAGE, Severity.WARNING, int(msg.TYPE)))

    def _actual_twist(self, cmd: VelocityCommand) -> Twist2D:
        """The twist the wheels really produce: the firmware converts with its *parameters*; the
        simulator moves with the *true* geometry of the profile."""
        r = self.profile.wheel_radius / self.params[ParamId.WHEEL_RADIUS]
        if self.profile.is_omni:
            w = r * self.params[ParamId.OMNI_RADIUS] / self.profile.omni_radius
        else:
            w = r * self.params[ParamId.TRACK_WIDTH] / self.profile.track_width
        return Twist2D(cmd.vx * r, cmd.vy * r, cmd.wz * w)

    def _set_param(self, pid: int, value: float) -> ParamValue:
        if pid not in self.params:
            return ParamValue(pid, 0.0, ParamStatus.UNKNOWN_ID)
        lo, hi = PARAM_RANGES[ParamId(pid)]
        if not (lo <= value <= hi):
            return ParamValue(pid, self.params[pid], ParamStatus.OUT_OF_RANGE)
        self.params[pid] = float(value)
        if pid == ParamId.OBSTACLE_STOP_ENABLE:
            self.pump.set_ir_stop(value >= 0.5)
        return ParamValue(pid, float(value), ParamStatus.OK)

    def _reset(self, mode: int) -> None:
        self.estopped = False
        self.watchdog_fired = False
        self.pump.reset()
        self.pump.command(Twist2D())
        self._moving = False
        if mode in (ResetMode.ZERO_ENCODERS, ResetMode.REBOOT):
            with self._lock:
                self._enc_offset = self._sensors.counts.copy()
        if mode == ResetMode.REBOOT:
            self._t0 = time.monotonic()
            self.params = dict(self.flash if self.flash is not None else self.defaults)
            self.pump.set_ir_stop(self.params[ParamId.OBSTACLE_STOP_ENABLE] >= 0.5)
            self._decoder = MessageDecoder()
            self._seq = Sequencer()

    def _watchdog(self, now: float) -> None:
        if self._moving and now - self._last_cmd > self.params[ParamId.CMD_TIMEOUT]:
            self._moving = False
            self.watchdog_fired = True
            self.pump.command(Twist2D())
            ms = int((now - self._last_cmd) * 1000)
            self._send(ErrorReport(ErrorCode.WATCHDOG, Severity.WARNING, ms))

    def _send_telemetry(self, now: float) -> None:
        with self._lock:
            s = self._sensors
            raw = s.counts - self._enc_offset
            # The angle turned since the previous frame over that frame's MCU period, so the host's
            # sum of rate x period is the angle the robot turned, as the encoder counts are its
            # travel. (Over the simulator's IMU time instead, a starved simulator thread makes the two
            # windows differ: a catch-up frame's angle, 200 ms of IMU time but 20 ms of MCU time,
            # would be lost.) Without a new IMU sample: while the simulator stands still (counts
            # unchanged too) nothing turned as far as the data go, and the host, seeing still wheels,
            # takes that frame's rate as gyro bias, so 0; otherwise the last rate, as an MCU holds its
            # last reading, taken off the next frame that has samples.
            period = now - self._last_telemetry if self._last_telemetry is not None else 0.0
            if s.gyro_time > 0 and period > 0:
                gyro = (s.gyro_integral - self._gyro_claimed) / period
                self._gyro_claimed = 0.0
            elif self._last_raw is not None and np.array_equal(raw, self._last_raw):
                gyro = 0.0 if period > 0 else s.gyro_last
            else:
                gyro = s.gyro_last
                self._gyro_claimed += gyro * period
            s.gyro_integral, s.gyro_time = 0.0, 0.0
            self._last_telemetry, self._last_raw = now, raw.copy()
            accel, ir_bits, battery, obstacle = s.accel, s.ir_bits, s.battery_v, s.obstacle_stop
        enc = (((raw + (1 << 31)) % (1 << 32)) - (1 << 31)).astype(np.int64).tolist()
        status = Status(0)
        if self.estopped:
            status |= Status.ESTOP_LATCHED
        if obstacle and self.params[ParamId.OBSTACLE_STOP_ENABLE] >= 0.5:
            status |= Status.OBSTACLE_STOP
        if self.watchdog_fired:
            status |= Status.WATCHDOG_STOP
        if battery < self.params[ParamId.BATTERY_CUTOFF]:
            status |= Status.LOW_BATTERY
        if self.params == self.defaults:
            status |= Status.PARAMS_DEFAULT
        mcu_us = int((now - self._t0) * 1e6) & 0xFFFFFFFF
        msg = Telemetry(mcu_us, *enc, gyro, *accel, ir_bits, round(battery * 1000) & 0xFFFF, int(status))
        self._send(msg)
        self.telemetry_sent += 1

    # ---- fault switches --------------------------------------------------------------------------
    def set_wheel_slip(self, rim_speed: np.ndarray | list[float] | None) -> None:
        """Wheels spinning on a slippery patch: each wheel (profile order) turns ``rim_speed`` m/s
        faster than the ground carries it, so the encoders count motion that neither the body nor
        the gyro makes (what ``WheelOdometry``'s slip detector looks for). None clears it."""
        speed = np.zeros(4)
        if rim_speed is not None:
            given = np.asarray(rim_speed, dtype=float)
            speed[: given.size] = given
        with self._lock:
            self._slip_speed = speed

    def unplug(self) -> None:
        """Pull the cable: the pty disappears (the motors stop, as USB power would go)."""
        self.port.unplug()
        self.pump.command(Twist2D())
        self._moving = False

    def replug(self) -> None:
        self._decoder.reset()
        self.port.plug()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        with contextlib.suppress(Exception):
            self.port.close()
