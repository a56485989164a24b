"""Runs benchmarks: recording cost on the loop thread, storage per hour, listing, replay seek.

``synth_run`` writes a run straight through ``RunsStore`` (the recorder's own write path) from a
synthetic but realistic trajectory: a robot circling at 0.3 m/s with a 360-beam scan of a room.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from bench.core import Benchmark, Figure


def _scan(rng: np.random.Generator, t: float, beams: int = 360):
    from nav.types import LaserScan

    a = -math.pi + (2 * math.pi / beams) * np.arange(beams)
    # A 6 x 4 m room seen from near its centre, with noise and 1% dropouts (+inf).
    r = np.minimum(
        np.abs(3.0 / np.maximum(np.abs(np.cos(a)), 1e-6)), np.abs(2.0 / np.maximum(np.abs(np.sin(a)), 1e-6))
    )
    r = r + rng.normal(0.0, 0.01, beams)
    r[rng.random(beams) < 0.01] = np.inf
    return LaserScan(t, -math.pi, 2 * math.pi / beams, r, 0.15, 6.0)


def synth_run(
    store,
    *,
    duration_s: float = 60.0,
    kind: str = "navigation",
    outcome: str | None = "completed",
    started_at: datetime | None = None,
    map_id: int | None = None,
    robot: str = "bench",
    seed: int = 0,
    sample_hz: float = 10.0,
    scan_hz: float = 2.0,
    grid=None,
    events: list[dict] | None = None,
    goals: list[dict] | None = None,
) -> int:
    """Write a run of ``duration_s`` in 1 s batches; ``outcome=None`` leaves it recording."""
    from app.runs.codec import MODE_CODE
    from app.runs.store import Batch

    rng = np.random.default_rng(seed)
    rid = store.create_run(
        kind, robot_name=robot, profile="skid4", map_id=map_id, started_at=started_at,
        summary={"laser_pose": [0.0, 0.0, 0.0]},
    )  # fmt: skip
    mode = MODE_CODE["navigating" if kind == "navigation" else kind]
    n_batches = max(1, math.ceil(duration_s))
    plan = np.column_stack((np.linspace(0, 2, 40), np.zeros(40), np.zeros(40)))
    for b in range(n_batches):
        batch = Batch(run_id=rid)
        ts = np.arange(b, min(b + 1.0, duration_s), 1.0 / sample_hz)
        for t in ts:
            th = 0.15 * t
            x, y = 1.5 * math.cos(th), 1.5 * math.sin(th)
            batch.samples.append(
                (t, x, y, th + math.pi / 2, x, y, th + math.pi / 2, 0.225, 0.0, 0.15,
                 0.225, 0.0, 0.15, 0.01, 0.01, 0.002, 0.8 + 0.1 * math.sin(t), mode, 0)
            )  # fmt: skip
        for t in np.arange(b, min(b + 1.0, duration_s), 1.0 / scan_hz):
            batch.scan_times.append(float(t))
            batch.scans.append(_scan(rng, float(t)))
        if b == 0:
            batch.plans.append((0.0, plan))
            batch.events.append(
                {"t": 0.0, "type": "mode", "from": "idle", "to": "navigating", "reason": "bench"}
            )
            batch.events.extend(events or [])
            batch.goals.extend(goals or [])
            if grid is not None:
                batch.grids.append((0.0, 1, grid))
        batch.duration_s = float(ts[-1]) if len(ts) else None
        store.write(batch)
    if outcome is not None:
        store.finish(rid, outcome, end_reason="bench")
    return rid


def _engine(tmp: Path):
    from app.db import make_engine, migrate

    engine = make_engine(f"sqlite:///{tmp / 'bench.db'}")
    migrate(engine)
    return engine


def bench_loop_cost() -> list[Figure]:
    """Extra time per control cycle on the loop thread with the recorder attached (virtual clock)."""
    from app.recorder import Recorder
    from app.runs.store import RunsStore
    from app.session import Session
    from nav.types import Twist2D
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.sim import SimDriver, World

    def session() -> Session:
        clock = VirtualClock()
        w = World.stock("office")
        d = SimDriver(w, load_profile("skid4"), clock, seed=1, start_pose=w.start_pose)
        s = Session(d, clock=clock, grid=w.grid, start_pose=w.start_pose)
        s.request_mode("teleop")
        return s

    def ticks(s: Session, n: int, rec=None) -> list[float]:
        out = []
        for _ in range(n):
            s.set_teleop(Twist2D(0.1, 0.0, 0.2), "bench")
            t0 = time.perf_counter()
            s.run_for(s.period)
            out.append((time.perf_counter() - t0) * 1e3)
            if rec is not None:
                rec.sync(flush=False)  # let the capture thread work between ticks, as in real time
            else:
                time.sleep(0)
        return out

    with tempfile.TemporaryDirectory() as d:
        engine = _engine(Path(d))
        base = ticks(session(), 400)
        s = session()
        rec = Recorder(s, RunsStore(engine))
        rec.start()  # the session is already in teleop: the run starts from the first snapshot
        with_rec = ticks(s, 400, rec)
        # Direct cost of the hand-offs the loop makes: event listener + one bus mailbox put.
        ev = {"t": 0.0, "type": "bench"}
        snap = s.bus.latest
        n = 20000
        t0 = time.perf_counter()
        for _ in range(n):
            rec._on_event(ev)
            rec._sub._put(snap)  # type: ignore[union-attr]
        handoff_us = (time.perf_counter() - t0) / n * 1e6
        rec.close()
        s.close()
        engine.dispose()
    extra = statistics.median(with_rec) - statistics.median(base)
    return [
        Figure("runs.loop_handoff", handoff_us, "us/cycle", "< 1000 us", handoff_us < 1000),
        Figure("runs.loop_tick_delta_p50", extra, "ms", "< 1 ms", extra < 1.0),
        Figure("runs.loop_tick_p50_with_recorder", statistics.median(with_rec), "ms"),
    ]


def bench_storage_hour() -> list[Figure]:
    from app.runs.store import RunsStore

    with tempfile.TemporaryDirectory() as d:
        engine = _engine(Path(d))
        store = RunsStore(engine)
        t0 = time.perf_counter()
        rid = synth_run(store, duration_s=3600.0)
        write_s = time.perf_counter() - t0
        blob_mb = store.storage_bytes(rid) / 1e6
        engine.dispose()
        file_mb = (Path(d) / "bench.db").stat().st_size / 1e6
    return [
        Figure("runs.hour_storage_file", file_mb, "MB", "< 50 MB", file_mb < 50.0),
        Figure("runs.hour_storage_blobs", blob_mb, "MB"),
        Figure("runs.hour_write_time", write_s, "s"),
    ]


def bench_list_and_seek() -> list[Figure]:
    from sqlmodel import Session

    from app.models import Run
    from app.runs.store import RunFilters, RunsStore

    with tempfile.TemporaryDirectory() as d:
        engine = _engine(Path(d))
        store = RunsStore(engine)
        base = datetime(2026, 1, 1, tzinfo=UTC)
        kinds, outcomes = ("teleop", "mapping", "navigation"), ("completed", "succeeded", "failed", "aborted")
        with Session(engine) as s:
            for i in range(10_000):
                s.add(
                    Run(
                        kind=kinds[i % 3], robot_name="bench", profile="skid4", map_id=1 + i % 5,
                        started_at=base + timedelta(minutes=7 * i),
                        ended_at=base + timedelta(minutes=7 * i + 5),
                        outcome=outcomes[i % 4], duration_s=300.0, distance_m=12.5,
                        summary={"duration_s": 300.0, "distance_m": 12.5, "goals_reached": 3},
                    )
                )  # fmt: skip
            s.commit()
        rid = synth_run(store, duration_s=600.0)

        def timed(fn, reps: int = 20) -> float:
            fn()
            out = []
            for _ in range(reps):
                t0 = time.perf_counter()
                fn()
                out.append((time.perf_counter() - t0) * 1e3)
            return statistics.median(out)

        list_ms = timed(lambda: store.list(RunFilters(), 50, 0))
        filt_ms = timed(
            lambda: store.list(RunFilters(kind="navigation", outcome="failed", map_id=3), 50, 100)
        )
        rng = np.random.default_rng(0)
        times = iter(rng.uniform(0, 600, 100))

        def seek() -> None:
            t = float(next(times))
            store.sample_at(rid, t)
            store.scan_at(rid, t)
            store.plan_at(rid, t)

        seek_ms = timed(seek, reps=50)
        from app.runs.replay import ReplayPlayer

        player = ReplayPlayer(store)
        player.load(rid)
        player_ms = timed(lambda: player.seek(float(next(times))), reps=40)
        player.close()
        engine.dispose()
    return [
        Figure("runs.list_10k_p50", list_ms, "ms", "< 100 ms", list_ms < 100.0),
        Figure("runs.list_10k_filtered_p50", filt_ms, "ms", "< 100 ms", filt_ms < 100.0),
        Figure("runs.replay_seek_p50", seek_ms, "ms", "< 200 ms", seek_ms < 200.0),
        Figure("runs.replay_player_seek_p50", player_ms, "ms", "< 200 ms", player_ms < 200.0),
    ]


BENCHMARKS = [
    Benchmark(name="runs.loop_cost", run=bench_loop_cost),
    Benchmark(name="runs.list_and_seek", run=bench_list_and_seek),
    Benchmark(name="runs.storage_hour", run=bench_storage_hour, group="slow"),
]
