"""Run times (issue 17 item 4): a run's duration, end time and event stamps are on one clock.

A 39 s navigation run was listed as 20 min 11 s, ended 16 min in the future, its recovery events at
t = 1211 s: the recovery events carried their own ``t`` (the session clock's raw reading, monotonic
seconds since boot on a real clock), which replaced the session's stamp (seconds since start)."""

from __future__ import annotations

import math
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
from conftest import make_settings

from app.db import make_engine, migrate
from app.embedded import serve_in_thread
from app.recorder import Recorder, RecorderOptions
from app.runs.store import RunFilters, RunsStore
from app.session import Session
from nav.recovery import RecoveryEvent
from nav.types import Twist2D
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.safety import SafetyFilter, SafetyOptions
from robot.sim import SimDriver, World

START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose


def test_event_stamps_stay_run_relative_on_a_clock_that_did_not_start_at_zero(tmp_path: Path) -> None:
    """A clock at 1000 s when the session starts (a real clock: the machine has been up 1000 s). An
    event whose payload carries a raw clock reading, as a RecoveryEvent does, is stamped like any
    other, and the run lasts what it lasted."""
    engine = make_engine(f"sqlite:///{tmp_path / 'runs.db'}")
    migrate(engine)
    clock = VirtualClock(start=1000.0)
    world = World.stock("office")
    driver = SimDriver(world, load_profile("skid4"), clock, seed=5, start_pose=world.start_pose)
    session = Session(driver, clock=clock, grid=world.grid, start_pose=world.start_pose)
    store = RunsStore(engine)
    rec = Recorder(session, store, RecorderOptions(idle_grace=1.0))
    rec.start()
    try:
        session.request_mode("teleop")
        for _ in range(40):  # 2 s of teleop
            session.set_teleop(Twist2D(0.2, 0.0, 0.0), "test")
            session.run_for(session.period)
            rec.sync(flush=False)
        ev = RecoveryEvent(kind="attempt", t=clock.now(), trigger="no_progress", behavior="spin")
        session.add_event("recovery", **ev.as_dict())
        session.run_for(1.0)
        session.request_mode("idle")
        for _ in range(30):  # > idle_grace: the run ends
            session.run_for(session.period)
            rec.sync(flush=False)
        rec.sync()
        assert not rec.recording
    finally:
        rec.close()
        session.close()
    _, (run,) = store.list(RunFilters())
    events = store.events(run["id"])
    recovery = [e for e in events if e["type"] == "recovery"]
    assert recovery and abs(recovery[0]["t"] - 2.0) < 0.2, recovery
    assert recovery[0]["behavior"] == "spin" and recovery[0]["kind"] == "attempt"
    assert 3.0 <= run["duration_s"] <= 4.5, run
    assert all(0.0 <= e["t"] <= run["duration_s"] + 1e-6 for e in events), events
    engine.dispose()


def _iso(s: str) -> datetime:
    return datetime.fromisoformat(s.replace("Z", "+00:00"))


def test_navigation_run_with_recoveries_lasts_its_wall_time(tmp_path: Path) -> None:
    """A served (real-clock) navigation that a far too cautious safety layer keeps stopping, so the
    safety_stop recovery runs: the run's duration compares with the wall time it took (loosely: a
    loaded machine only stretches both), its end is not in the future and every event is inside it."""
    with (
        serve_in_thread(make_settings(tmp_path)) as server,
        httpx.Client(base_url=server.url, timeout=10) as api,
    ):
        rt = server.runtime
        rt.features["safety"].filter = SafetyFilter(
            rt.profile,
            SafetyOptions(
                stop_margin=2.2, slowdown_margin=2.2, slowdown_enabled=False, approach_enabled=False
            ),
        )
        wall0 = datetime.now(UTC)
        t0 = time.monotonic()
        assert api.post("/api/localization/initial_pose", json=START).status_code == 200
        assert api.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": 0.0}).status_code == 200
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline:
            if any(e["type"] == "recovery" and e.get("kind") == "attempt" for e in rt.session.events):
                break
            time.sleep(0.2)
        else:
            raise AssertionError([e for e in rt.session.events if e["type"] in ("recovery", "navigation")])
        api.post("/api/navigation/cancel")
        assert api.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200  # ends the run
        elapsed = time.monotonic() - t0
        rec = rt.features["recording"].recorder
        rec.sync()
        runs = api.get("/api/runs?kind=navigation").json()["items"]
        assert runs and runs[0]["outcome"] != "recording", runs
        run = api.get(f"/api/runs/{runs[0]['id']}").json()
        wall1 = datetime.now(UTC)
    duration = run["duration_s"]
    assert 0.3 * elapsed - 1.0 <= duration <= elapsed + 1.0, (duration, elapsed)
    started, ended = _iso(run["started_at"]), _iso(run["ended_at"])
    slack = timedelta(seconds=1.0)
    assert wall0 - slack <= started <= ended <= wall1 + slack, (wall0, started, ended, wall1)
    assert math.isclose((ended - started).total_seconds(), duration, abs_tol=1e-3)
    events = run.get("events") or []
    recovery = [e for e in events if e["type"] == "recovery" and e.get("kind") == "attempt"]
    assert recovery, events
    assert all(0.0 <= e["t"] <= duration + 1e-6 for e in events), [e["t"] for e in events]
