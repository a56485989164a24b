"""Storage, migrations and the API on both SQLite and PostgreSQL (issue 9 part 1).

``db_url`` (tests/conftest.py) runs each test on a SQLite file and on a fresh database of the session's
throw-away PostgreSQL server (tests/pg.py).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from conftest import ROOT
from sqlalchemy import inspect, select, text
from sqlmodel import Session

from app.db import downgrade, make_engine, migrate
from app.map_store import MapStore
from app.models import Robot, Run
from app.robots import register_robot
from nav.types import GridGeometry, OccupancyGrid, Pose2D

TABLES = {"robots", "maps", "runs", "run_events", "run_sample_chunks", "users", "user_sessions"}


def test_migrations_up_down_up(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        migrate(engine)
        assert set(inspect(engine).get_table_names()) >= TABLES
        downgrade(engine, "base")
        assert not TABLES & set(inspect(engine).get_table_names())
        migrate(engine)
        assert set(inspect(engine).get_table_names()) >= TABLES
    finally:
        engine.dispose()


def test_concurrent_migrations_converge(pg_url: str) -> None:
    """Four processes migrate one empty PostgreSQL database at once (a fleet powering up): all succeed
    and the schema is at head once. Without the advisory lock in app.db.migrate two of them race on
    CREATE TABLE. (Processes, not threads: Alembic's context is process-global.)"""
    code = "import sys; from app.db import make_engine, migrate; migrate(make_engine(sys.argv[1]))"
    procs = [
        subprocess.Popen([sys.executable, "-c", code, pg_url], cwd=ROOT, stderr=subprocess.PIPE, text=True)
        for _ in range(4)
    ]
    results = [(p.wait(120), p.stderr.read() if p.stderr else "") for p in procs]
    assert all(rc == 0 for rc, _ in results), [err[-500:] for rc, err in results if rc]
    engine = make_engine(pg_url)
    try:
        with engine.connect() as conn:
            versions = conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all()
        assert len(versions) == 1
        assert set(inspect(engine).get_table_names()) >= TABLES
    finally:
        engine.dispose()


def test_map_store_and_robot_tagging(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        migrate(engine)
        rid_a = register_robot(engine, "alpha", "skid4")
        rid_b = register_robot(engine, "bravo", "omni4")
        assert rid_a != rid_b and register_robot(engine, "alpha", "skid4") == rid_a  # restart: same row
        store = MapStore(engine)
        rng = np.random.default_rng(3)
        data = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(120, 90))
        grid = OccupancyGrid(GridGeometry(0.05, 90, 120, Pose2D(-2.0, 1.0, 0.3)), data)
        info = store.add("lab", grid, source="slam", robot_id=rid_b)
        back = store.grid(info.id)
        assert back is not None and back.geometry == grid.geometry
        np.testing.assert_array_equal(back.data, data)
        assert store.info(info.id).robot_id == rid_b
        with Session(engine) as s:  # a run written with only the robot's name gets its id
            s.add(Run(kind="teleop", robot_name="alpha"))
            s.add(Run(kind="teleop", robot_name="ghost"))
            s.commit()
            rows = {r.robot_name: r.robot_id for r in s.scalars(select(Run))}
            assert rows == {"alpha": rid_a, "ghost": None}
            assert {r.name for r in s.scalars(select(Robot))} == {"alpha", "bravo"}
    finally:
        engine.dispose()


def test_api_on_each_database(db_client) -> None:
    """The REST API reads the same on both: stock maps registered, robot registered, 4xx stays 4xx."""
    c = db_client
    assert c.get("/api/health").json()["status"] == "ok"
    maps = c.get("/api/maps", params={"limit": 500}).json()["items"]
    assert any(m["is_stock"] and m["name"] == "apartment" for m in maps)
    m = maps[0]
    assert c.get(f"/api/maps/{m['id']}").json()["name"] == m["name"]
    assert c.get(f"/api/maps/{m['id']}/thumbnail.png").content.startswith(b"\x89PNG")
    assert c.get("/api/maps/999999").status_code == 404
    assert c.get("/api/runs?limit=5").status_code == 200
    assert c.get("/api/runs?limit=-1").status_code == 422
    rt = c.app.state.runtime
    assert rt.robot_id is not None


def test_pg_server_is_shared_per_session(pg_server) -> None:
    """Fresh databases are cheap on the one session server (no second initdb)."""
    urls = {pg_server.create_database() for _ in range(3)}
    assert len(urls) == 3 and all(f":{pg_server.port}/" in u for u in urls)
