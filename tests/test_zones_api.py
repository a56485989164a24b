"""Zones through the REST API (issue 19): CRUD, 422 problems for invalid polygons, and the active
map's keepout zones refusing goals."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from conftest import make_settings
from fastapi.testclient import TestClient

from app.main import create_app
from app.runtime import Runtime

SQUARE = [[2.0, 1.0], [4.0, 1.0], [4.0, 2.0], [2.0, 2.0]]


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    runtime = Runtime.build(make_settings(tmp_path_factory.mktemp("zonesapi")))
    with TestClient(create_app(runtime)) as c:
        yield c


@pytest.fixture(scope="module")
def map_id(client) -> int:
    return client.get("/api/localization").json()["map_id"]


def test_zone_crud(client, map_id: int) -> None:
    r = client.post(f"/api/maps/{map_id}/zones", json={"name": "lab", "kind": "keepout", "polygon": SQUARE})
    assert r.status_code == 201, r.text
    zone = r.json()
    assert r.headers["location"] == f"/api/zones/{zone['id']}"
    assert zone["map_id"] == map_id and zone["kind"] == "keepout" and zone["speed_limit"] is None
    assert zone["polygon"] == SQUARE and zone["created_at"].endswith("Z")
    listed = client.get(f"/api/maps/{map_id}/zones").json()
    assert [z["id"] for z in listed["items"]] == [zone["id"]]

    body = {"name": "aisle", "kind": "speed", "polygon": SQUARE, "speed_limit": 30}
    r = client.put(f"/api/zones/{zone['id']}", json=body)
    assert r.status_code == 200
    got = client.get(f"/api/zones/{zone['id']}").json()
    assert got["kind"] == "speed" and got["speed_limit"] == 30 and got["speed_limit_unit"] == "percent"

    assert client.delete(f"/api/zones/{zone['id']}").status_code == 204
    r = client.get(f"/api/zones/{zone['id']}")
    assert r.status_code == 404 and r.headers["content-type"].startswith("application/problem+json")
    assert client.delete(f"/api/zones/{zone['id']}").status_code == 404
    assert client.get("/api/maps/99999/zones").status_code == 404
    r = client.post("/api/maps/99999/zones", json={"name": "x", "kind": "keepout", "polygon": SQUARE})
    assert r.status_code == 404


@pytest.mark.parametrize(
    ("polygon", "reason"),
    [
        ([[2.0, 1.0], [3.0, 1.0]], "at least 3 vertices"),
        ([[2.0, 1.0], [3.0, 2.0], [3.0, 1.0], [2.0, 2.0]], "intersects itself"),
        ([[2.0, 1.0], [300.0, 1.0], [2.0, 2.0]], "off the map"),
    ],
)
def test_invalid_polygons_are_422_problems(client, map_id: int, polygon, reason: str) -> None:
    r = client.post(f"/api/maps/{map_id}/zones", json={"name": "bad", "kind": "keepout", "polygon": polygon})
    assert r.status_code == 422
    body = r.json()
    assert body["type"].endswith("/invalid-polygon") and reason in body["detail"]
    assert client.get(f"/api/maps/{map_id}/zones").json()["items"] == []  # nothing stored


def test_speed_fields_are_checked(client, map_id: int) -> None:
    url = f"/api/maps/{map_id}/zones"
    assert client.post(url, json={"name": "s", "kind": "speed", "polygon": SQUARE}).status_code == 422
    over = {"name": "s", "kind": "speed", "polygon": SQUARE, "speed_limit": 150}
    assert client.post(url, json=over).status_code == 422
    keep = {"name": "k", "kind": "keepout", "polygon": SQUARE, "speed_limit": 0.2}
    assert client.post(url, json=keep).status_code == 422
    mps = {"name": "s", "kind": "speed", "polygon": SQUARE, "speed_limit": 0.2, "speed_limit_unit": "m/s"}
    r = client.post(url, json=mps)
    assert r.status_code == 201 and r.json()["speed_limit_unit"] == "m/s"
    client.delete(f"/api/zones/{r.json()['id']}")


def test_a_goal_inside_a_keepout_zone_of_the_active_map_is_refused(client, map_id: int) -> None:
    start = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose
    assert client.post("/api/localization/initial_pose", json=start).status_code == 200
    goal = {"x": 3.0, "y": 1.2, "theta": 0.0}
    zone = [[2.6, 0.9], [3.4, 0.9], [3.4, 1.5], [2.6, 1.5]]
    r = client.post(
        f"/api/maps/{map_id}/zones", json={"name": "wet floor", "kind": "keepout", "polygon": zone}
    )
    assert r.status_code == 201
    zid = r.json()["id"]
    try:
        r = client.post("/api/navigation/goals", json=goal)
        assert r.status_code == 422 and r.json()["reason"] == "inside a keepout zone"
    finally:
        client.delete(f"/api/zones/{zid}")
        client.post("/api/navigation/cancel")
