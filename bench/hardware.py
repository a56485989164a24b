"""Hardware-path benchmark: latency from a websocket teleop message to its bytes on the serial port.

An in-process server (``serve_in_thread``) drives the emulated STM32 base and RPLidar A1 over
pseudo-terminals (loopback); the emulators run in a child process, as real devices do not share the
server's GIL. Each teleop message carries a new angular rate; the emulated firmware timestamps every
frame it reads off the pty (``BaseEmulator.message_log``), so the latency is ``time the VELOCITY
frame with that rate was read - time the websocket message was sent``, on the system's monotonic
clock. Messages are spaced irregularly so they land at random phases of the control loop.

The path is websocket -> ``Session.set_teleop`` -> next control tick -> limits -> ``SerialDriver``
-> pty: the tick wait is uniform over one control period, so the default 20 Hz loop alone adds up
to 50 ms; the 100 Hz figure shows what the rest of the path costs.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench.core import Benchmark, Figure

TARGET_P99_MS = 20.0


def _latencies(rate_hz: float, n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) latencies in ms with the control loop at ``rate_hz``: websocket send -> bytes read off
    the pty, and the driver's write -> bytes read (the serial leg alone)."""
    from websockets.sync.client import connect

    from app.embedded import serve_in_thread
    from app.settings import Settings
    from robot.serial.driver import wait_for

    rng = np.random.default_rng(seed)
    out: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory(prefix="navdeck-bench-hw-") as tmp, _EmulatorProcess(Path(tmp)) as emu:
        settings = Settings(
            robot=emu.url,
            data_dir=Path(tmp),
            db_url=f"sqlite:///{Path(tmp) / 'navdeck.db'}",
            viewer=False,
            rate_hz=rate_hz,
        )
        with serve_in_thread(settings) as server:
            session = server.runtime.session
            sent = session.driver.sent_log  # SerialDriver: frames written with their times
            if not wait_for(lambda: session.last_scan is not None, timeout=10.0):
                raise RuntimeError("the emulated lidar sent no scan")
            with connect(f"{server.ws_url}/ws/teleop") as ws:
                json.loads(ws.recv(timeout=10))  # hello
                # a triangle wave of rates 0.30..0.50 rad/s, 0.02 apart: each step is within one
                # tick of the acceleration limit, so the limited command equals the message
                wave = np.concatenate((np.arange(0.30, 0.50, 0.02), np.arange(0.50, 0.30, -0.02)))
                for i in range(n + 5):
                    wz = float(wave[i % wave.size])
                    emu.drain()
                    t_send = time.monotonic()
                    ws.send(json.dumps({"linear": {"x": 0.0}, "angular": {"z": wz}}))
                    t_read = emu.wait_for_rate(wz, timeout=1.0)
                    t_write = _first_write(sent, wz, t_send)
                    if i >= 5:  # the first few include entering TELEOP mode
                        out.append(((t_read - t_send) * 1e3, (t_read - t_write) * 1e3))
                    time.sleep(float(rng.uniform(0.01, 0.04)))
                ws.send(json.dumps({"linear": {"x": 0.0}, "angular": {"z": 0.0}}))
    return np.asarray(out)


def _first_write(sent, wz: float, t_send: float, timeout: float = 1.0) -> float:
    """Time the driver wrote the first VELOCITY frame with ``wz`` after ``t_send`` (the log entry is
    appended just after the write returns, so it may trail the child's report by a moment)."""
    from robot.serial.protocol import VelocityCommand

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for t, m in list(sent):
            if t >= t_send and isinstance(m, VelocityCommand) and abs(m.wz - wz) < 1e-4:
                return t
        time.sleep(0.001)
    raise RuntimeError(f"the driver never wrote wz={wz:.2f}")


class _EmulatorProcess:
    """The emulated base + lidar in a child process (as a real MCU is: not sharing this process's
    GIL), reporting ``<monotonic time read> <wz>`` for every VELOCITY frame it reads off the pty.
    CLOCK_MONOTONIC is system-wide on Linux, so the child's read times compare with ours."""

    def __init__(self, link_dir: Path) -> None:
        self.link_dir = link_dir
        self._queue: queue.Queue[tuple[float, float]] = queue.Queue()

    def __enter__(self) -> _EmulatorProcess:
        root = Path(__file__).resolve().parent.parent
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "bench.hardware", "emulate", str(self.link_dir)],
            cwd=root,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        first = self.proc.stdout.readline().split()
        if len(first) != 2 or first[0] != "ready":
            self.proc.kill()
            raise RuntimeError(f"emulator process did not start: {first}")
        self.url = first[1]
        threading.Thread(target=self._read, daemon=True).start()
        return self

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            t, wz = line.split()
            self._queue.put((float(t), float(wz)))

    def drain(self) -> None:
        while not self._queue.empty():
            self._queue.get_nowait()

    def wait_for_rate(self, wz: float, timeout: float) -> float:
        """Read time of the first VELOCITY frame carrying ``wz`` (float32 on the wire)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                t, got = self._queue.get(timeout=max(deadline - time.monotonic(), 1e-3))
            except queue.Empty:
                raise RuntimeError(f"teleop wz={wz:.2f} never reached the serial port") from None
            if abs(got - wz) < 1e-4:
                return t

    def __exit__(self, *exc: object) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()  # the child exits at EOF
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def _emulate(link_dir: str) -> None:
    """Child process of ``_EmulatorProcess``: run an ``EmulatorPair`` until stdin closes."""
    from robot.profiles import load_profile
    from robot.serial.emulate import EmulatorPair
    from robot.serial.protocol import VelocityCommand

    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    with EmulatorPair(load_profile("skid4"), world="box", link_dir=link_dir) as pair:
        print("ready", pair.url(), flush=True)
        log = pair.base.message_log
        while not done.wait(0.002):
            lines = []
            while log:
                t_read, msg = log.popleft()
                if isinstance(msg, VelocityCommand):
                    lines.append(f"{t_read:.6f} {msg.wz:.6f}\n")
            if lines:
                sys.stdout.write("".join(lines))
                sys.stdout.flush()


def _figures(lat: np.ndarray, label: str, target: bool) -> list[Figure]:
    total, serial_leg = lat[:, 0], lat[:, 1]
    p99 = float(np.percentile(total, 99))
    return [
        Figure(f"{label} p50", float(np.percentile(total, 50)), "ms"),
        Figure(
            f"{label} p99",
            p99,
            "ms",
            target=f"< {TARGET_P99_MS:g} ms" if target else "",
            ok=(p99 < TARGET_P99_MS) if target else None,
        ),
        Figure(f"{label}: write->pty read p50", float(np.percentile(serial_leg, 50)), "ms"),
        Figure(f"{label}: write->pty read p99", float(np.percentile(serial_leg, 99)), "ms"),
    ]


def teleop_latency() -> list[Figure]:
    """Default server settings (20 Hz control loop): the figure the issue's target is about."""
    return _figures(_latencies(20.0, 80), "ws->serial 20Hz", target=True)


def teleop_latency_fast_loop() -> list[Figure]:
    """The same path with a 100 Hz control loop: the part of the latency that is not tick phase."""
    return _figures(_latencies(100.0, 80), "ws->serial 100Hz", target=False)


BENCHMARKS = [
    Benchmark(name="hardware.teleop_latency", run=teleop_latency),
    Benchmark(name="hardware.teleop_latency_100hz", run=teleop_latency_fast_loop, group="slow"),
]


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "emulate":
        _emulate(sys.argv[2])
