"""An emulated RPLidar A1 on a pseudo-terminal, measuring the simulator's world.

Speaks Slamtec's protocol byte for byte (STOP, RESET, SCAN, FORCE_SCAN, GET_INFO, GET_HEALTH; other
requests are ignored like the A1 does). Each simulated scan (at the profile's ``rate_hz``, 5.5-10
Hz) becomes one rotation of ``sample_rate / rate_hz`` clockwise nodes with the start flag on the
first, streamed at ``sample_rate`` in real time: by default the A1's 2000 samples/s, or more when
the profile asks more beams per rotation than that gives (a 360-beam lidar at 10 Hz is an A2/A3-class
sensor: 3600 samples/s), so any profile's lidar is emulated without empty beams. The
motor cannot be switched through DTR on a pseudo-terminal, so it always spins while scanning.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque

import numpy as np

from nav.types import LaserScan
from robot.base import SensorFrame
from robot.profiles import LidarSpec
from robot.serial.faults import LineFaults
from robot.serial.pty import PtyPort
from robot.serial.rplidar import SCAN_DESCRIPTOR, SYNC, Cmd, DeviceInfo, Health, encode_nodes
from robot.serial.simlink import SimPump

A1_INFO = DeviceInfo(
    model=0x18, firmware=(1, 29), hardware=7, serial_number="4E6A9AF2C3E19ED2A0E69EF1342E4C09"
)
RESET_BANNER = b"RP LIDAR System.\r\nFirmware Ver 1.29 - rtm, HW Ver 7\r\nModel: 18\r\n"
A1_SAMPLE_RATE = 2000.0  # samples/s in standard scan mode


def default_sample_rate(spec: LidarSpec) -> float:
    """Samples/s that give every beam of ``spec`` a sample each rotation (the emulated angles jitter by
    under a quarter step, so one sample a beam lands in each), and never fewer than the A1's 2000."""
    return max(A1_SAMPLE_RATE, float(spec.beams * spec.rate_hz))


def scan_to_nodes(
    scan: LaserScan, samples: int, rng: np.random.Generator, quality: int = 47
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One rotation of A1 nodes sampling ``scan`` (CCW, laser frame) at ``samples`` clockwise angles.

    Returns (angle_deg_cw, dist_mm, quality, start). Non-finite ranges (no return, too close)
    read distance 0 and quality 0, as the A1 reports them.
    """
    step = 360.0 / samples
    cw = (np.arange(samples) + rng.uniform(0.0, 0.25, samples)) * step
    ccw = -np.radians(cw)
    k = np.round((ccw - scan.angle_min) / scan.angle_increment).astype(np.int64)
    n = scan.ranges.size
    full = abs(scan.angle_increment * n - 2 * math.pi) < 1e-6
    inside = np.ones(samples, dtype=bool) if full else (k >= 0) & (k < n)
    k = np.clip(k % n if full else k, 0, n - 1)
    r = scan.ranges[k]
    ok = inside & np.isfinite(r) & (r > 0)
    dist = np.where(ok, r * 1000.0, 0.0)
    q = np.where(ok, quality, 0)
    start = np.zeros(samples, dtype=bool)
    start[0] = True
    return cw, dist, q, start


class RPLidarEmulator:
    """A1 emulator bound to a ``SimPump`` (scans) and a ``PtyPort``."""

    def __init__(
        self,
        pump: SimPump,
        port: PtyPort | None = None,
        sample_rate: float | None = None,
        faults: LineFaults | None = None,
        seed: int = 0,
    ) -> None:
        self.pump = pump
        self.port = port or PtyPort(name="rplidar")
        self.sample_rate = sample_rate or default_sample_rate(pump.profile.lidar)
        self.faults = faults or LineFaults(seed=seed)
        self.health = Health(0, 0)
        self.info = A1_INFO
        self.rng = np.random.default_rng(seed)
        self.scanning = False
        self.nodes_sent = 0
        self.requests: list[int] = []
        self._rotations: deque[bytes] = deque(maxlen=2)  # newest rotations not yet streamed
        self._out = b""  # bytes of the rotation being streamed
        self._rx = b""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        pump.subscribe(self._on_frame)

    @property
    def path(self) -> str:
        return self.port.path

    def _on_frame(self, frame: SensorFrame) -> None:
        if frame.scan is None or not self.scanning:
            return
        samples = max(8, round(self.sample_rate / self.pump.profile.lidar.rate_hz))
        raw = encode_nodes(*scan_to_nodes(frame.scan, samples, self.rng))
        with self._lock:
            self._rotations.append(raw)

    def start(self) -> RPLidarEmulator:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="emulate-rplidar", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        last = time.monotonic()
        credit = 0.0  # nodes we may send now
        while not self._stop.is_set():
            data = self.port.read(timeout=0.005)
            if data:
                self._rx += data
                self._parse_requests()
            now = time.monotonic()
            credit = min(credit + (now - last) * self.sample_rate, self.sample_rate * 0.05)
            last = now
            if self.scanning and credit >= 1.0:
                with self._lock:
                    if not self._out and self._rotations:
                        self._out = self._rotations.popleft()
                    n = min(int(credit), len(self._out) // 5)
                    chunk, self._out = self._out[: 5 * n], self._out[5 * n :]
                if n:
                    credit -= n
                    self.nodes_sent += n
                    self.port.write(self.faults.apply(chunk))
            if not self.port.plugged:
                self._stop.wait(0.01)

    def _parse_requests(self) -> None:
        buf = self._rx
        while True:
            i = buf.find(bytes((SYNC,)))
            if i < 0 or len(buf) - i < 2:
                buf = buf[i:] if i >= 0 else b""
                break
            cmd = buf[i + 1]
            if cmd & 0x80:  # request with payload: size, payload, checksum
                if len(buf) - i < 3 or len(buf) - i < 4 + buf[i + 2]:
                    buf = buf[i:]
                    break
                buf = buf[i + 4 + buf[i + 2] :]
            else:
                buf = buf[i + 2 :]
            self._request(cmd)
        self._rx = buf

    def _request(self, cmd: int) -> None:
        self.requests.append(cmd)
        if cmd == Cmd.STOP:
            self._halt()
        elif cmd == Cmd.RESET:
            self._halt()
            self._reply(RESET_BANNER)
        elif cmd in (Cmd.SCAN, Cmd.FORCE_SCAN):
            if self.health.status == 2 and cmd == Cmd.SCAN:
                return  # the A1 refuses to scan in protection stop
            self._halt()
            self._reply(SCAN_DESCRIPTOR)
            self.scanning = True
        elif cmd == Cmd.GET_INFO:
            self._reply(self.info.encode())
        elif cmd == Cmd.GET_HEALTH:
            self._reply(self.health.encode())

    def _halt(self) -> None:
        self.scanning = False
        with self._lock:
            self._rotations.clear()
            self._out = b""

    def _reply(self, data: bytes) -> None:
        self.port.write(self.faults.apply(data))

    # ---- fault switches --------------------------------------------------------------------------
    def set_health_error(self, code: int | None) -> None:
        """``code`` -> GET_HEALTH answers status 2 (error) with it; None -> healthy."""
        self.health = Health(0, 0) if code is None else Health(2, code)

    def unplug(self) -> None:
        self._halt()
        self.port.unplug()

    def replug(self) -> None:
        self._rx = b""
        self.port.plug()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        with contextlib.suppress(Exception):
            self.port.close()
