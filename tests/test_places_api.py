"""Places and routes (issue 19): named poses per map through the API, goals by place name (422 for
an unknown name), a route of three places run twice as one mission with an outcome per leg."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import make_settings
from fastapi.testclient import TestClient

from app.api.routes.places import resolve_place
from app.features import localization, missions, navigation, zones
from app.features.missions import GoalState, MissionState
from app.main import create_app
from app.modes import Mode
from app.place_store import PlaceStore
from app.runtime import Runtime
from nav.types import Pose2D
from robot.clock import VirtualClock

# three free spots in the apartment world's living room, around its start (3.0, 3.5)
PLACES = {"sofa": (1.5, 3.5, 3.14), "window": (2.2, 1.8, -1.57), "door": (3.0, 4.3, 1.57)}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    runtime = Runtime.build(make_settings(tmp_path_factory.mktemp("placesapi")))
    with TestClient(create_app(runtime)) as c:
        yield c


def test_places_crud_and_goals_by_name(client) -> None:
    map_id = client.get("/api/localization").json()["map_id"]
    url = f"/api/maps/{map_id}/places"
    ids = []
    for name, (x, y, th) in PLACES.items():
        r = client.post(url, json={"name": name, "x": x, "y": y, "theta": th})
        assert r.status_code == 201, r.text
        assert r.headers["location"] == f"/api/places/{r.json()['id']}"
        ids.append(r.json()["id"])
    assert [p["name"] for p in client.get(url).json()["items"]] == sorted(PLACES)
    r = client.post(url, json={"name": "sofa", "x": 1.0, "y": 1.0})
    assert r.status_code == 409 and r.json()["type"].endswith("/place-exists")
    r = client.post(url, json={"name": "moon", "x": 100.0, "y": 1.0})
    assert r.status_code == 422 and "off the map" in r.json()["detail"]
    assert client.get("/api/maps/99999/places").status_code == 404

    r = client.post("/api/navigation/goals", json={"place": "attic"})
    assert r.status_code == 422
    body = r.json()
    assert body["type"].endswith("/unknown-place") and sorted(body["places"]) == sorted(PLACES)

    assert client.post("/api/localization/initial_pose", json={"x": 3.0, "y": 3.5}).status_code == 200
    r = client.post("/api/navigation/goals", json={"place": "sofa"})
    assert r.status_code == 200, r.text
    assert r.json()["goals"][0] == {"x": 1.5, "y": 3.5, "theta": 3.14}

    r = client.post("/api/routes/run", json={"stops": ["sofa", {"x": 2.0, "y": 2.5}, "door"], "repeat": 2})
    assert r.status_code == 201, r.text
    mission = r.json()
    assert r.headers["location"] == f"/api/missions/{mission['id']}"
    xs = [g["pose"]["x"] for g in mission["goals"]]
    assert xs == [1.5, 2.0, 3.0, 1.5, 2.0, 3.0]
    assert client.post("/api/routes/run", json={"stops": ["sofa", "attic"]}).status_code == 422
    client.post("/api/navigation/cancel")

    assert client.delete(f"/api/places/{ids[0]}").status_code == 204
    assert client.delete(f"/api/places/{ids[0]}").status_code == 404


def test_a_route_of_three_places_run_twice(tmp_path: Path) -> None:
    """Virtual clock: each of the six legs is reached, in order, and recorded as its own outcome."""
    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    try:
        rt.setup_features((localization, navigation, missions, zones))
        rt.on_pose_input("initial_pose", Pose2D(3.0, 3.5, 0.0))
        store = PlaceStore(rt.engine)
        map_id = rt.features["localization"].map_id
        for name, xyt in PLACES.items():
            store.add(map_id, name, Pose2D(*xyt))
        legs = [resolve_place(rt, n) for n in ("sofa", "window", "door")]
        m = rt.features["missions"].create(legs * 2)
        assert rt.session.modes.mode == Mode.NAVIGATING
        for _ in range(240):  # at most 240 s of virtual time
            rt.session.run_for(1.0)
            if m.state in (MissionState.SUCCEEDED, MissionState.FAILED, MissionState.CANCELED):
                break
        assert m.state == MissionState.SUCCEEDED, (m.state, m.goal_states, m.goal_reasons)
        assert m.goal_states == [GoalState.REACHED] * 6
        truth = rt.session.driver.truth_pose
        assert truth.distance_to(legs[-1]) < 0.3
    finally:
        rt.close()
