"""``SerialDriver``: the real robot over pyserial (STM32 base link + optional RPLidar A1).

Implements ``robot.base.Driver`` exactly as ``SimDriver`` does: ``read()`` returns what is new
since the last call. One reader thread per port decodes frames as they arrive; the control loop
only takes the latest state under a short lock and never waits on I/O.

Safety contract (docs/hardware.md): the host resends the held velocity every ``keepalive_period``
only while the control loop keeps commanding (``command_hold``), so a dead control loop lets the
firmware's 200 ms watchdog stop the motors. No telemetry for ``link_timeout`` (300 ms) -> the link
is LOST with a reason, the held command is zeroed and commands are refused until telemetry
returns; a vanished port is reopened with exponential back-off.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from urllib.parse import parse_qs, urlparse

import numpy as np
import serial

from nav.types import Twist2D
from robot.base import ImuReading, IrReading, LinkState, LinkStatus, SensorFrame, WheelTicks
from robot.clock import Clock, RealClock
from robot.profiles import RobotProfile
from robot.serial.port import Backoff, PortUnavailableError, SerialLinkError, describe_crash, open_port
from robot.serial.protocol import (
    ENCODER_CHANNELS,
    PARAM_SAVE_ID,
    ErrorCode,
    ErrorReport,
    EStop,
    Heartbeat,
    MessageDecoder,
    ParamSave,
    ParamSet,
    ParamStatus,
    ParamValue,
    Reset,
    ResetMode,
    Sequencer,
    Status,
    Telemetry,
    VelocityCommand,
)
from robot.serial.rplidar import RPLidar, RPLidarOptions

log = logging.getLogger(__name__)


SerialError = SerialLinkError  # the name app/drivers.py catches: every error of this package


class SerialUrlError(SerialLinkError, ValueError):
    """A ``serial://`` robot URL that cannot be parsed."""


@dataclass(frozen=True)
class SerialOptions:
    """Options of ``SerialDriver`` (all times in seconds)."""

    port: str
    """Base (STM32) serial device, e.g. ``/dev/ttyUSB0`` or ``/dev/serial/by-id/...``."""
    lidar_port: str | None = None
    """RPLidar A1 USB adapter device; None: a base without a lidar (URL without ``lidar=`` or with
    ``lidar=none``): teleop only, mapping and navigation are refused."""
    baud: int = 115200
    """Base UART baud rate (8N1)."""
    lidar_baud: int = 115200
    """RPLidar A1 baud rate (fixed 115200 on the A1)."""
    link_timeout: float = 0.3
    """No telemetry for this long -> LinkStatus LOST."""
    lidar_timeout: float = 1.0
    """No lidar sample for this long -> the lidar driver restarts the scan and reports it (a fault)."""
    keepalive_period: float = 0.05
    """How often the reader thread resends the held velocity (or a heartbeat when idle)."""
    command_hold: float = 0.5
    """Stop keeping a command alive when the control loop has not called ``command`` for this long."""
    reconnect_initial: float = 0.1
    """First reconnect delay after the port vanished; doubles each failure."""
    reconnect_max: float = 2.0
    """Longest reconnect delay."""
    degraded_bad_ratio: float = 0.05
    """Bad / (good + bad) frames over the last second above this -> LinkStatus DEGRADED."""


def parse_serial_url(url: str) -> SerialOptions:
    """``serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1&baud=115200`` -> ``SerialOptions``.

    Query keys: ``lidar`` (a device, or ``none`` for a base without a lidar), ``baud``,
    ``lidar_baud``, ``link_timeout``, ``lidar_timeout``, ``keepalive_period``, ``command_hold``.
    Unknown keys are an error, so a typo does not silently fall back to a default.
    """
    parsed = urlparse(url)
    if parsed.scheme != "serial":
        raise SerialUrlError(f"robot URL {url!r} must start with serial://")
    port = parsed.path
    if parsed.netloc:  # serial://ttyUSB0 -> /dev/ttyUSB0
        port = "/dev/" + parsed.netloc + parsed.path
    if not port or port == "/":
        raise SerialUrlError(f"robot URL {url!r} names no port (serial:///dev/ttyUSB0)")
    query = {k: v[-1] for k, v in parse_qs(parsed.query, keep_blank_values=True).items()}
    kwargs: dict[str, object] = {"port": port}
    converters = {
        "lidar": ("lidar_port", str),
        "baud": ("baud", int),
        "lidar_baud": ("lidar_baud", int),
        "link_timeout": ("link_timeout", float),
        "lidar_timeout": ("lidar_timeout", float),
        "keepalive_period": ("keepalive_period", float),
        "command_hold": ("command_hold", float),
    }
    for key, value in query.items():
        if key not in converters:
            raise SerialUrlError(
                f"robot URL {url!r}: unknown option {key!r} (known: {', '.join(converters)})"
            )
        field_name, conv = converters[key]
        try:
            converted = conv(value)
        except ValueError as exc:
            raise SerialUrlError(
                f"robot URL {url!r}: {key}={value!r} is not a valid {conv.__name__}"
            ) from exc
        if conv is not str and converted <= 0:  # type: ignore[operator]
            raise SerialUrlError(f"robot URL {url!r}: {key} must be positive")
        if key == "lidar" and str(converted).lower() == "none":
            converted = None  # said explicitly: this base has no lidar
        kwargs[field_name] = converted or None
    return SerialOptions(**kwargs)  # type: ignore[arg-type]


class _ClockSync:
    """Maps the MCU microsecond timer onto host time: offset = the least (host receive time - MCU
    time) seen, the usual one-way-delay lower bound (the sample with the least queuing delay), with
    wrap-around of the 32-bit timer unwrapped.

    The offset falls at once (a less delayed sample) but rises no faster than ``MAX_DRIFT`` s per s
    of MCU time, what two clocks can drift apart. A minimum over a window of recent samples used to
    forget the good sample after a starved second of the host: every sample in the window was late,
    the offset jumped up by the delay, one tick interval lasted a second longer than the MCU's, and
    the gyro's mean rate times it turned the odometry's heading by radians (seen in CI)."""

    MAX_DRIFT = 0.01
    """s/s; an MCU on its internal RC oscillator is within 1 % (a crystal within 50 ppm)."""

    def __init__(self) -> None:
        self._offset: float | None = None
        self._last_us: int | None = None
        self._last_t = 0.0
        self._wraps = 0

    def stamp(self, mcu_us: int, host_t: float) -> float:
        if self._last_us is not None and mcu_us < self._last_us:
            if self._last_us - mcu_us > 1 << 31:
                self._wraps += 1
            else:  # the MCU rebooted: start over
                self._offset = None
                self._wraps = 0
        self._last_us = mcu_us
        mcu_t = (mcu_us + (self._wraps << 32)) * 1e-6
        sample = host_t - mcu_t
        if self._offset is None:
            self._offset = sample
        else:
            drift = self.MAX_DRIFT * max(mcu_t - self._last_t, 0.0)
            self._offset = min(sample, self._offset + drift)
        self._last_t = mcu_t
        return mcu_t + self._offset


class _TickUnwrapper:
    """int32 firmware counters -> cumulative int64 counts that survive wrap-around and MCU reboots."""

    def __init__(self, n: int) -> None:
        self.total = np.zeros(n, dtype=np.int64)
        self._last: np.ndarray | None = None

    def update(self, raw: tuple[int, ...], rebased: bool) -> np.ndarray:
        cur = np.asarray(raw, dtype=np.int64)
        if self._last is not None and not rebased:
            self.total += ((cur - self._last + (1 << 31)) % (1 << 32)) - (1 << 31)
        self._last = cur
        return self.total.copy()


class BaseLink:
    """The STM32 link: reader thread, keep-alive, watchdog, reconnect. Used by ``SerialDriver``."""

    def __init__(self, options: SerialOptions, clock: Clock) -> None:
        self.options = options
        self.clock = clock
        self._ser: serial.Serial | None = open_port(options.port, options.baud)
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._stop = threading.Event()
        self._decoder = MessageDecoder()
        self._seq = Sequencer()
        self._sync = _ClockSync()
        self._ticks = _TickUnwrapper(ENCODER_CHANNELS)  # all four wire channels; the driver takes its wheels
        self._backoff = Backoff(options.reconnect_initial, options.reconnect_max)
        # state shared with the control loop (under _lock)
        self._latest: Telemetry | None = None
        self._latest_stamp = 0.0
        self._latest_ticks: np.ndarray | None = None
        # Each frame's gyro_z is the mean rate over its own period (since the previous frame): the
        # mean over several frames weights them by those periods (MCU time), so a frame sent late
        # (covering 200 ms) and the ones sent right after it (covering ~0) integrate to the true angle.
        self._gyro_integral = 0.0  # rad since the last take
        self._gyro_time = 0.0  # s of MCU time in that integral
        self._gyro_last: float | None = None  # newest frame's rate since the last take
        self._new = False
        self._last_rx = time.monotonic()  # link timing is wall time whatever the session clock
        self._port_error: str | None = None
        self._crash: str | None = None  # why the reader thread died, if it did: a FAULT until restart
        self._errors: list[str] = []
        self.params: dict[int, ParamValue] = {}
        # command state
        self._held = Twist2D()
        self._held_at = -1e9
        self._last_keepalive = 0.0
        self._lost = False
        self._lost_reason = ""
        self._last_mcu_us: int | None = None
        self.refused_commands = 0
        # (monotonic time written, message) of recent frames sent: diagnostics and the latency bench
        self.sent_log: deque[tuple[float, object]] = deque(maxlen=1024)
        self._rx_bytes = 0  # bytes received since the last good telemetry (diagnoses wiring / baud)
        t = time.monotonic()
        self._rate_ref = ((t, 0, 0), (t, 0, 0))  # (time, good, bad) one and two buckets ago
        self._thread = threading.Thread(target=self._run, name=f"serial-base {options.port}", daemon=True)
        self._thread.start()

    # ---- reader thread -------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a bug here must not leave a silent link blamed on the wiring
            reason = describe_crash(f"base reader thread ({self.options.port})", exc)
            log.exception("%s", reason)
            with self._lock:
                self._crash = reason
            self.link_status()  # enter LOST now: zero the held command and send the stop

    def _loop(self) -> None:
        while not self._stop.is_set():
            ser = self._ser
            if ser is None:
                self._reconnect()
                continue
            try:
                data = ser.read(max(1, ser.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                self._port_gone(f"base port {self.options.port} disconnected: {str(exc).splitlines()[0]}")
                continue
            if data:
                self._rx_bytes += len(data)
                self._handle(self._decoder.feed(data))
            if not self._backlog():  # judge silence only once everything that arrived is decoded
                self.link_status()  # the watchdog runs here too, so LOST does not wait for read()
            self._keepalive()

    def _backlog(self) -> int:
        """Bytes received by the OS and not yet read (0 if the port is gone)."""
        ser = self._ser
        if ser is None:
            return 0
        try:
            return int(ser.in_waiting)
        except (serial.SerialException, OSError, TypeError, AttributeError):
            return 0

    def _port_gone(self, reason: str) -> None:
        with self._lock:
            self._port_error = reason
        ser, self._ser = self._ser, None
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.close()
        log.warning("%s", reason)

    def _reconnect(self) -> None:
        if self._stop.wait(self._backoff.next_delay()):
            return
        try:
            ser = open_port(self.options.port, self.options.baud)
        except PortUnavailableError as exc:
            with self._lock:
                self._port_error = str(exc)
            return
        self._backoff.reset()
        self._decoder.reset()
        self._ser = ser
        with self._lock:
            self._port_error = None
        log.info("base port %s reopened", self.options.port)

    def _handle(self, msgs: list) -> None:
        now = self.clock.now()
        wall = time.monotonic()
        for m in msgs:
            if isinstance(m, Telemetry):
                rebooted = (
                    self._last_mcu_us is not None
                    and m.mcu_us < self._last_mcu_us
                    and (self._last_mcu_us - m.mcu_us < 1 << 31)
                )
                period = (
                    ((m.mcu_us - self._last_mcu_us) & 0xFFFFFFFF) * 1e-6
                    if self._last_mcu_us is not None and not rebooted
                    else 0.0
                )
                self._last_mcu_us = m.mcu_us
                stamp = self._sync.stamp(m.mcu_us, now)
                ticks = self._ticks.update(m.enc, rebased=rebooted)
                with self._lock:
                    self._latest = m
                    self._latest_stamp = stamp
                    self._latest_ticks = ticks
                    self._gyro_integral += m.gyro_z * period
                    self._gyro_time += period
                    self._gyro_last = m.gyro_z
                    self._new = True
                    self._last_rx = wall
                    self._rx_bytes = 0
            elif isinstance(m, ParamValue):
                with self._lock:
                    self.params[m.param_id] = m
            elif isinstance(m, ErrorReport):
                try:
                    name = ErrorCode(m.code).name
                except ValueError:
                    name = f"code {m.code}"
                with self._lock:
                    self._errors.append(f"base error {name} (detail {m.detail})")

    def _keepalive(self) -> None:
        now = time.monotonic()
        if now - self._last_keepalive < self.options.keepalive_period:
            return
        self._last_keepalive = now
        with self._lock:
            held, fresh, lost = self._held, now - self._held_at < self.options.command_hold, self._lost
        if lost:
            return
        if fresh:
            self._send(VelocityCommand(held.vx, held.vy, held.wz))
        else:
            self._send(Heartbeat(int(now * 1000) & 0xFFFFFFFF))

    def _send(self, msg) -> bool:
        ser = self._ser
        if ser is None:
            return False
        try:
            with self._write_lock:  # the loop, the reader's keep-alive and the reflex path all write
                frame = self._seq.encode(msg)  # sequence numbers leave in order
                t_write = time.monotonic()
                ser.write(frame)
            self.sent_log.append((t_write, msg))
            return True
        except (serial.SerialException, OSError, TypeError, AttributeError):
            return False  # the reader thread notices the dead port and reconnects

    # ---- control-loop side ---------------------------------------------------------------------
    def link_status(self) -> LinkStatus:
        """Evaluate the watchdog (on wall time); entering LOST zeroes the held command and sends a stop."""
        now = time.monotonic()
        with self._lock:
            silent = now - self._last_rx
            port_error = self._crash or self._port_error
        good, bad = self._decoder.good, self._decoder.bad
        with self._lock:
            if now - self._rate_ref[0][0] >= 1.0:  # two one-second buckets: the ratio covers 1-2 s
                self._rate_ref = (self._rate_ref[1], (now, good, bad))
            _, good0, bad0 = self._rate_ref[0]
        late = port_error is None and self.options.link_timeout < silent < 5 * self.options.link_timeout
        if late and (waiting := self._backlog()):
            # Telemetry did arrive (the OS holds it) but this process has not decoded it yet: the
            # host was busy (GIL, swap, a start-up import), not the link. Within 5 timeouts this is
            # DEGRADED, not LOST, so a busy host does not fault a healthy robot.
            return LinkStatus(
                LinkState.DEGRADED,
                f"telemetry read {silent * 1000:.0f} ms late ({waiting} bytes waiting: host busy)",
                good,
                bad,
            )
        if port_error is not None or silent > self.options.link_timeout:
            reason = port_error or f"no telemetry from {self.options.port} for {silent * 1000:.0f} ms"
            if port_error is None and self._rx_bytes > 64:
                reason += f" but {self._rx_bytes} bytes of something else (wrong port or baud rate?)"
            with self._lock:
                entering, self._lost = not self._lost, True
                self._lost_reason = reason
                self._held = Twist2D()
            if entering:
                self._send(VelocityCommand(0.0, 0.0, 0.0))
                log.warning("base link LOST: %s", reason)
            return LinkStatus(LinkState.LOST, reason, good, bad)
        with self._lock:
            recovered, self._lost = self._lost, False
        if recovered:
            log.info("base link recovered")
        d_good, d_bad = good - good0, bad - bad0
        if d_bad and d_bad / (d_good + d_bad) > self.options.degraded_bad_ratio:
            return LinkStatus(
                LinkState.DEGRADED, f"{d_bad} bad frames of {d_good + d_bad} recently", good, bad
            )
        return LinkStatus(LinkState.OK, "", good, bad)

    def take(self) -> tuple[Telemetry | None, float, np.ndarray | None, float | None, bool, list[str]]:
        """Latest telemetry, its stamp, cumulative ticks, mean gyro since last take, whether new."""
        with self._lock:
            m, stamp, ticks, new = self._latest, self._latest_stamp, self._latest_ticks, self._new
            gyro = self._gyro_integral / self._gyro_time if self._gyro_time > 0 else self._gyro_last
            self._gyro_integral, self._gyro_time, self._gyro_last, self._new = 0.0, 0.0, None, False
            errors, self._errors = self._errors, []
        return m, stamp, ticks, gyro, new, errors

    def command(self, cmd: Twist2D) -> bool:
        """Hold and send ``cmd``; refused (False) while the link is LOST."""
        with self._lock:
            if self._lost:
                self.refused_commands += 1
                return False
            self._held = cmd
            self._held_at = time.monotonic()
        return self._send(VelocityCommand(cmd.vx, cmd.vy, cmd.wz))

    @property
    def good_frames(self) -> int:
        return self._decoder.good

    def send(self, msg) -> bool:
        return self._send(msg)

    def ask_param(self, msg: ParamSet | ParamSave, answer_id: int, timeout: float) -> ParamValue:
        """Send ``msg`` and wait for the PARAM_VALUE answer carrying ``answer_id`` (whatever its
        status). Raises ``SerialLinkError`` when the port is gone or no answer comes in ``timeout`` s."""
        port = self.options.port
        what = f"{msg.TYPE.name} {answer_id}" if isinstance(msg, ParamSet) else msg.TYPE.name
        with self._lock:
            self.params.pop(answer_id, None)
        if not self.send(msg):
            raise SerialLinkError(f"cannot send {what}: base port {port} is gone")
        end = time.monotonic() + timeout
        while (reply := self.params.get(answer_id)) is None:
            if time.monotonic() > end:
                heard = "it sends telemetry" if self._decoder.good else "nothing came back"
                older = (
                    ": a firmware older than PARAM_SAVE cannot persist parameters"
                    if isinstance(msg, ParamSave)
                    else ""
                )
                raise SerialLinkError(
                    f"no answer to {what} from {port} within {timeout:.1f} s ({heard}){older}"
                )
            time.sleep(0.005)
        return reply

    def save_params(self, timeout: float = 2.0) -> ParamValue:
        """PARAM_SAVE: the base writes every parameter now in effect to flash; its answer's ``value``
        is the number written. Raises ``SerialLinkError`` when it does not answer (a firmware without
        PARAM_SAVE) or the flash write failed. ``SerialDriver`` and ``robot.firmware.save_params``
        both save through here."""
        reply = self.ask_param(ParamSave(), PARAM_SAVE_ID, timeout)
        if reply.status != ParamStatus.OK:
            raise SerialLinkError(
                f"the base on {self.options.port} could not write its flash: {ParamStatus(reply.status).name}"
            )
        return reply

    def close(self) -> None:
        self._stop.set()
        self._send(VelocityCommand(0.0, 0.0, 0.0))
        self._thread.join(timeout=1.0)
        ser, self._ser = self._ser, None
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.close()


class SerialDriver:
    """``robot.base.Driver`` for the real robot: STM32 base over ``port``, RPLidar A1 on ``lidar_port``.

    Raises ``PortUnavailableError`` (one-line reason) if a port is missing or busy at start.
    """

    command_thread_safe = True
    """``command``/``stop``/``estop`` may be called from any thread (``BaseLink`` locks its state and
    serializes writes): the session's teleop reflex writes from the websocket's thread."""

    def __init__(
        self,
        port: str | SerialOptions,
        profile: RobotProfile,
        lidar_port: str | None = None,
        clock: Clock | None = None,
        **options: object,
    ) -> None:
        if isinstance(port, SerialOptions):
            opts = port
        else:
            opts = SerialOptions(port=port, lidar_port=lidar_port, **options)  # type: ignore[arg-type]
        self.options = opts
        self.profile = profile
        self.clock: Clock = clock or RealClock()
        self._estop_sent = False
        self._base = BaseLink(opts, self.clock)
        self._lidar = None
        self.has_lidar = bool(opts.lidar_port)
        if opts.lidar_port:
            try:
                self._lidar = RPLidar(
                    opts.lidar_port,
                    profile.lidar,
                    clock=self.clock,
                    baud=opts.lidar_baud,
                    options=RPLidarOptions(silent_timeout=opts.lidar_timeout),
                )
            except BaseException:
                self._base.close()
                raise

    @classmethod
    def from_url(cls, url: str, profile: RobotProfile, clock: Clock | None = None) -> SerialDriver:
        """``SerialDriver.from_url("serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1", profile)``."""
        return cls(parse_serial_url(url), profile, clock=clock)

    @classmethod
    def from_url_options(
        cls, options: SerialOptions, profile: RobotProfile, clock: Clock | None = None
    ) -> SerialDriver:
        """From already parsed ``SerialOptions`` (``parse_serial_url``)."""
        return cls(options, profile, clock=clock)

    def read(self) -> SensorFrame:
        now = self.clock.now()
        link = self._base.link_status()
        telem, stamp, counts, gyro, new, errors = self._base.take()
        ticks = imu = ir = None
        battery = None
        stopped = False
        faults: list[str] = []
        if link.state is LinkState.LOST:
            faults.append(link.reason)
        if telem is not None and new and counts is not None:
            n = self.profile.wheel_count
            ticks = WheelTicks(stamp, counts[:n].copy())
            imu = ImuReading(
                stamp,
                float(gyro if gyro is not None else telem.gyro_z),
                (telem.accel_x, telem.accel_y, telem.accel_z),
            )
            n_ir = len(self.profile.ir)
            bits = (telem.ir_bits >> np.arange(n_ir)) & 1 if n_ir else np.zeros(0, dtype=np.int64)
            trig = bits.astype(bool)
            # E3F-DS30Y2 sensors are digital: a triggered sensor reports its switching distance.
            rng = (
                np.where(trig, np.array([s.range for s in self.profile.ir]), np.inf) if n_ir else np.zeros(0)
            )
            ir = IrReading(stamp, trig, rng)
            battery = telem.battery_mv / 1000.0
            stopped = bool(telem.status & Status.OBSTACLE_STOP)
            flags = Status(telem.status)
            if flags & Status.MOTOR_FAULT:
                faults.append("base reports a motor driver fault")
            if flags & Status.IMU_FAULT:
                faults.append("base reports an IMU fault")
        faults.extend(errors)
        scan = None
        lidar_fault = None
        if self._lidar is not None:
            scan = self._lidar.take_scan()
            lidar_fault = self._lidar.fault
            if lidar_fault:
                faults.append(lidar_fault)
        return SensorFrame(
            stamp=now,
            scan=scan,
            ticks=ticks,
            imu=imu,
            ir=ir,
            battery_v=battery,
            link=link,
            base_stopped_by_obstacle=stopped,
            fault="; ".join(faults) if faults else None,
            lidar_fault=lidar_fault or None,
        )

    def command(self, cmd: Twist2D) -> None:
        if not cmd.is_finite():
            cmd = Twist2D()
        self._base.command(cmd)

    def stop(self) -> None:
        self._base.command(Twist2D())

    def estop(self) -> None:
        self._base.command(Twist2D())
        self._base.send(EStop())

    def reset(self) -> None:
        self._base.send(Reset(ResetMode.CLEAR_ESTOP))

    def set_param(self, param_id: int, value: float, timeout: float = 1.0) -> ParamValue:
        """Write a firmware parameter (PARAM_SET) and wait for the base's PARAM_VALUE answer. The value
        lives in the base's RAM until ``save_params``.

        Raises ``SerialLinkError`` when no answer comes within ``timeout`` s or the base refuses."""
        reply = self._base.ask_param(ParamSet(int(param_id), float(value)), int(param_id), timeout)
        if reply.status != ParamStatus.OK:
            raise SerialLinkError(
                f"the base refused parameter {param_id} = {value:g}: {ParamStatus(reply.status).name}"
            )
        return reply

    def save_params(self, timeout: float = 2.0) -> ParamValue:
        """PARAM_SAVE: the base writes every parameter now in effect to flash, so they survive a
        reboot (``BaseLink.save_params``)."""
        return self._base.save_params(timeout)

    @property
    def refused_commands(self) -> int:
        """Commands dropped because the link was LOST."""
        return self._base.refused_commands

    @property
    def sent_log(self) -> deque[tuple[float, object]]:
        """Recent frames written to the base port with their monotonic write times."""
        return self._base.sent_log

    @property
    def telemetry(self) -> Telemetry | None:
        """The latest raw telemetry (for diagnostics)."""
        return self._base._latest

    def close(self) -> None:
        if self._lidar is not None:
            self._lidar.close()
        self._base.close()


def wait_for(predicate, timeout: float, period: float = 0.01) -> bool:
    """Poll ``predicate`` until true or ``timeout`` s pass (for tools and tests on real time)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(period)
    return bool(predicate())
