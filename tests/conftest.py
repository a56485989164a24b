"""Shared fixtures and helpers: a real navdeck app (simulated robot, temporary SQLite) in-process or
served; teleop over its websocket and a control loop on a driver, for the hardware-path tests."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from app.embedded import EmbeddedServer, serve_in_thread
from nav.types import Twist2D
from robot.base import Driver, SensorFrame

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"
CHROMIUM = Path("/usr/bin/chromium")  # Debian's, installed by scripts/test.sh when root
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
]


BROWSER_MARKS = [
    pytest.mark.browser,
    pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium"),
]
"""``pytestmark`` of every browser-test module."""


@contextmanager
def operator_page(browser, url: str, pose: dict, timeout_ms: int = 120_000) -> Iterator:
    """A Live page whose operator takes control (from whoever held it) and sets the initial pose
    ``{x, y[, theta]}``, as someone arriving at the dashboard would; the context closes after."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, bypass_csp=True)
    ctx.set_default_timeout(timeout_ms)
    page = ctx.new_page()
    try:
        page.goto(url + "/")
        take = page.request.post(url + "/api/control/acquire", data={"take_over": True})
        assert take.ok, take.text()
        r = page.request.post(url + "/api/localization/initial_pose", data=pose)
        assert r.ok, r.text()
        yield page
    finally:
        ctx.close()


def make_settings(tmp_path: Path, **overrides):
    from app.settings import Settings

    base = dict(data_dir=tmp_path, db_url=f"sqlite:///{tmp_path / 'navdeck.db'}", viewer=False)
    base.update(overrides)
    return Settings(**base)


def twist(vx: float = 0.0, wz: float = 0.0, vy: float = 0.0) -> str:
    """A teleop message as the dashboard sends it over the websocket."""
    return json.dumps({"linear": {"x": vx, "y": vy, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": wz}})


def teleop_until(ws, done, timeout: float = 15.0, vx: float = 0.0, vy: float = 0.0, wz: float = 0.0) -> bool:
    """Send teleop commands at 10 Hz (the dashboard's rate) until ``done()`` (or ``timeout`` s), then a
    stop: how far the robot got is the condition, not how long it drove, so a starved machine only
    makes it take longer. Used by the hardware-path stack tests (emulators and the C firmware)."""
    end = time.monotonic() + timeout
    while not (reached := done()) and time.monotonic() < end:
        ws.send(twist(vx, wz, vy))
        time.sleep(0.1)
    ws.send(twist())
    return reached


def drive(d: Driver, cmd: Twist2D, seconds: float, period: float = 0.05) -> list[SensorFrame]:
    """Run a 20 Hz control loop on a driver for ``seconds`` and return its frames (the serial driver
    against the Python emulator and against the C firmware)."""
    frames = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        d.command(cmd)
        frames.append(d.read())
        time.sleep(period)
    return frames


def last_ticks(frames: list[SensorFrame]) -> np.ndarray:
    """The newest cumulative wheel counts among ``frames``."""
    return next(f.ticks.counts for f in reversed(frames) if f.ticks is not None)


@pytest.fixture
def live_server(tmp_path: Path) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path)) as server:
        yield server


@pytest.fixture
def live_server_viewer(tmp_path: Path) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path, viewer=True)) as server:
        yield server


@pytest.fixture
def client(tmp_path: Path):
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.runtime import Runtime

    runtime = Runtime.build(make_settings(tmp_path))
    with TestClient(create_app(runtime)) as c:
        yield c


# --------------------------------------------------------------------------- databases (issue 9)
# One throw-away PostgreSQL server per session (tests/pg.py); tests that take ``db_url`` run once on
# SQLite and once on PostgreSQL. The PostgreSQL variants are skipped, with the reason, only when the
# server cannot be installed or started.


@pytest.fixture(scope="session")
def pg_server():
    from pg import PostgresUnavailable, start_server

    try:
        server = start_server()
    except PostgresUnavailable as exc:
        pytest.skip(f"PostgreSQL unavailable: {exc}")
    yield server
    server.stop()


@pytest.fixture
def pg_url(pg_server) -> str:
    """A fresh, empty PostgreSQL database (SQLAlchemy URL)."""
    return pg_server.create_database()


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path: Path) -> str:
    """An empty database of each kind: a SQLite file, or a fresh database on the session's PostgreSQL."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'navdeck.db'}"
    return request.getfixturevalue("pg_url")


@pytest.fixture
def db_client(tmp_path: Path, db_url: str):
    """Like ``client`` but on each database kind (``db_url``)."""
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.runtime import Runtime

    runtime = Runtime.build(make_settings(tmp_path, db_url=db_url))
    with TestClient(create_app(runtime)) as c:
        yield c


@pytest.fixture(scope="module")
def browser():
    """One headless chromium (software WebGL) per browser-test module."""
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()
