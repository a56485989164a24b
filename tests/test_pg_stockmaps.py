"""Stock-map registration is idempotent and race-safe (issue 9 part 1): a fleet of navdeck processes
starting at once against one database registers each stock world exactly once (migration 0004's
partial unique index + app.map_store.register_stock), on SQLite and on PostgreSQL."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import sqlalchemy as sa
from conftest import ROOT
from sqlalchemy import text
from sqlmodel import Session

from app.db import make_engine, migrate
from app.map_store import MapStore, map_record
from app.models import Run
from nav.types import GridGeometry, OccupancyGrid, Pose2D

# Each process migrates, then registers two stock worlds. Its loader waits at a file barrier until every
# process has looked the world up and found it missing, so all of them insert at the same moment: the
# race of a fleet powering up, made certain instead of likely.
RACER = r"""
import sys, time
from pathlib import Path
from app.db import make_engine, migrate
from app.map_store import MapStore
from maps.mapio import load_map_yaml
from maps.stock import stock_world_path

url, barrier, me, n = sys.argv[1], Path(sys.argv[2]), sys.argv[3], int(sys.argv[4])
engine = make_engine(url)
migrate(engine)

def load(path):
    (barrier / f"{path.stem}-{me}").touch()
    deadline = time.monotonic() + 90
    while len(list(barrier.glob(f"{path.stem}-*"))) < n:
        if time.monotonic() > deadline:
            raise SystemExit("barrier time-out")
        time.sleep(0.01)
    return load_map_yaml(path)

added = MapStore(engine).register_stock({w: stock_world_path(w) for w in ("apartment", "office")}, load)
print(len(added))
"""


def test_fleet_start_registers_each_stock_map_once(pg_url: str, tmp_path: Path) -> None:
    """PostgreSQL, the fleet database (SQLite has one writer at a time but the same look-up/insert gap;
    the constraint is the same index there, exercised by the migration test below)."""
    db_url = pg_url
    n = 3
    barrier = tmp_path / "barrier"
    barrier.mkdir()
    migrate(make_engine(db_url))  # the migration race is tests/test_pg_storage.py's; this is the insert race
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", RACER, db_url, str(barrier), str(i), str(n)],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(n)
    ]
    results = [(p.wait(180), *p.communicate()) for p in procs]
    assert all(rc == 0 for rc, _, _ in results), [err[-800:] for rc, _, err in results if rc]
    assert len(list(barrier.iterdir())) == 2 * n  # every process reached the insert of both worlds
    assert sum(int(out.strip()) for _, out, _ in results) == 2  # one winner per world
    engine = make_engine(db_url)
    try:
        with engine.connect() as conn:
            rows = conn.execute(
                text("SELECT name, COUNT(*) FROM maps WHERE is_stock GROUP BY name ORDER BY name")
            ).all()
        assert [tuple(r) for r in rows] == [("apartment", 1), ("office", 1)]
        store = MapStore(engine)
        assert store.grid(store.find("office", stock=True).id).geometry.width > 0
        # imported (non-stock) maps may still share a name: the index covers stock rows only
        grid = OccupancyGrid(GridGeometry(0.05, 4, 4, Pose2D()), np.zeros((4, 4), np.int8))
        store.add("office", grid)
        store.add("office", grid)
        assert len([m for m in store.list() if m.name == "office"]) == 3
    finally:
        engine.dispose()


def insert_map_at_0003(
    engine: sa.Engine, name: str, grid: OccupancyGrid, *, source: str = "import", is_stock: bool = False
) -> int:
    """A map row written with the columns the schema had at 0003 (today's model has later columns,
    such as 0007's parent_id and version, that the old table lacks)."""
    rec = map_record(name, grid, source=source, is_stock=is_stock)
    maps = sa.Table("maps", sa.MetaData(), autoload_with=engine)
    values = {c.name: getattr(rec, c.name) for c in maps.columns if c.name != "id"}
    with engine.begin() as conn:
        return int(conn.execute(maps.insert().values(**values)).inserted_primary_key[0])


def test_migration_0004_merges_existing_duplicates(db_url: str) -> None:
    """A database where the race already happened: duplicates are merged and runs repointed."""
    engine = make_engine(db_url)
    try:
        migrate(engine, "0003")
        store = MapStore(engine)
        grid = OccupancyGrid(GridGeometry(0.05, 4, 4, Pose2D()), np.zeros((4, 4), np.int8))
        first = insert_map_at_0003(engine, "office", grid, source="stock", is_stock=True)
        dup = insert_map_at_0003(engine, "office", grid, source="stock", is_stock=True)
        mine = insert_map_at_0003(engine, "office", grid)  # an import with the same name is not a duplicate
        with Session(engine) as s:
            run = Run(kind="teleop", map_id=dup)
            s.add(run)
            s.commit()
            run_id = run.id
        migrate(engine)
        ids = sorted(m.id for m in store.list() if m.name == "office")
        assert ids == sorted([first, mine])
        with Session(engine) as s:
            assert s.get(Run, run_id).map_id == first
    finally:
        engine.dispose()
