"""Localization you can trust (issue 22): in simulation a map of another world is refused on
activation (the lidar's scan does not fit it), the world's own map is accepted; an initial pose is
answered with the estimate it led to, never the old one."""

from __future__ import annotations

import math

import pytest


def stock(client) -> dict[str, dict]:
    return {
        m["name"]: m for m in client.get("/api/maps", params={"limit": 500}).json()["items"] if m["is_stock"]
    }


@pytest.mark.parametrize("other", ["office", "greenhouse"])
def test_a_map_of_another_world_is_refused_with_its_score(client, other: str) -> None:
    maps = stock(client)  # the client's robot is in the apartment
    r = client.post(f"/api/maps/{maps[other]['id']}/activate")
    assert r.status_code == 409, r.text
    body = r.json()
    assert body["type"].endswith("/map-mismatch") and body["world"] == "apartment"
    assert body["match_score"] < 0.8 * body["world_match_score"]
    assert "apartment" in body["detail"] and "activate this world's map" in body["detail"]
    assert client.get("/api/maps").json()["active_map_id"] == maps["apartment"]["id"]  # unchanged
    r = client.post(f"/api/maps/{maps['apartment']['id']}/activate")
    assert r.status_code == 200 and r.json()["match_score"] > 0.9, r.text


def test_initial_pose_answers_the_new_estimate(client) -> None:
    before = client.get("/api/localization").json()
    r = client.post("/api/localization/initial_pose", json={"x": 3.0, "y": 3.5, "theta": 0.0})
    assert r.status_code == 200, r.text
    loc = r.json()
    # the answer comes after the filter weighed a scan at the new pose: not particles 0 / quality 0
    assert loc["updates"] > before["updates"] and loc["particles"] > 0 and loc["quality"] > 0.5
    assert math.hypot(loc["pose"]["x"] - 3.0, loc["pose"]["y"] - 3.5) < 0.3
    assert loc["localized"] and loc["converged"] and not loc["map_mismatch"]
    assert loc["criterion"]["matched_std_xy"] == 0.3 and loc["fit"] >= loc["criterion"]["localized_fit_on"]
