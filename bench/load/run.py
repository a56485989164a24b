"""Load and soak driver (issue 9 part 4): a real server in a child process, N telemetry viewers, N REST
pollers, one teleop driver, one stalled client; measure what the operator would feel.

Why each piece:
- viewers: ``/ws/telemetry`` websockets, each counting frames, so the per-client delivery rate shows
  whether the fan-out keeps up (target >= 9 Hz each with 50 viewers);
- pollers: ``GET /api/robot`` at 5 Hz each, the dashboard's REST traffic;
- driver: ``/ws/teleop`` twists at 10 Hz in a slow circle, so the control loop, odometry and the
  recorder all work while loaded;
- stalled client: a raw TCP websocket that never reads; the server must drop it (its send times out)
  and never let it slow the control loop;
- the control-loop timing comes from the server itself (``/api/health`` -> ``health.loop``: lateness of
  each tick's start against its 20 Hz schedule, last <= 2000 ticks), CPU and RSS from ``/proc/<pid>``.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import statistics
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from bench.load.server import ServerProcess, spawn_server

CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


@dataclass(frozen=True)
class LoadOptions:
    """One load run. Defaults are the issue's target scenario."""

    viewers: int = 50  # telemetry websocket clients
    poll_hz: float = 5.0  # REST polling rate per viewer
    telemetry_hz: float = 15.0  # rate each viewer asks for (server default)
    seconds: float = 30.0  # measured duration (after warm-up)
    warmup_s: float = 5.0
    stalled_clients: int = 1
    db_url: str = ""  # default: a SQLite file in a temporary directory
    world: str = "apartment"
    sample_every_s: float = 5.0  # RSS / CPU sampling period (soak curve)


@dataclass
class LoadReport:
    viewers: int
    seconds: float
    rates_hz: list[float]
    poll_ok: int
    poll_latency_p99_ms: float
    lateness_p50_ms: float
    lateness_p99_ms: float
    period_p99_ms: float  # start-to-start interval of ticks: the "period over the 20 Hz period"
    tick_p99_ms: float
    overruns: int
    cpu_pct: float  # of one core, server process, during the measured window
    client_cpu_pct: float = float("nan")  # the load generator's own CPU (saturated: figures are its limit)
    rss_mb: list[tuple[float, float]] = field(default_factory=list)  # (t since warm-up end, MB)
    stalled_dropped: bool | None = None
    server_alive: bool = True
    poll_error_kinds: dict[str, int] = field(default_factory=dict)  # "HTTP 503" / exception name -> count

    @property
    def poll_errors(self) -> int:
        return sum(self.poll_error_kinds.values())

    @property
    def min_rate(self) -> float:
        return min(self.rates_hz) if self.rates_hz else 0.0

    def rss_growth_mb(self) -> float:
        """RSS at the end minus RSS at the end of warm-up (mean of the last/first two samples)."""
        if len(self.rss_mb) < 2:
            return 0.0
        first = statistics.fmean(m for _, m in self.rss_mb[:2])
        last = statistics.fmean(m for _, m in self.rss_mb[-2:])
        return last - first

    def rss_slope_mb_per_30min(self) -> float:
        """Least-squares slope of RSS over time, scaled to 30 minutes (robust to one-off jumps)."""
        if len(self.rss_mb) < 3:
            return 0.0
        ts = [t for t, _ in self.rss_mb]
        ms = [m for _, m in self.rss_mb]
        return statistics.linear_regression(ts, ms).slope * 1800.0

    def as_dict(self) -> dict:
        return {
            "viewers": self.viewers,
            "seconds": self.seconds,
            "telemetry_min_hz": round(self.min_rate, 2),
            "telemetry_mean_hz": round(statistics.fmean(self.rates_hz), 2) if self.rates_hz else 0.0,
            "poll_ok": self.poll_ok,
            "poll_errors": self.poll_errors,
            "poll_error_kinds": self.poll_error_kinds,
            "poll_latency_p99_ms": round(self.poll_latency_p99_ms, 1),
            "loop_lateness_p50_ms": round(self.lateness_p50_ms, 2),
            "loop_lateness_p99_ms": round(self.lateness_p99_ms, 2),
            "loop_period_p99_ms": round(self.period_p99_ms, 2),
            "tick_p99_ms": round(self.tick_p99_ms, 2),
            "overruns": self.overruns,
            "server_cpu_pct": round(self.cpu_pct, 1),
            "load_generator_cpu_pct": round(self.client_cpu_pct, 1),
            "machine_load_avg_1min": round(os.getloadavg()[0], 2),
            "rss_start_mb": round(self.rss_mb[0][1], 1) if self.rss_mb else None,
            "rss_end_mb": round(self.rss_mb[-1][1], 1) if self.rss_mb else None,
            "rss_growth_mb": round(self.rss_growth_mb(), 1),
            "rss_slope_mb_per_30min": round(self.rss_slope_mb_per_30min(), 1),
            "stalled_client_dropped": self.stalled_dropped,
            "server_alive": self.server_alive,
        }


# ------------------------------------------------------------------------------------ /proc probes
def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of ``pid`` (and its threads) from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def proc_rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


# ------------------------------------------------------------------------------------ clients
async def _viewer(url: str, counts: list[int], i: int, stop: asyncio.Event) -> None:
    from websockets.asyncio.client import connect

    try:
        async with connect(url, max_size=None, open_timeout=30) as ws:
            while not stop.is_set():
                try:
                    await asyncio.wait_for(ws.recv(), timeout=1.0)
                except TimeoutError:
                    continue
                counts[i] += 1
    except Exception:  # a dropped viewer shows up as a low rate, which is what is reported
        return


async def _poller(client, hz: float, stop: asyncio.Event, lat: list[float], errors: Counter[str]) -> None:
    period = 1.0 / hz
    nxt = time.monotonic()
    while not stop.is_set():
        t0 = time.monotonic()
        try:
            r = await client.get("/api/robot")
            if r.status_code == 200:
                lat.append((time.monotonic() - t0) * 1e3)
            else:
                errors[f"HTTP {r.status_code}"] += 1
        except Exception as exc:  # timeouts, refused or reset connections: kept by kind
            errors[type(exc).__name__] += 1
        nxt += period
        await asyncio.sleep(max(0.0, nxt - time.monotonic()))


async def _driver(url: str, stop: asyncio.Event) -> None:
    """Teleop at 10 Hz: a slow circle (0.15 m/s, 0.5 rad/s) that stays clear of the walls."""
    from websockets.asyncio.client import connect

    async with connect(url + "/ws/teleop?name=load-driver", open_timeout=30) as ws:
        await ws.recv()  # hello
        drain = asyncio.create_task(_drain(ws))
        try:
            while not stop.is_set():
                await ws.send(json.dumps({"linear": {"x": 0.15}, "angular": {"z": 0.5}}))
                await asyncio.sleep(0.1)
            await ws.send(json.dumps({"linear": {"x": 0.0}, "angular": {"z": 0.0}}))
        finally:
            drain.cancel()


async def _drain(ws) -> None:
    while True:
        await ws.recv()


def open_stalled_client(port: int, path: str = "/ws/telemetry?hz=20") -> socket.socket:
    """A websocket that completes the handshake and then never reads a byte (tiny receive buffer)."""
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    return s


def stalled_was_dropped(s: socket.socket, timeout: float = 10.0) -> bool:
    """Read what the server queued; True if it then closed the connection (EOF or reset)."""
    s.settimeout(0.5)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if not s.recv(1 << 20):
                return True
        except TimeoutError:
            continue
        except OSError:
            return True
    return False


# ------------------------------------------------------------------------------------ the run
async def _drive_load(server: ServerProcess, opts: LoadOptions, progress=None) -> LoadReport:
    import httpx

    ws_base = f"ws://127.0.0.1:{server.port}"
    stop = asyncio.Event()
    counts = [0] * opts.viewers
    lat: list[float] = []
    errors: Counter[str] = Counter()
    stalled = [open_stalled_client(server.port) for _ in range(opts.stalled_clients)]
    limits = httpx.Limits(max_connections=opts.viewers + 10, max_keepalive_connections=opts.viewers + 10)
    async with httpx.AsyncClient(base_url=server.base, timeout=10, limits=limits) as client:
        tasks = [
            asyncio.create_task(_viewer(f"{ws_base}/ws/telemetry?hz={opts.telemetry_hz:g}", counts, i, stop))
            for i in range(opts.viewers)
        ]
        tasks += [
            asyncio.create_task(_poller(client, opts.poll_hz, stop, lat, errors)) for _ in range(opts.viewers)
        ]
        tasks.append(asyncio.create_task(_driver(ws_base, stop)))
        await asyncio.sleep(opts.warmup_s)
        c0 = list(counts)
        lat.clear()
        errors.clear()
        cpu0, t0, my0 = proc_cpu_s(server.pid), time.monotonic(), time.process_time()
        rss: list[tuple[float, float]] = [(0.0, proc_rss_mb(server.pid))]
        while (elapsed := time.monotonic() - t0) < opts.seconds:
            await asyncio.sleep(min(opts.sample_every_s, max(0.05, opts.seconds - elapsed)))
            rss.append((time.monotonic() - t0, proc_rss_mb(server.pid)))
            if progress is not None:
                progress(rss[-1])
        wall = time.monotonic() - t0
        cpu = (proc_cpu_s(server.pid) - cpu0) / wall * 100.0
        my_cpu = (time.process_time() - my0) / wall * 100.0
        rates = [(c - b) / wall for c, b in zip(counts, c0, strict=True)]
        health = (await client.get("/api/health")).json()["health"]["loop"]
        stop.set()
        await asyncio.wait(tasks, timeout=5)
        for t in tasks:
            t.cancel()
    dropped = all(stalled_was_dropped(s) for s in stalled) if stalled else None
    for s in stalled:
        s.close()
    lat_sorted = sorted(lat)
    return LoadReport(
        viewers=opts.viewers,
        seconds=wall,
        rates_hz=rates,
        poll_ok=len(lat),
        poll_error_kinds=dict(errors),
        poll_latency_p99_ms=lat_sorted[int(0.99 * (len(lat_sorted) - 1))] if lat_sorted else float("nan"),
        lateness_p50_ms=health.get("lateness_p50_ms", float("nan")),
        lateness_p99_ms=health.get("lateness_p99_ms", float("nan")),
        period_p99_ms=health.get("period_p99_ms", float("nan")),
        tick_p99_ms=health.get("tick_p99_ms", float("nan")),
        overruns=int(health.get("overruns", 0)),
        cpu_pct=cpu,
        client_cpu_pct=my_cpu,
        rss_mb=rss,
        stalled_dropped=dropped,
        server_alive=server.proc.poll() is None,
    )


def run_load(opts: LoadOptions, progress=None) -> LoadReport:
    """Start a server, drive it with ``opts``, stop it, and return the report."""
    with tempfile.TemporaryDirectory(prefix="navdeck-load-") as tmp:
        db_url = opts.db_url or f"sqlite:///{Path(tmp) / 'load.db'}"
        server = spawn_server(db_url, Path(tmp), world=opts.world, robot_name="load", ready_timeout=120)
        try:
            return asyncio.run(_drive_load(server, opts, progress))
        finally:
            server.stop()
