"""Control-loop timing while serving: 20 Hz period jitter with telemetry clients connected."""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench.core import Benchmark, Figure


def _telemetry_client(url: str, stop: threading.Event, counts: list[int], i: int) -> None:
    from websockets.sync.client import connect

    with connect(url) as ws:
        while not stop.is_set():
            ws.recv(timeout=5)
            counts[i] += 1


def loop_jitter(clients: int = 5, seconds: float = 10.0) -> list[Figure]:
    from app.embedded import serve_in_thread
    from app.settings import Settings

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(data_dir=Path(tmp), db_url=f"sqlite:///{tmp}/b.db", viewer=True, world="office")
        with serve_in_thread(settings) as server:
            stop = threading.Event()
            counts = [0] * clients
            threads = [
                threading.Thread(
                    target=_telemetry_client,
                    daemon=True,
                    args=(f"{server.ws_url}/ws/telemetry?hz=15", stop, counts, i),
                )
                for i in range(clients)
            ]
            for t in threads:
                t.start()
            time.sleep(1.0)  # warm-up
            stats = server.runtime.session.stats
            stats.lateness_ms.clear()
            stats.duration_ms.clear()
            c0 = list(counts)
            time.sleep(seconds)
            late = np.fromiter(stats.lateness_ms, float)
            dur = np.fromiter(stats.duration_ms, float)
            rates = [(c - b) / seconds for c, b in zip(counts, c0, strict=True)]
            stop.set()
    p99 = float(np.percentile(late, 99))
    return [
        Figure(f"period jitter p50 ({clients} clients)", float(np.percentile(late, 50)), "ms"),
        Figure(f"period jitter p99 ({clients} clients)", p99, "ms", "< 5 ms", p99 < 5.0),
        Figure("tick duration p99", float(np.percentile(dur, 99)), "ms"),
        Figure("telemetry rate per client (min)", min(rates), "Hz", ">= 10 Hz", min(rates) >= 10.0),
    ]


BENCHMARKS = [Benchmark("loop.jitter", loop_jitter)]
