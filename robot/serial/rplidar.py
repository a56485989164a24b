"""RPLidar A1 over its USB adapter: Slamtec's published serial protocol, vectorized.

Protocol (Slamtec "RPLIDAR Interface Protocol and Application Notes", LR001 v2.x, legacy SCAN):

* request: ``0xA5 cmd`` (STOP 0x25, RESET 0x40, SCAN 0x20, GET_INFO 0x50, GET_HEALTH 0x52); commands
  with a payload add ``size payload xor-checksum`` (none used here).
* response descriptor: ``0xA5 0x5A`` + uint32 LE (30-bit length | 2-bit send mode << 30) + type.
  SCAN answers ``A5 5A 05 00 00 40 81`` then streams 5-byte nodes forever; GET_INFO ``.. 14 00 00 00
  04`` + 20 bytes; GET_HEALTH ``.. 03 00 00 00 06`` + 3 bytes.
* scan node: ``b0 = quality << 2 | !S << 1 | S`` (S = first node of a new rotation),
  ``b1 = angle_q6[6:0] << 1 | C`` (C = 1, check bit), ``b2 = angle_q6[14:7]``, ``b3..b4 = distance_q2``
  (LE). angle = angle_q6 / 64 degrees **clockwise** seen from above, distance = distance_q2 / 4 mm, 0 =
  no valid return.
* the A1's USB adapter wires the motor enable to DTR: DTR asserted = motor stopped (the SDK's
  ``stopMotor`` sets DTR, ``startMotor`` clears it).

Parsing works on whole numpy byte arrays: the S/!S and C check bits of every 5-byte window are
tested at once, so a clean stream is sliced into nodes with no Python loop; corrupted bytes cost one
search for the next offset where three consecutive windows pass the checks (resync).

The laser frame's x axis is the A1's 0 degree direction. ``rotation_to_scan`` flips the clockwise
angles into a REP-103 counter-clockwise ``LaserScan`` binned to the profile's beams; the mount pose
(``LidarSpec.mount_x/y/yaw``) is the laser frame in base_link and is applied by consumers through
``laser_pose``, exactly as for the simulator's scans.
"""

from __future__ import annotations

import contextlib
import logging
import math
import struct
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
import serial

from nav.types import LaserScan
from robot.clock import Clock, RealClock
from robot.profiles import LidarSpec
from robot.serial.port import Backoff, PortUnavailableError, describe_crash, open_port

log = logging.getLogger(__name__)

SYNC = 0xA5
SYNC2 = 0x5A
NODE_SIZE = 5
ANGLE_Q6_FULL = 360 * 64


class Cmd(IntEnum):
    STOP = 0x25
    RESET = 0x40
    SCAN = 0x20
    FORCE_SCAN = 0x21
    GET_INFO = 0x50
    GET_HEALTH = 0x52


class RespType(IntEnum):
    SCAN = 0x81
    INFO = 0x04
    HEALTH = 0x06


class HealthStatus(IntEnum):
    GOOD = 0
    WARNING = 1
    ERROR = 2


DESCRIPTOR = struct.Struct("<BBIB")
INFO = struct.Struct("<BBBB16s")
HEALTH = struct.Struct("<BH")
SEND_MODE_SINGLE = 0
SEND_MODE_MULTI = 1


def request(cmd: int, payload: bytes = b"") -> bytes:
    """A request packet: ``A5 cmd`` or ``A5 cmd size payload checksum`` (checksum = xor of all)."""
    if not payload:
        return bytes((SYNC, cmd))
    body = bytes((SYNC, cmd, len(payload))) + payload
    check = 0
    for b in body:
        check ^= b
    return body + bytes((check,))


def descriptor(length: int, mode: int, dtype: int) -> bytes:
    return DESCRIPTOR.pack(SYNC, SYNC2, (length & 0x3FFFFFFF) | (mode << 30), dtype)


SCAN_DESCRIPTOR = descriptor(NODE_SIZE, SEND_MODE_MULTI, RespType.SCAN)


@dataclass(frozen=True)
class DeviceInfo:
    model: int
    firmware: tuple[int, int]  # (major, minor)
    hardware: int
    serial_number: str

    def encode(self) -> bytes:
        sn = bytes.fromhex(self.serial_number.ljust(32, "0")[:32])
        return descriptor(INFO.size, SEND_MODE_SINGLE, RespType.INFO) + INFO.pack(
            self.model, self.firmware[1], self.firmware[0], self.hardware, sn
        )

    @staticmethod
    def decode(body: bytes) -> DeviceInfo:
        model, minor, major, hw, sn = INFO.unpack(body)
        return DeviceInfo(model, (major, minor), hw, sn.hex().upper())


@dataclass(frozen=True)
class Health:
    status: int
    error_code: int = 0

    def encode(self) -> bytes:
        return descriptor(HEALTH.size, SEND_MODE_SINGLE, RespType.HEALTH) + HEALTH.pack(
            self.status, self.error_code
        )

    @staticmethod
    def decode(body: bytes) -> Health:
        return Health(*HEALTH.unpack(body))


def encode_nodes(angle_deg: np.ndarray, dist_mm: np.ndarray, quality: np.ndarray, start: np.ndarray) -> bytes:
    """Vectorized node encoder (the emulator's and the tests' source of truth for the byte layout)."""
    a = np.clip(np.round(np.asarray(angle_deg) * 64.0), 0, ANGLE_Q6_FULL - 1).astype(np.uint16)
    d = np.clip(np.round(np.asarray(dist_mm) * 4.0), 0, 0xFFFF).astype(np.uint16)
    s = np.asarray(start, dtype=np.uint8) & 1
    q = np.clip(np.asarray(quality), 0, 63).astype(np.uint8)
    out = np.empty((a.size, NODE_SIZE), dtype=np.uint8)
    out[:, 0] = (q << 2) | ((1 - s) << 1) | s
    out[:, 1] = ((a & 0x7F) << 1).astype(np.uint8) | 1
    out[:, 2] = (a >> 7).astype(np.uint8)
    out[:, 3] = (d & 0xFF).astype(np.uint8)
    out[:, 4] = (d >> 8).astype(np.uint8)
    return out.tobytes()


@dataclass
class Nodes:
    """A batch of decoded scan nodes (parallel arrays)."""

    angle_deg: np.ndarray  # clockwise, [0, 360)
    dist_mm: np.ndarray  # 0 = no return
    quality: np.ndarray  # 0..63
    start: np.ndarray  # bool, first node of a rotation

    def __len__(self) -> int:
        return int(self.angle_deg.size)

    @staticmethod
    def empty() -> Nodes:
        return Nodes(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.uint8), np.zeros(0, dtype=bool))

    @staticmethod
    def concat(parts: list[Nodes]) -> Nodes:
        if not parts:
            return Nodes.empty()
        return Nodes(
            np.concatenate([p.angle_deg for p in parts]),
            np.concatenate([p.dist_mm for p in parts]),
            np.concatenate([p.quality for p in parts]),
            np.concatenate([p.start for p in parts]),
        )

    def slice(self, i: int, j: int) -> Nodes:
        return Nodes(self.angle_deg[i:j], self.dist_mm[i:j], self.quality[i:j], self.start[i:j])


def _window_checks(arr: np.ndarray) -> np.ndarray:
    """For every offset with 5 bytes available: do S/!S, C and the angle range pass?"""
    m = arr.size - NODE_SIZE + 1
    if m <= 0:
        return np.zeros(0, dtype=bool)
    b0 = arr[:m]
    b1 = arr[1 : m + 1]
    b2 = arr[2 : m + 2].astype(np.uint16)
    angle = (b2 << 7) | (b1 >> 1)
    return (((b0 ^ (b0 >> 1)) & 1) == 1) & ((b1 & 1) == 1) & (angle < ANGLE_Q6_FULL)


def decode_nodes_at(arr: np.ndarray, offsets: np.ndarray) -> Nodes:
    """Decode nodes starting at ``offsets`` (already validated) of a uint8 array."""
    if offsets.size == 0:
        return Nodes.empty()
    idx = offsets[:, None] + np.arange(NODE_SIZE)
    raw = arr[idx]
    b0 = raw[:, 0]
    angle_q6 = (raw[:, 2].astype(np.uint16) << 7) | (raw[:, 1] >> 1)
    dist_q2 = raw[:, 3].astype(np.uint16) | (raw[:, 4].astype(np.uint16) << 8)
    return Nodes(angle_q6 / 64.0, dist_q2 / 4.0, b0 >> 2, (b0 & 1).astype(bool))


@dataclass
class NodeParser:
    """Streaming node parser with check-bit resync. ``feed`` returns the nodes completed so far."""

    resync_confirm: int = 3  # consecutive valid windows needed to accept a new alignment
    aligned: bool = True
    skipped_bytes: int = 0
    resyncs: int = 0
    _tail: bytes = b""

    def feed(self, chunk: bytes) -> Nodes:
        data = self._tail + chunk
        arr = np.frombuffer(data, dtype=np.uint8)
        valid = _window_checks(arr)
        m = valid.size
        if m == 0:
            self._tail = data
            return Nodes.empty()
        strong = valid.copy()
        for k in range(1, self.resync_confirm):
            sh = k * NODE_SIZE
            strong[: max(m - sh, 0)] &= valid[sh:]
            strong[max(m - sh, 0) :] = False
        offsets: list[np.ndarray] = []
        pos = 0
        aligned = self.aligned
        while True:
            if not aligned:
                cand = np.flatnonzero(strong[pos:])
                if cand.size == 0:
                    keep = max(pos, m - (self.resync_confirm - 1) * NODE_SIZE)
                    self.skipped_bytes += keep - pos
                    pos = keep
                    break
                self.skipped_bytes += int(cand[0])
                pos += int(cand[0])
                aligned = True
                self.resyncs += 1
            chain = valid[pos::NODE_SIZE]
            bad = np.flatnonzero(~chain)
            k = int(bad[0]) if bad.size else chain.size
            if k:
                offsets.append(pos + NODE_SIZE * np.arange(k))
            pos += NODE_SIZE * k
            if pos >= m:
                break  # the rest is an incomplete node
            aligned = False  # window at pos failed its checks: corrupted bytes
            pos += 1
            self.skipped_bytes += 1
        self.aligned = aligned
        self._tail = data[pos:]
        if not offsets:
            return Nodes.empty()
        return decode_nodes_at(arr, np.concatenate(offsets))

    def reset(self) -> None:
        self._tail = b""
        self.aligned = True


class StreamParser:
    """Byte stream from the A1 -> responses (``DeviceInfo``, ``Health``) and scan ``Nodes``.

    Finds ``A5 5A`` descriptors, reads single responses, and hands the bytes after a SCAN descriptor
    to ``NodeParser``. ``reset`` after sending a new request (the driver flushes the input first).
    """

    def __init__(self) -> None:
        self.nodes = NodeParser()
        self._buf = b""
        self._pending: tuple[int, int] | None = None  # (length, type) of a single response
        self.scanning = False
        self.unknown_descriptors = 0

    def reset(self) -> None:
        self._buf = b""
        self._pending = None
        self.scanning = False
        self.nodes.reset()

    def feed(self, chunk: bytes) -> tuple[list[DeviceInfo | Health], Nodes]:
        responses: list[DeviceInfo | Health] = []
        if self.scanning:
            return responses, self.nodes.feed(chunk)
        self._buf += chunk
        node_parts: list[Nodes] = []
        while True:
            if self._pending is not None:
                length, dtype = self._pending
                if len(self._buf) < length:
                    break
                body, self._buf = self._buf[:length], self._buf[length:]
                self._pending = None
                if dtype == RespType.INFO and length == INFO.size:
                    responses.append(DeviceInfo.decode(body))
                elif dtype == RespType.HEALTH and length == HEALTH.size:
                    responses.append(Health.decode(body))
                continue
            i = self._buf.find(bytes((SYNC, SYNC2)))
            if i < 0:
                self._buf = self._buf[-1:]  # a lone A5 may start the next descriptor
                break
            if len(self._buf) - i < DESCRIPTOR.size:
                self._buf = self._buf[i:]
                break
            _, _, len_mode, dtype = DESCRIPTOR.unpack_from(self._buf, i)
            self._buf = self._buf[i + DESCRIPTOR.size :]
            length, mode = len_mode & 0x3FFFFFFF, len_mode >> 30
            if dtype == RespType.SCAN and mode == SEND_MODE_MULTI and length == NODE_SIZE:
                self.scanning = True
                rest, self._buf = self._buf, b""
                node_parts.append(self.nodes.feed(rest))
                break
            if dtype in (RespType.INFO, RespType.HEALTH) and mode == SEND_MODE_SINGLE:
                self._pending = (length, dtype)
            else:
                self.unknown_descriptors += 1
        return responses, Nodes.concat(node_parts)


@dataclass
class ScanAssembler:
    """Splits the node stream into rotations at the start flags; the partial first rotation is dropped.
    ``push`` returns ``(nodes, stamp)`` per completed rotation, stamped at the rotation's start."""

    max_nodes: int = 4096  # a rotation longer than this (no start flag seen) is dropped
    _pending: list[Nodes] = field(default_factory=list)
    _pending_n: int = 0
    _started: bool = False
    _stamp: float = 0.0

    def push(self, nodes: Nodes, stamp: float) -> list[tuple[Nodes, float]]:
        out: list[tuple[Nodes, float]] = []
        if len(nodes) == 0:
            return out
        starts = np.flatnonzero(nodes.start)
        prev = 0
        for s in starts.tolist():
            if self._started:
                self._pending.append(nodes.slice(prev, s))
                rot = Nodes.concat(self._pending)
                if len(rot):
                    out.append((rot, self._stamp))
            self._pending, self._pending_n = [], 0
            self._started = True
            self._stamp = stamp
            prev = s
        if self._started:
            tail = nodes.slice(prev, len(nodes))
            self._pending.append(tail)
            self._pending_n += len(tail)
            if self._pending_n > self.max_nodes:
                self._pending, self._pending_n, self._started = [], 0, False
        return out

    def reset(self) -> None:
        self._pending, self._pending_n, self._started = [], 0, False


def rotation_to_scan(nodes: Nodes, spec: LidarSpec, stamp: float) -> LaserScan:
    """One rotation (clockwise A1 angles) -> a REP-103 ``LaserScan`` with ``spec.beams`` beams.

    The A1 measures clockwise seen from above, so the CCW angle is ``-angle_cw``. Samples are put in
    the nearest beam; a beam keeps its nearest valid return (conservative for obstacle avoidance).
    A beam whose samples all read 0 (no return) is ``+inf`` (REP-117); a beam no sample fell in is
    ``nan`` (not measured: it must neither mark nor clear). Vectorized over the nodes.
    """
    inc = spec.angle_increment
    full = abs(spec.fov - 2 * math.pi) < 1e-9
    a = -np.radians(nodes.angle_deg)
    k = np.round((a - spec.angle_min) / inc).astype(np.int64)
    if full:
        k %= spec.beams
        keep = np.ones(k.shape, dtype=bool)
    else:
        keep = (k >= 0) & (k < spec.beams)
    k = k[keep]
    d = nodes.dist_mm[keep] / 1000.0
    counts = np.bincount(k, minlength=spec.beams)
    valid = d > 0
    ranges = np.full(spec.beams, np.inf)
    np.minimum.at(ranges, k[valid], d[valid])
    ranges[counts == 0] = np.nan
    return LaserScan(
        stamp=stamp,
        angle_min=spec.angle_min,
        angle_increment=inc,
        ranges=ranges,
        range_min=spec.range_min,
        range_max=spec.range_max,
        frame_id="laser",
    )


def set_motor(ser: serial.Serial, on: bool) -> bool:
    """Motor on/off through DTR (A1 USB adapter: DTR asserted stops the motor). False if the port has
    no modem lines: a Linux pseudo-terminal answers the TIOCMBIS/TIOCMBIC ioctls with ENOTTY."""
    try:
        ser.dtr = not on
        return True
    except (OSError, serial.SerialException):
        return False


def hold_dtr_after_close(ser: serial.Serial) -> bool:
    """Clear HUPCL so that closing the port leaves DTR as it is. With HUPCL (the usual default of USB
    serial ports) the kernel drops DTR on the last close, and the A1's motor, stopped by DTR
    asserted, spins again once navdeck has exited. False if the port has no termios."""
    try:
        attrs = termios.tcgetattr(ser.fileno())
        attrs[2] &= ~termios.HUPCL
        termios.tcsetattr(ser.fileno(), termios.TCSANOW, attrs)
        return True
    except (termios.error, OSError, ValueError, AttributeError, serial.SerialException):
        return False


@dataclass(frozen=True)
class RPLidarOptions:
    """Options of the ``RPLidar`` driver (seconds)."""

    response_timeout: float = 1.0
    """Wait this long for GET_HEALTH / GET_INFO answers."""
    silent_timeout: float = 1.0
    """No scan node for this long while scanning -> fault and restart the scan."""
    reset_wait: float = 2.0
    """After RESET the A1 reboots; wait before talking to it again."""
    min_quality: int = 0
    """Drop nodes below this quality (0 keeps all; the A1 reports 0 for no-return samples)."""


class RPLidar:
    """RPLidar A1 driver: a reader thread, health check, scan assembly, reconnect with back-off.

    ``take_scan()`` returns the newest complete rotation since the last call (or None); ``fault`` is a
    one-line reason while something is wrong (health error, silent sensor, port gone).
    Raises ``PortUnavailableError`` if the port is missing or busy at start.
    """

    def __init__(
        self,
        port: str,
        spec: LidarSpec,
        clock: Clock | None = None,
        baud: int = 115200,
        options: RPLidarOptions | None = None,
        on_scan: Callable[[LaserScan], None] | None = None,
    ) -> None:
        self.port = port
        self.spec = spec
        self.baud = baud
        self.clock: Clock = clock or RealClock()
        self.options = options or RPLidarOptions()
        self.on_scan = on_scan
        self._ser: serial.Serial | None = open_port(port, baud, timeout=0.02)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._parser = StreamParser()
        self._assembler = ScanAssembler()
        self._backoff = Backoff()
        self._scan: LaserScan | None = None
        self.fault: str | None = None
        self.info: DeviceInfo | None = None
        self.health: Health | None = None
        self.scans = 0
        self.samples = 0
        self.motor_on = False  # what was last asked of the motor line
        self.motor_line: bool | None = None  # whether the port has a DTR line (None: not tried yet)
        self._thread = threading.Thread(target=self._run, name=f"rplidar {port}", daemon=True)
        self._thread.start()

    # ---- thread ----------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a bug here must not pass for a silent sensor
            reason = describe_crash(f"lidar reader thread ({self.port})", exc)
            log.exception("%s", reason)
            with self._lock:
                self.fault = reason  # nothing clears it: no scan can arrive any more

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self._ser is None:
                if self._stop.wait(self._backoff.next_delay()):
                    return
                try:
                    self._ser = open_port(self.port, self.baud, timeout=0.02)
                except PortUnavailableError as exc:
                    self.fault = str(exc)
                    continue
                self._backoff.reset()
            try:
                self._session(self._ser)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                self.fault = f"lidar port {self.port} disconnected: {str(exc).splitlines()[0]}"
                log.warning("%s", self.fault)
                ser, self._ser = self._ser, None
                if ser is not None:
                    with contextlib.suppress(Exception):
                        ser.close()

    def _write(self, ser: serial.Serial, data: bytes) -> None:
        ser.write(data)

    def _ask(self, ser: serial.Serial, cmd: Cmd, want: type) -> DeviceInfo | Health | None:
        self._parser.reset()
        self._write(ser, request(cmd))
        end = time.monotonic() + self.options.response_timeout
        while time.monotonic() < end and not self._stop.is_set():
            data = ser.read(max(1, ser.in_waiting))
            if data:
                responses, _ = self._parser.feed(data)
                for r in responses:
                    if isinstance(r, want):
                        return r
        return None

    def _motor(self, ser: serial.Serial, on: bool) -> None:
        """Switch the motor through DTR; a port without modem-control ioctls (the emulator's pty) is
        noted once: a motor behind such a port spins whenever it is powered."""
        self.motor_on = on
        if set_motor(ser, on):
            self.motor_line = True
        elif self.motor_line is None:
            self.motor_line = False
            log.info("lidar port %s has no DTR line: the motor cannot be switched from here", self.port)

    def _stop_scan(self, ser: serial.Serial) -> None:
        self._write(ser, request(Cmd.STOP))
        time.sleep(0.01)  # the A1 needs >= 1 ms after STOP before the next request
        ser.reset_input_buffer()
        self._parser.reset()
        self._assembler.reset()

    def _session(self, ser: serial.Serial) -> None:
        """Health check, info, then scan until the sensor goes silent or the port dies."""
        self._motor(ser, True)  # the A1 needs its motor spinning before SCAN gives nodes
        self._stop_scan(ser)
        health = self._ask(ser, Cmd.GET_HEALTH, Health)
        if health is None:
            self.fault = f"lidar on {self.port} does not answer GET_HEALTH"
            self._stop.wait(self._backoff.next_delay())
            return
        self.health = health
        if health.status == HealthStatus.ERROR:
            self.fault = f"lidar health error (code 0x{health.error_code:04x}); resetting"
            log.warning("%s", self.fault)
            self._write(ser, request(Cmd.RESET))
            self._stop.wait(self.options.reset_wait)
            ser.reset_input_buffer()
            self._stop.wait(self._backoff.next_delay())
            return
        info = self._ask(ser, Cmd.GET_INFO, DeviceInfo)
        if info is not None:
            self.info = info
        self._parser.reset()
        self._write(ser, request(Cmd.SCAN))
        last_node = time.monotonic()
        while not self._stop.is_set():
            data = ser.read(max(1, ser.in_waiting))
            now = time.monotonic()
            if data:
                _, nodes = self._parser.feed(data)
                if len(nodes):
                    last_node = now
                    self._on_nodes(nodes)
            if now - last_node > self.options.silent_timeout:
                self.fault = f"lidar on {self.port} silent for {now - last_node:.1f} s; restarting scan"
                log.warning("%s", self.fault)
                self._stop_scan(ser)
                return
        with contextlib.suppress(Exception):
            self._stop_scan(ser)
            self._motor(ser, False)
            hold_dtr_after_close(ser)  # the motor stays stopped once the port is closed

    def _on_nodes(self, nodes: Nodes) -> None:
        self.samples += len(nodes)
        if self.options.min_quality > 0:
            low = nodes.quality < self.options.min_quality
            nodes.dist_mm = np.where(low, 0.0, nodes.dist_mm)
        for rot, stamp in self._assembler.push(nodes, self.clock.now()):
            scan = rotation_to_scan(rot, self.spec, stamp)
            with self._lock:
                self._scan = scan
                self.scans += 1
                self.fault = None
                self._backoff.reset()
            if self.on_scan is not None:
                self.on_scan(scan)

    # ---- control-loop side -----------------------------------------------------------------------
    def take_scan(self) -> LaserScan | None:
        with self._lock:
            scan, self._scan = self._scan, None
        return scan

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        ser, self._ser = self._ser, None
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.close()
