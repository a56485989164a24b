"""Patrol routes (issue 19): a route run in a loop until cancelled, one mission whose legs each keep
their outcome (in the mission and as ``mission_leg`` run events), on the virtual clock."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import make_settings
from fastapi.testclient import TestClient

from app.api.routes.places import RouteIn
from app.features import localization, missions, navigation, zones
from app.features.missions import GoalState, MissionState
from app.main import create_app
from app.modes import Mode
from app.runtime import Runtime
from nav.types import Pose2D
from robot.clock import VirtualClock

# two free spots in the apartment world's living room, around its start (3.0, 3.5)
SOFA = Pose2D(1.5, 3.5, 3.14)
WINDOW = Pose2D(2.2, 1.8, -1.57)


def test_a_patrol_loops_until_cancelled(tmp_path: Path) -> None:
    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    try:
        rt.setup_features((localization, navigation, missions, zones))
        rt.on_pose_input("initial_pose", Pose2D(3.0, 3.5, 0.0))
        ms = rt.features["missions"]
        m = ms.create([SOFA, WINDOW], patrol=True)
        assert len(m.goals) == 4  # two laps queued
        for _ in range(400):  # at most 400 s of virtual time
            rt.session.run_for(1.0)
            if m.reached >= 5 or m.state != MissionState.ACTIVE:
                break
        # past the two laps it started with: the patrol appended laps and never stopped
        assert m.state == MissionState.ACTIVE, (m.state, m.goal_states, m.goal_reasons)
        assert m.reached >= 5 and len(m.goals) >= 6
        assert m.goals[4] == SOFA and m.goals[5] == WINDOW
        assert rt.session.modes.mode == Mode.NAVIGATING
        ms.cancel(m.id, "operator")
        rt.session.run_for(1.0)
        assert m.state == MissionState.CANCELED
        reached = m.reached
        assert m.goal_states[:reached] == [GoalState.REACHED] * reached
        assert m.goal_states[reached] == GoalState.CANCELED and m.goal_reasons[reached] == "operator_cancel"
        legs = [e for e in rt.session.events if e["type"] == "mission_leg" and e["id"] == m.id]
        assert [e["index"] for e in legs] == list(range(len(m.goals)))  # each leg once, in order
        assert [e["lap"] for e in legs[:4]] == [1, 1, 2, 2]
        assert [e["state"] for e in legs[:reached]] == ["reached"] * reached
        n_goals = len(m.goals)
        rt.session.run_for(5.0)
        assert len(m.goals) == n_goals  # nothing appended after the cancel
    finally:
        rt.close()


def test_route_api_patrol_and_repeat_zero(tmp_path: Path) -> None:
    with TestClient(create_app(Runtime.build(make_settings(tmp_path)))) as client:
        assert client.post("/api/localization/initial_pose", json={"x": 3.0, "y": 3.5}).status_code == 200
        stops = [{"x": 1.5, "y": 3.5}, {"x": 2.2, "y": 1.8}]
        for body in ({"stops": stops, "patrol": True}, {"stops": stops, "repeat": 0}):
            r = client.post("/api/routes/run", json=body)
            assert r.status_code == 201, r.text
            assert [g["pose"]["x"] for g in r.json()["goals"]] == [1.5, 2.2, 1.5, 2.2]
        r = client.post("/api/routes/run", json={"stops": stops[:1], "patrol": True})
        assert r.status_code == 422 and "at least two stops" in r.json()["detail"]
        client.post("/api/navigation/cancel")


@pytest.mark.parametrize("repeat", [-1, 101])
def test_route_repeat_out_of_range_is_422(tmp_path: Path, repeat: int) -> None:
    with pytest.raises(ValueError, match="repeat"):
        RouteIn.model_validate({"stops": ["dock"], "repeat": repeat})
