"""Crash safety of map saves (issue 9 part 2): kill -9 in the middle of saving maps, restart, and the
store holds every map either completely or not at all, never a partial one.

Two killers: (1) a process saving big maps through ``MapStore.add`` in a loop (the code path every map
save takes: one transaction), killed at random moments, on SQLite and PostgreSQL; (2) the real server
(``python -m app.cli serve``) killed during a map import over HTTP, when the import route exists.
After each kill the real server is started on the same database and must list and serve every map.
"""

from __future__ import annotations

import io
import random
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import httpx
import numpy as np
import pytest
from conftest import ROOT
from sqlmodel import Session, select

from app.db import make_engine
from app.models import MapRecord
from bench.load.server import spawn_server

WRITER = r"""
import sys, numpy as np
from app.db import make_engine, migrate
from app.map_store import MapStore
from nav.types import GridGeometry, OccupancyGrid, Pose2D
engine = make_engine(sys.argv[1]); migrate(engine); store = MapStore(engine)
for seed in range(1000):
    n = 900 + 37 * (seed % 7)
    data = np.random.default_rng(seed).choice(np.array([-1, 0, 100], dtype=np.int8), size=(n, n))
    print(f"saving {seed}", flush=True)
    store.add(f"crash-{seed}", OccupancyGrid(GridGeometry(0.05, n, n, Pose2D(0.0, 0.0, 0.0)), data))
"""


def expected_grid(seed: int) -> np.ndarray:
    n = 900 + 37 * (seed % 7)
    return np.random.default_rng(seed).choice(np.array([-1, 0, 100], dtype=np.int8), size=(n, n))


def check_maps_complete(db_url: str) -> int:
    """Every stored crash map decompresses to exactly the map that was saved; returns how many."""
    engine = make_engine(db_url)
    try:
        with Session(engine) as s:
            recs = s.exec(select(MapRecord).where(MapRecord.name.like("crash-%"))).all()
            for rec in recs:
                seed = int(rec.name.split("-")[1])
                data = np.frombuffer(zlib.decompress(rec.data), dtype=np.int8).reshape(rec.height, rec.width)
                np.testing.assert_array_equal(data, expected_grid(seed), err_msg=rec.name)
                assert rec.thumbnail_png.startswith(b"\x89PNG")
            return len(recs)
    finally:
        engine.dispose()


def restart_and_list(db_url: str, data_dir: Path) -> list[dict]:
    server = spawn_server(db_url, data_dir, ready_timeout=120)
    try:
        maps = server.get_json("/api/maps?limit=500")["items"]
        for m in maps:
            assert server.get_json(f"/api/maps/{m['id']}")["width"] == m["width"]
        return maps
    finally:
        server.stop()


@pytest.mark.parametrize("kind", ["sqlite", "postgresql"])
def test_kill9_during_map_saves_leaves_no_partial_map(kind: str, tmp_path: Path, request) -> None:
    db_url = f"sqlite:///{tmp_path / 'crash.db'}" if kind == "sqlite" else request.getfixturevalue("pg_url")
    rng = random.Random(42)
    saved_before = 0
    for _ in range(3):  # three kills at different points of a save
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, db_url], cwd=ROOT, stdout=subprocess.PIPE, text=True
        )
        assert proc.stdout is not None
        started = 0
        while started < 2:  # let at least one save complete and the next one begin
            line = proc.stdout.readline()
            assert line, "writer exited early"
            started += line.startswith("saving")
        time.sleep(rng.uniform(0.0, 0.4))  # somewhere inside compress / thumbnail / INSERT / COMMIT
        proc.kill()
        proc.wait(10)
        count = check_maps_complete(db_url)
        assert count >= saved_before + 1
        saved_before = count
    maps = restart_and_list(db_url, tmp_path / "srv")
    assert sum(m["name"].startswith("crash-") for m in maps) == saved_before


def _pgm_and_yaml(seed: int, n: int = 2500) -> tuple[bytes, bytes]:
    img = np.random.default_rng(seed).choice(np.array([0, 205, 254], dtype=np.uint8), size=(n, n))
    pgm = f"P5\n{n} {n}\n255\n".encode() + img.tobytes()
    yaml = f"image: m{seed}.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n".encode()
    yaml += b"occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    return pgm, yaml


def test_kill9_server_during_map_import(tmp_path: Path) -> None:
    db_url = f"sqlite:///{tmp_path / 'srv.db'}"
    server = spawn_server(db_url, tmp_path / "srv", ready_timeout=120)
    try:
        schema = server.get_json("/openapi.json")
        if "/api/maps/import" not in schema.get("paths", {}):
            pytest.skip("no map import route (POST /api/maps/import) in this build yet")

        stop = threading.Event()
        done: list[str] = []

        def importer() -> None:
            seed = 0
            with httpx.Client(base_url=server.base, timeout=60) as c:
                while not stop.is_set():
                    pgm, yaml = _pgm_and_yaml(seed)
                    files = {
                        "yaml": (f"m{seed}.yaml", io.BytesIO(yaml), "application/x-yaml"),
                        "image": (f"m{seed}.pgm", io.BytesIO(pgm), "image/x-portable-graymap"),
                    }
                    try:
                        r = c.post("/api/maps/import", files=files, data={"name": f"imp-{seed}"})
                    except httpx.HTTPError:
                        return
                    if r.status_code < 300:
                        done.append(f"imp-{seed}")
                    seed += 1

        t = threading.Thread(target=importer, daemon=True)
        t.start()
        deadline = time.monotonic() + 90
        while not done and time.monotonic() < deadline:
            time.sleep(0.1)
        assert done, f"no import completed: {server.log()[-1500:]}"
        time.sleep(random.Random(7).uniform(0.05, 0.5))
        server.kill9()
        stop.set()
        t.join(30)
    finally:
        server.stop()
    maps = restart_and_list(db_url, tmp_path / "srv2")
    imported = {m["name"]: m for m in maps if m["name"].startswith("imp-")}
    assert set(done) <= set(imported)  # every acknowledged import survived
    for m in imported.values():
        assert (m["width"], m["height"]) == (2500, 2500)  # and none is partial
