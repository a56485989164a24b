"""Routes reach their feature through one typed dependency: a server without the feature answers 503
as a problem, from one place (``FeatureUnavailable``), and the runtime finds features by type."""

from __future__ import annotations

from app.features.exploration import Exploration
from app.features.navigation import Navigation
from app.features.recording import Recording
from app.features.zones import Zones


def test_the_runtime_finds_a_feature_by_its_type(client) -> None:
    rt = client.app.state.runtime
    assert isinstance(rt.feature(Navigation), Navigation)
    assert rt.find_feature(Zones) is rt.features["zones"]


def test_a_missing_feature_is_a_503_problem_naming_it(client) -> None:
    rt = client.app.state.runtime
    removed = {name: rt.features.pop(name) for name in ("exploration", "recording")}
    try:
        assert rt.find_feature(Exploration) is None and rt.find_feature(Recording) is None
        r = client.get("/api/exploration")
        assert r.status_code == 503
        assert r.headers["content-type"].startswith("application/problem+json")
        body = r.json()
        assert body["status"] == 503 and body["type"].endswith("exploration-unavailable")
        assert "exploration is not running" in body["detail"]
        assert client.get("/api/replay").status_code == 503
        assert client.get("/api/runs").status_code == 200  # runs are listed from the database without it
    finally:
        rt.features.update(removed)
    assert client.get("/api/exploration").status_code == 200
