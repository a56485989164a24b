"""Shared fixtures: a real navdeck app (simulated robot, temporary SQLite) in-process or served."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from app.embedded import EmbeddedServer, serve_in_thread

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
ARTIFACTS = ROOT / "test-artifacts"


def make_settings(tmp_path: Path, **overrides):
    from app.settings import Settings

    base = dict(data_dir=tmp_path, db_url=f"sqlite:///{tmp_path / 'navdeck.db'}", viewer=False)
    base.update(overrides)
    return Settings(**base)


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
