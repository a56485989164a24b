"""A mapping session end to end through the real API of a live server (simulated robot, wall clock):
start, drive with the teleop websocket, stop, save, list, download as map_server files."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from conftest import make_settings
from websockets.sync.client import connect

from app.embedded import EmbeddedServer, serve_in_thread
from maps.mapio import encode_pgm, load_map_yaml


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("mapapi"))) as srv:
        yield srv


@pytest.fixture(scope="module")
def api(server: EmbeddedServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        yield c


def drive(ws, seconds: float, vx: float, wz: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ws.send(json.dumps({"linear": {"x": vx}, "angular": {"z": wz}}))
        time.sleep(0.1)


def test_save_without_a_map_is_409(api: httpx.Client) -> None:
    r = api.post("/api/mapping/save", json={"name": "nothing"})
    assert r.status_code == 409 and "no map" in r.json()["detail"]
    assert api.post("/api/mapping/save", json={"name": ""}).status_code == 422


def test_mapping_session_end_to_end(api: httpx.Client, server: EmbeddedServer, tmp_path: Path) -> None:
    rt = server.runtime
    r = api.post("/api/mapping/start")  # this REST client takes the control lease
    assert r.status_code == 200, r.text
    assert r.json()["running"]
    assert rt.session.modes.mode.value == "mapping"
    with (
        connect(f"{server.ws_url}/ws/teleop") as ws,
        connect(f"{server.ws_url}/ws/telemetry?hz=5") as tel,
    ):
        json.loads(ws.recv())  # hello
        ws.send(json.dumps({"type": "take_control"}))  # the operator's browser takes over
        assert json.loads(ws.recv())["driving"]
        drive(ws, 1.6, 0.0, 1.0)  # turn left to face +y (free space above the start)
        drive(ws, 2.5, 0.2, 0.0)
        drive(ws, 0.5, 0.0, 0.0)
        frames = [json.loads(tel.recv()) for _ in range(5)]
    assert any("mapping" in f for f in frames)
    state = api.get("/api/mapping").json()
    assert state["running"] and state["nodes"] >= 3 and state["front_end_ms"] is not None
    # the pose follows SLAM in the new map frame (started at the robot's pose)
    truth = rt.session.driver.truth_pose
    assert truth.distance_to(rt.features["mapping"].started_pose) > 0.3  # it really drove
    expected = truth.relative_to(rt.features["mapping"].started_pose)  # the new map frame
    assert rt.session.pose.distance_to(expected) < 0.1

    r = api.post("/api/mapping/stop")
    assert r.status_code == 200 and not r.json()["running"]
    assert rt.session.modes.mode.value == "idle"
    loc = rt.features["localization"]
    deadline = time.monotonic() + 10
    # hand_off sets the map, then the initial pose: wait for both (the test thread can run between)
    while time.monotonic() < deadline and not (
        loc.grid is rt.features["mapping"].current_map() and loc.localized
    ):
        time.sleep(0.05)
    # the new map is handed to localization, the robot localized where SLAM left it
    assert loc.grid is rt.features["mapping"].current_map() and loc.localized
    r = api.post("/api/mapping/save", json={"name": "living room"})
    assert r.status_code == 201, r.text
    saved = r.json()
    map_id = saved["id"]
    assert saved["source"] == "slam" and saved["name"] == "living room"
    assert saved["run_id"] is not None  # the recorder's mapping run
    listed = {m["id"]: m for m in api.get("/api/maps", params={"limit": 500}).json()["items"]}
    assert map_id in listed and listed[map_id]["thumbnail_url"] == f"/api/maps/{map_id}/thumbnail.png"
    thumb = api.get(listed[map_id]["thumbnail_url"])
    assert thumb.status_code == 200 and thumb.content.startswith(b"\x89PNG")

    (tmp_path / "map.yaml").write_bytes(api.get(f"/api/maps/{map_id}/map.yaml").content)
    (tmp_path / "map.pgm").write_bytes(api.get(f"/api/maps/{map_id}/map.pgm").content)
    loaded = load_map_yaml(tmp_path / "map.yaml")
    stored = rt.maps.grid(map_id)
    assert loaded.geometry == stored.geometry
    # map_saver writes trinary: what comes back is the stored map thresholded at 0.25 / 0.65
    assert encode_pgm(loaded) == encode_pgm(stored) == (tmp_path / "map.pgm").read_bytes()
    assert (loaded.data == 100).sum() > 50 and (loaded.data == 0).sum() > 500
    assert np.array_equal(loaded.data == 100, stored.data >= 65)

    pose = rt.session.pose
    r = api.post(f"/api/maps/{map_id}/activate")
    assert r.status_code == 200 and rt.session.grid.data.shape == stored.data.shape
    assert loc.map_id == map_id and loc.localized  # same map frame: the pose holds
    time.sleep(0.5)
    assert rt.session.pose.distance_to(pose) < 0.1
