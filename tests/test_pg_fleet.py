"""A fleet on one PostgreSQL: two navdeck processes (two simulated robots) start at once, both record
runs, and every run is tagged with its robot and readable from either dashboard (issue 9 part 1)."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from bench.load.server import ServerProcess, spawn_server

pytestmark = pytest.mark.postgres


def _drive_one_run(server: ServerProcess, seconds: float) -> None:
    """teleop mode starts a run (app/recorder.py), idle ends it."""
    server.post_json("/api/robot/mode", {"mode": "teleop"})
    time.sleep(seconds)
    server.post_json("/api/robot/mode", {"mode": "idle"})


def _runs(server: ServerProcess, n: int, timeout: float = 20.0) -> list[dict]:
    deadline = time.monotonic() + timeout
    while True:
        body = server.get_json("/api/runs?limit=50")
        items = body["items"] if isinstance(body, dict) else body
        done = [r for r in items if r.get("outcome") != "recording"]
        if len(done) >= n or time.monotonic() > deadline:
            return items
        time.sleep(0.3)


def test_two_robots_share_one_postgres(pg_url: str, tmp_path: Path) -> None:
    names = ("robot-a", "robot-b")
    with ThreadPoolExecutor(2) as pool:  # both start (and migrate) at the same moment
        servers = list(
            pool.map(lambda n: spawn_server(pg_url, tmp_path / n, robot_name=n, ready_timeout=120), names)
        )
    try:
        with ThreadPoolExecutor(2) as pool:
            list(pool.map(lambda s: _drive_one_run(s, 1.5), servers))
        for s in servers:
            health = s.get_json("/api/health")
            assert health["robot_name"] in names
        seen = [_runs(s, 2) for s in servers]
        assert [r["id"] for r in seen[0]] == [r["id"] for r in seen[1]]  # one database, one view
        by_robot = {r["robot"]: r for r in seen[0]}
        assert set(by_robot) == set(names), seen[0]
        ids = {r["robot_id"] for r in seen[0]}
        assert None not in ids and len(ids) == 2
        for r in seen[0]:
            assert r["outcome"] != "recording"
            detail = servers[1].get_json(f"/api/runs/{r['id']}")
            assert detail["id"] == r["id"]
            traj = servers[0].get_json(f"/api/runs/{r['id']}/trajectory?max_points=50")
            assert traj  # samples of the other robot's run are readable here too
    finally:
        for s in servers:
            s.stop()
