"""Missions as resources (issue 22): REST on a real embedded server (simulated robot, wall clock)
and the missions feature on a virtual clock (run events: why each mission ended, the goal list)."""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import httpx
import pytest
from conftest import make_settings

from app.embedded import EmbeddedServer, serve_in_thread
from app.runs.store import RunFilters
from nav.types import Pose2D

START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose
NEAR = {"x": 3.0, "y": 1.2, "theta": -math.pi / 2}  # reached in ~10 s from START
FAR = [{"x": 7.0, "y": 4.0, "theta": 0.0}, {"x": 3.0, "y": 1.2, "theta": 0.0}]
TERMINAL = {"succeeded", "failed", "canceled"}
PROBLEM = "application/problem+json"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("missions"))) as srv:
        yield srv


@pytest.fixture(scope="module")
def api(server: EmbeddedServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=70.0) as c:
        yield c


@pytest.fixture
def localized(server: EmbeddedServer, api: httpx.Client) -> None:
    """Localized where the robot truly is, no e-stop, no mission running."""
    if api.get("/api/robot").json()["estop"]:
        assert api.post("/api/robot/reset").status_code == 200
    t = server.runtime.session.driver.truth_pose
    r = api.post("/api/localization/initial_pose", json={"x": t.x, "y": t.y, "theta": t.theta})
    assert r.status_code == 200, r.text


def wait_until(api: httpx.Client, mission: dict, pred, rounds: int = 40) -> dict:
    """Long-poll until ``pred(mission)``. An answer with nothing new is allowed only once the 30 s wait
    ran out (a slow drive on a loaded machine), and at least one change must come back before its wait
    ran out: this proves the wait returns on a change rather than on its timeout."""
    polled = woke = False
    for _ in range(rounds):
        if pred(mission):
            assert woke or not polled, "every long-poll answer came at its timeout"
            return mission
        start = time.monotonic()
        r = api.get(f"/api/missions/{mission['id']}", params={"wait": 30, "version": mission["version"]})
        elapsed = time.monotonic() - start
        assert r.status_code == 200, r.text
        new = r.json()
        changed = new["version"] > mission["version"] or new["state"] in TERMINAL
        assert changed or elapsed >= 29.0, (elapsed, mission, new)
        polled, woke = True, woke or (changed and elapsed < 29.0)
        mission = new
    raise AssertionError(f"mission never got there: {mission}")


def create(api: httpx.Client, goals: list[dict]) -> dict:
    r = api.post("/api/missions", json={"goals": goals})
    assert r.status_code == 201, r.text
    return r.json()


def is_utc_z(stamp: str) -> bool:
    return (
        stamp.endswith("Z") and datetime.fromisoformat(stamp.replace("Z", "+00:00")).utcoffset().seconds == 0
    )


def test_create_then_wait_for_completion(server: EmbeddedServer, api: httpx.Client, localized: None) -> None:
    r = api.post("/api/missions", json={"waypoints": [NEAR]})
    assert r.status_code == 201, r.text
    m = r.json()
    assert r.headers["location"] == f"/api/missions/{m['id']}"
    assert m["state"] == "accepted"  # the NEW state, not the previous navigation's
    assert m["progress"] == {
        "goal_index": 0,
        "goal_count": 1,
        "goals_reached": 0,
        "distance_remaining_m": None,
    }
    assert is_utc_z(m["created_at"]) and m["cancel"] is None
    m = wait_until(api, m, lambda m: m["state"] in TERMINAL)
    assert m["state"] == "succeeded", m
    assert m["goals"][0]["state"] == "reached" and m["progress"]["goals_reached"] == 1
    assert is_utc_z(m["started_at"]) and is_utc_z(m["ended_at"]) and m["ended_at"] >= m["started_at"]
    # an ended mission answers a long-poll at once
    assert api.get(f"/api/missions/{m['id']}", params={"wait": 30}).json()["state"] == "succeeded"
    page = api.get("/api/missions", params={"limit": 1}).json()
    assert page["total"] >= 1 and page["limit"] == 1 and page["offset"] == 0
    assert [i["id"] for i in page["items"]] == [m["id"]]  # newest first
    recorded = [e for e in server.runtime.session.events if e["type"] == "mission" and e["id"] == m["id"]]
    assert [e["state"] for e in recorded][-1] == "succeeded"


def test_cancel_has_reason_and_actor_and_a_lease_lapse_cancels_nothing(
    server: EmbeddedServer, api: httpx.Client, localized: None
) -> None:
    m = create(api, FAR)
    m = wait_until(api, m, lambda m: m["state"] == "active")
    # the client goes quiet: its lease lapses (the guard's idle sweep, far in the future)
    guard = server.app.state.guard
    guard.sweep(now=1e12)
    assert server.runtime.lease.holder is None
    assert api.get(f"/api/missions/{m['id']}").json()["state"] == "active"  # the mission drives on
    r = api.post(f"/api/missions/{m['id']}/cancel")
    assert r.status_code == 200, r.text
    assert r.json()["state"] == "canceling"
    m = wait_until(api, r.json(), lambda m: m["state"] in TERMINAL)
    assert m["state"] == "canceled"
    assert m["cancel"]["reason"] == "operator_cancel" and m["cancel"]["actor"] == m["created_by"]
    assert [g["state"] for g in m["goals"]] == ["canceled", "canceled"]
    assert [g["reason"] for g in m["goals"]] == ["operator_cancel", "not_attempted"]
    r = api.post(f"/api/missions/{m['id']}/cancel")  # nothing left to cancel
    assert r.status_code == 409 and r.headers["content-type"].startswith(PROBLEM)
    assert r.json()["type"].endswith("/mission-ended") and r.json()["state"] == "canceled"


def test_estop_cancels_with_its_own_reason(
    server: EmbeddedServer, api: httpx.Client, localized: None
) -> None:
    m = create(api, FAR)
    m = wait_until(api, m, lambda m: m["state"] == "active")
    assert api.post("/api/robot/estop").status_code == 200
    m = wait_until(api, m, lambda m: m["state"] in TERMINAL)
    assert m["state"] == "canceled"
    assert m["cancel"]["reason"] == "estop" and m["cancel"]["actor"] == "api", m["cancel"]
    r = api.post("/api/missions", json={"goals": [NEAR]})  # refused while the e-stop is latched
    assert r.status_code == 409 and r.headers["content-type"].startswith(PROBLEM)
    assert r.json()["status"] == 409 and "estop" in r.json()["detail"]
    assert api.post("/api/robot/reset").status_code == 200


def test_new_mission_supersedes_the_running_one(
    server: EmbeddedServer, api: httpx.Client, localized: None
) -> None:
    first = wait_until(api, create(api, FAR), lambda m: m["state"] == "active")
    second = create(api, [NEAR])
    first = wait_until(api, first, lambda m: m["state"] in TERMINAL)
    assert first["state"] == "canceled"
    assert first["cancel"]["reason"] == "superseded" and first["cancel"]["actor"] == second["created_by"]
    assert second["id"] in first["cancel"]["message"] or first["cancel"]["message"]
    second = wait_until(api, second, lambda m: m["state"] != "accepted")
    assert second["state"] in ("active", "succeeded")
    api.post(f"/api/missions/{second['id']}/cancel")
    wait_until(api, second, lambda m: m["state"] in TERMINAL)


def test_unknown_mission_is_a_404_problem(api: httpx.Client) -> None:
    for r in (api.get("/api/missions/nope"), api.post("/api/missions/nope/cancel")):
        assert r.status_code == 404 and r.headers["content-type"].startswith(PROBLEM)
        body = r.json()
        assert body["status"] == 404 and body["type"].endswith("/not-found") and body["title"]
        assert "nope" in body["detail"] and body["instance"].startswith("/api/missions/nope")


def test_goal_in_a_wall_is_a_422_problem_with_nearest_free(api: httpx.Client, localized: None) -> None:
    r = api.post("/api/missions", json={"goals": [NEAR, {"x": 0.02, "y": 0.02, "theta": 0.0}]})
    assert r.status_code == 422 and r.headers["content-type"].startswith(PROBLEM)
    body = r.json()
    assert body["type"].endswith("/goal-rejected") and body["status"] == 422
    assert body["reason"] == "inside an obstacle" and body["index"] == 1
    assert body["nearest_free"] is not None and set(body["nearest_free"]) == {"x", "y", "theta"}
    # the same shape from the goal endpoint, and nothing was started
    r = api.post("/api/navigation/goals", json={"x": 0.02, "y": 0.02, "theta": 0.0})
    assert r.status_code == 422 and r.json()["nearest_free"] is not None and r.json()["title"]
    assert api.post("/api/missions", json={"goals": []}).status_code == 422


def test_goal_endpoints_are_thin_wrappers_answering_the_new_state(
    server: EmbeddedServer, api: httpx.Client, localized: None
) -> None:
    before = api.get("/api/navigation").json()
    r = api.post("/api/navigation/goals", json=FAR)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["state"] == "planning" and body["active"] is True and body["outcome"] is None, (before, body)
    assert [g["x"] for g in body["goals"]] == [7.0, 3.0]
    m = api.get(f"/api/missions/{body['mission_id']}").json()
    assert m["state"] in ("accepted", "active") and len(m["goals"]) == 2
    m = wait_until(api, m, lambda m: m["state"] == "active")
    r = api.post("/api/navigation/cancel")
    assert r.status_code == 200
    assert r.json()["canceled"] is True and r.json()["mission_id"] == m["id"]
    assert r.json()["state"] == "canceled" and r.json()["active"] is False
    m = wait_until(api, m, lambda m: m["state"] in TERMINAL)
    assert m["state"] == "canceled" and m["cancel"]["reason"] == "operator_cancel"


# ------------------------------------------------------------------ the feature on a virtual clock


@pytest.fixture
def rt(tmp_path: Path):
    from app.features import localization, missions, navigation, recording
    from app.runtime import Runtime
    from robot.clock import VirtualClock

    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    try:
        # what Runtime.start does, without the wall-clock thread
        rt.setup_features((localization, navigation, missions, recording))
        rt.on_pose_input("initial_pose", Pose2D(3.0, 3.5, 0.0))
        yield rt
    finally:
        rt.close()


def _goal_list(events: list[dict]) -> tuple[int, Counter]:
    """What the run's goal list is made of: goals set, and outcome events per type."""
    goals = sum(e["type"] == "goal" for e in events)
    outcomes = Counter(
        e["type"] for e in events if e["type"] in ("goal_reached", "goal_failed", "goal_canceled")
    )
    return goals, outcomes


def test_each_cause_of_an_end_is_told_apart(rt) -> None:
    from app.features.missions import MissionState

    ms, s = rt.features["missions"], rt.session
    a = ms.create([Pose2D(7.0, 4.0, 0.0)], actor="alice")
    s.run_for(1.0)
    b = ms.create([Pose2D(7.0, 4.0, 0.0)], actor="bob")  # supersedes a
    s.run_for(1.0)
    ms.cancel(b.id, "carol")
    s.run_for(0.5)
    c = ms.create([Pose2D(7.0, 4.0, 0.0)], actor="dave")
    s.run_for(1.0)
    s.estop("panel")
    s.run_for(0.5)
    s.reset()
    d = ms.create([Pose2D(7.0, 4.0, 0.0)], actor="erin")
    s.run_for(1.0)
    s.request_mode("idle")  # the operator takes the robot for something else
    s.run_for(0.5)
    assert all(m.state == MissionState.CANCELED for m in (a, b, c, d))
    causes = [(m.cancel["reason"], m.cancel["actor"]) for m in (a, b, c, d)]
    assert causes == [
        ("superseded", "bob"),
        ("operator_cancel", "carol"),
        ("estop", "panel"),
        ("mode_change", "operator"),
    ]
    ended = [e for e in s.events if e["type"] == "navigation" and e.get("outcome") == "cancelled"]
    assert [(e["reason"], e["actor"]) for e in ended] == causes


def test_fault_cancels_with_reason_fault(rt) -> None:
    from app.modes import Mode

    ms, s = rt.features["missions"], rt.session
    m = ms.create([Pose2D(7.0, 4.0, 0.0)], actor="alice")
    s.run_for(1.0)
    s.modes.enter(Mode.FAULT, "motor driver over temperature")
    s.run_for(0.5)
    assert m.cancel is not None and m.cancel["reason"] == "fault" and m.cancel["actor"] == "robot"


def test_run_goal_list_has_every_waypoint_once(rt) -> None:
    ms, s = rt.features["missions"], rt.session
    start = len(s.events)
    # three waypoints, superseded while driving to the first: three goals set, three ends
    ms.create([Pose2D(7.0, 4.0, 0.0), Pose2D(3.0, 1.2, 0.0), Pose2D(6.5, 2.5, 0.0)], actor="a")
    s.run_for(1.0)
    # a click in the 3D view, then a second one: one mission extended, the first goal not set twice
    ms.create([Pose2D(3.0, 1.2, -math.pi / 2)], actor="a")
    s.run_for(0.2)
    rt.on_pose_input("goal", Pose2D(3.0, 2.0, 0.0))
    s.run_for(0.2)
    goals, outcomes = _goal_list(list(s.events)[start:])
    assert goals == 5 and outcomes == Counter(goal_canceled=3), (goals, outcomes)
    last = ms.page(1, 0)[1][0]
    assert len(last.goals) == 2
    s.run_for(60.0)
    goals, outcomes = _goal_list(list(s.events)[start:])
    assert goals == 5 and sum(outcomes.values()) == 5, (goals, outcomes)
    assert last.state.value == "succeeded" and outcomes["goal_reached"] == 2
    # the recorder's goal list of the run: every goal once, each with its own outcome
    rec = rt.features["recording"]
    rec.recorder.sync()
    _, runs = rec.store.list(RunFilters())
    stored = [(g["x"], g["y"], g["outcome"]) for run in runs for g in rec.store.goals(run["id"])]
    assert stored == [
        (7.0, 4.0, "canceled"),
        (3.0, 1.2, "canceled"),
        (6.5, 2.5, "canceled"),
        (3.0, 1.2, "succeeded"),
        (3.0, 2.0, "succeeded"),
    ], stored
