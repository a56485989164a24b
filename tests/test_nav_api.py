"""Localization and navigation through the REST API of a real server (simulated robot, wall clock),
and the 3D view's pose clicks through ``Runtime.on_pose_input`` (virtual clock)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from conftest import make_settings

from app.embedded import EmbeddedServer, serve_in_thread
from app.modes import Mode
from nav.types import Pose2D

START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    tmp = tmp_path_factory.mktemp("navapi")
    with serve_in_thread(make_settings(tmp)) as srv:
        yield srv


@pytest.fixture(scope="module")
def api(server: EmbeddedServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=10.0) as c:
        yield c


def wait_for(api: httpx.Client, pred, timeout: float) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = api.get("/api/navigation").json()
        if pred(state):
            return state
        time.sleep(0.1)
    raise AssertionError(f"timed out; last navigation state {state}")


def test_navigation_without_localization_is_409(api: httpx.Client) -> None:
    r = api.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": 0.0})
    assert r.status_code == 409
    assert "not localized" in r.json()["detail"]
    assert api.get("/api/localization").json()["localized"] is False


def test_bad_input_is_422(api: httpx.Client) -> None:
    nan = '{"x": NaN, "y": 1.0, "theta": 0.0}'
    for path in ("/api/localization/initial_pose", "/api/navigation/goals"):
        r = api.post(path, content=nan, headers={"content-type": "application/json"})
        assert r.status_code == 422, path
        r = api.post(path, content='{"x": 1e999, "y": 1.0}', headers={"content-type": "application/json"})
        assert r.status_code == 422, path
    r = api.post("/api/localization/initial_pose", json={"x": -5.0, "y": 1.0, "theta": 0.0})
    assert r.status_code == 422 and "off the map" in r.json()["detail"]
    r = api.post("/api/localization/initial_pose", json={"x": 0.02, "y": 0.02, "theta": 0.0})
    assert r.status_code == 422 and "inside a wall" in r.json()["detail"]
    r = api.post("/api/navigation/goals", json=[])
    assert r.status_code == 422


def test_click_to_goal_end_to_end(server: EmbeddedServer, api: httpx.Client) -> None:
    r = api.post("/api/localization/initial_pose", json=START)
    assert r.status_code == 200 and r.json()["localized"] is True
    # goals in a wall / off the map: 422 with the reason and a free pose to use instead
    r = api.post("/api/navigation/goals", json={"x": 0.02, "y": 0.02, "theta": 0.0})
    assert r.status_code == 422
    body = r.json()
    assert body["reason"] == "inside an obstacle" and body["nearest_free"] is not None
    r = api.post("/api/navigation/goals", json={"x": 50.0, "y": 3.0, "theta": 0.0})
    assert r.status_code == 422 and r.json()["reason"] == "off the map"
    assert r.json()["nearest_free"]["x"] < 10.0

    goal = {"x": 3.0, "y": 1.2, "theta": -math.pi / 2}
    r = api.post("/api/navigation/goals", json=goal)
    assert r.status_code == 200, r.text
    state = wait_for(api, lambda s: s["state"] == "following", 10.0)
    assert state["goal"]["y"] == pytest.approx(1.2) and len(state["path"]) > 2
    assert api.get("/api/robot").json()["mode"] == "navigating"
    # what "reached" will mean (the goal checker's tolerances) and how far the robot is now
    assert state["xy_goal_tolerance"] == 0.25 and state["yaw_goal_tolerance"] == 0.25
    assert state["distance_to_goal"] > 0.25 and state["eta_s"] is not None
    state = wait_for(api, lambda s: s["outcome"] is not None, 60.0)
    assert state["outcome"]["kind"] == "succeeded", state  # the API's word (missions' vocabulary)
    out = state["outcome"]  # the final distance and heading error, and the tolerances they met
    assert out["xy_goal_tolerance"] == 0.25 and out["yaw_goal_tolerance"] == 0.25
    assert 0.0 <= out["distance_to_goal"] <= 0.25 and abs(out["yaw_to_goal"]) <= 0.25
    truth = server.runtime.session.driver.truth_pose
    assert truth.distance_to(Pose2D(goal["x"], goal["y"])) < 0.35
    assert api.get("/api/robot").json()["mode"] == "idle"
    events = [e for e in server.runtime.session.events if e["type"] == "navigation" and "outcome" in e]
    assert events[-1]["outcome"] == "reached"
    loc = api.get("/api/localization").json()
    assert loc["particles"] > 0 and 0.0 < loc["quality"] <= 1.0 and len(loc["covariance"]) == 3


def test_cancel_through_api(server: EmbeddedServer, api: httpx.Client) -> None:
    api.post("/api/localization/initial_pose", json=_truth(server))
    r = api.post("/api/navigation/goals", json=[{"x": 7.0, "y": 4.0, "theta": 0.0}, {"x": 3.0, "y": 1.2}])
    assert r.status_code == 200, r.text
    wait_for(api, lambda s: s["state"] == "following", 10.0)
    assert len(api.get("/api/navigation").json()["goals"]) == 2
    r = api.post("/api/navigation/cancel")
    assert r.status_code == 200 and r.json()["canceled"] is True
    state = wait_for(api, lambda s: s["outcome"] is not None and not s["active"], 5.0)
    assert state["outcome"]["kind"] == "canceled"
    assert api.get("/api/robot").json()["mode"] == "idle"


def test_estop_is_409(server: EmbeddedServer, api: httpx.Client) -> None:
    api.post("/api/robot/estop")
    try:
        r = api.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": 0.0})
        assert r.status_code == 409 and "estop" in r.json()["detail"]
        assert api.post("/api/localization/global").status_code == 409
    finally:
        api.post("/api/robot/reset")


def _truth(server: EmbeddedServer) -> dict:
    p = server.runtime.session.driver.truth_pose
    return {"x": p.x, "y": p.y, "theta": p.theta}


def test_viewer_clicks_set_initial_pose_and_queue_goals(tmp_path: Path) -> None:
    from app.features import localization, navigation
    from app.runtime import Runtime
    from robot.clock import VirtualClock

    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    try:
        rt.setup_features((localization, navigation))
        rt.on_pose_input("goal", Pose2D(3.0, 1.2, 0.0))
        assert any(e["type"] == "refused" and "not localized" in e["reason"] for e in rt.session.events)
        rt.on_pose_input("initial_pose", Pose2D(3.0, 3.5, 0.0))
        assert rt.features["localization"].localized
        rt.on_pose_input("goal", Pose2D(3.0, 1.2, 0.0))
        rt.on_pose_input("goal", Pose2D(6.5, 2.5, 0.0))  # a second click queues a waypoint
        assert rt.session.modes.mode == Mode.NAVIGATING
        rt.session.run_for(0.2)
        nav = rt.features["navigation"]
        assert [g["x"] for g in nav.state()["goals"]] == [3.0, 6.5]
        rt.on_pose_input("goal", Pose2D(0.02, 0.02, 0.0))  # in a wall: refused, shown as an event
        assert "inside an obstacle" in rt.session.events[-1]["reason"]
    finally:
        rt.close()


def test_costmap_view_toggle(server: EmbeddedServer, api: httpx.Client) -> None:
    assert api.post("/api/navigation/costmap_view", json={"view": "sideways"}).status_code == 422
    r = api.post("/api/navigation/costmap_view", json={"view": "local"})
    assert r.status_code == 200 and r.json()["costmap_view"] == "local"
    assert _published_costmap_shape(server, (60, 60))  # 3 x 3 m at 5 cm
    api.post("/api/navigation/costmap_view", json={"view": "global"})
    assert _published_costmap_shape(server, (160, 200))


def _published_costmap_shape(server: EmbeddedServer, shape: tuple[int, int], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.runtime.session.bus.latest.extras["costmap"].costs.shape == shape:
            return True
        time.sleep(0.05)
    return False
