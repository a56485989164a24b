"""The websocket protocol's JSON Schemas (served at /api/schemas/ws/...) hold for real traffic: every
telemetry frame of an idle and a navigating robot, every teleop message either way (issue 22)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import httpx
import jsonschema_rs
import pytest
from conftest import make_settings
from websockets.sync.client import connect

from app.embedded import EmbeddedServer, serve_in_thread

START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("wsschema"))) as srv:
        yield srv


@pytest.fixture(scope="module")
def api(server: EmbeddedServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        yield c


def validator(api: httpx.Client, name: str):
    r = api.get(f"/api/schemas/ws/{name}.json")
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/schema+json")
    return jsonschema_rs.validator_for(r.json())


def errors(v, message: dict) -> list[str]:
    return [f"{e.instance_path}: {e.message}" for e in v.iter_errors(message)]


def ws_url(server: EmbeddedServer, path: str) -> str:
    return server.url.replace("http", "ws", 1) + path


def test_the_schemas_are_listed_next_to_openapi(api: httpx.Client) -> None:
    index = api.get("/api/schemas/ws").json()["schemas"]
    assert set(index) == {"telemetry", "teleop-in", "teleop-out"}
    assert "/api/schemas/ws/{name}.json" in api.get("/openapi.json").json()["paths"]
    assert api.get("/api/schemas/ws/nope.json").status_code == 422  # the name is an enum


def test_telemetry_frames_match_the_schema_idle_and_navigating(
    server: EmbeddedServer, api: httpx.Client
) -> None:
    v = validator(api, "telemetry")
    frames: list[dict] = []
    with connect(ws_url(server, "/ws/telemetry?hz=10"), open_timeout=30) as ws:
        for _ in range(5):
            frames.append(json.loads(ws.recv(timeout=30)))
        assert api.post("/api/localization/initial_pose", json=START).status_code == 200
        r = api.post("/api/missions", json={"goals": [{"x": 3.0, "y": 1.2, "theta": 0.0}]})
        assert r.status_code == 201, r.text
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            frames.append(json.loads(ws.recv(timeout=30)))
            nav = frames[-1].get("navigation") or {}
            if nav.get("state") == "following" and len(frames) > 12:
                break
        api.post(f"/api/missions/{r.json()['id']}/cancel")
        for _ in range(5):
            frames.append(json.loads(ws.recv(timeout=30)))
    assert any((f.get("navigation") or {}).get("state") == "following" for f in frames)
    assert all(f["scan"] is not None for f in frames[-3:]) and frames[-1]["localization"]["particles"] > 0
    bad = {i: errors(v, f) for i, f in enumerate(frames) if errors(v, f)}
    assert not bad, bad
    # the schema is strict: a field it does not describe, or a wrong type, is caught
    assert errors(v, {**frames[-1], "undocumented": 1})
    assert errors(v, {**frames[-1], "mode": "flying"})
    assert frames[-1]["time"].endswith("Z")


def test_teleop_messages_match_the_schema_both_ways(server: EmbeddedServer, api: httpx.Client) -> None:
    v_in, v_out = validator(api, "teleop-in"), validator(api, "teleop-out")
    sent = [
        {"type": "take_control"},
        {"linear": {"x": 0.0}, "angular": {"z": 0.0}},
        {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.2}},
        {"type": "release_control"},
    ]
    assert all(not errors(v_in, m) for m in sent)
    assert errors(v_in, {"linear": {"x": "fast"}}) and errors(v_in, {"type": "dance"})
    got: list[dict] = []
    with connect(ws_url(server, "/ws/teleop?name=schema-test"), open_timeout=30) as ws:
        for m in [*sent, {"linear": {"x": "fast"}}, {"bogus": 1}]:
            ws.send(json.dumps(m))
        ws.send(json.dumps({"type": "release_control"}))  # the last answer: everything before is in
        while len([m for m in got if m["type"] == "control"]) < 3:
            got.append(json.loads(ws.recv(timeout=30)))
    kinds = [m["type"] for m in got]
    assert kinds[0] == "hello" and kinds.count("error") >= 2 and kinds.count("control") == 3, got
    bad = {i: errors(v_out, m) for i, m in enumerate(got) if errors(v_out, m)}
    assert not bad, bad
