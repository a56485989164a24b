"""``localized`` is decided by the scan's fit at the estimate (issue 22, docs/localization.md): a wrong
initial pose is refused with its fit named, the true one is accepted at once (no motion), and a crowd
hiding the walls for a few updates does not revoke it (hysteresis); a lasting bad fit does."""

from __future__ import annotations

import math

from conftest import make_settings

from app.features import localization as localization_feature
from app.runtime import Runtime
from nav.types import Pose2D, Twist2D
from robot.clock import VirtualClock

START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the stock apartment's navdeck_start


def test_a_wrong_initial_pose_is_not_localized_and_goals_are_refused_naming_the_fit(client) -> None:
    # a free place of the same apartment 4.5 m from the robot, facing another way
    r = client.post("/api/localization/initial_pose", json={"x": 7.5, "y": 2.5, "theta": math.pi / 2})
    assert r.status_code == 200, r.text
    loc = r.json()
    assert loc["updates"] >= 1 and not loc["localized"], loc
    assert loc["fit"] < loc["criterion"]["localized_fit_on"]
    r = client.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": 0.0})
    assert r.status_code == 409, r.text
    detail = r.json()["detail"]
    assert "not localized" in detail and f"fit {loc['fit']:.2f}" in detail, detail


def test_the_true_initial_pose_is_localized_at_once(client) -> None:
    before = client.get("/api/localization").json()
    assert not before["localized"]
    r = client.post("/api/localization/initial_pose", json=START)
    loc = r.json()
    assert r.status_code == 200 and loc["localized"], loc
    assert loc["updates"] == before["updates"] + 1  # the first update, the robot never moved
    assert loc["fit"] >= loc["criterion"]["localized_fit_on"]
    r = client.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": 0.0})
    assert r.status_code in (200, 201, 202), r.text


def _turn_one_update(rt: Runtime, loc: localization_feature.Localization) -> float:
    """Turn in place until the filter updates once; the fit at that update."""
    s = rt.session
    n = loc.updates
    for _ in range(200):
        s.set_teleop(Twist2D(0.0, 0.0, 0.8), "test")
        s.run_for(s.period)
        if loc.updates > n:
            return loc.fit
    raise AssertionError("the filter never updated while turning")


def _ring(rt: Runtime, centre: Pose2D, n: int = 12, radius: float = 0.9) -> list[int]:
    """Standing people all round the robot, hiding over half the walls from the lidar."""
    people = rt.session.driver.world.people
    angles = [2.0 * math.pi * k / n for k in range(n)]
    return [people.add(centre.x + radius * math.cos(a), centre.y + radius * math.sin(a)) for a in angles]


def test_a_crowd_for_a_few_updates_does_not_revoke_localized_a_lasting_bad_fit_does(tmp_path) -> None:
    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    try:
        loc = localization_feature.setup(rt)
        o, s = loc.options, rt.session
        s.run_for(0.5)
        loc.set_initial_pose(Pose2D(START["x"], START["y"], START["theta"]))
        while loc.updates == 0:
            s.run_for(s.period)
        assert loc.localized and loc.fit >= o.localized_fit_on
        s.request_mode("teleop")
        crowd = _ring(rt, s.driver.truth_pose)
        fits = [_turn_one_update(rt, loc) for _ in range(o.unlocalized_updates - 1)]
        assert max(fits) < o.localized_fit_off, fits  # the walls were hidden at every update...
        assert loc.localized  # ...not for long enough to revoke
        for pid in crowd:
            s.driver.world.people.remove(pid)
        assert _turn_one_update(rt, loc) >= o.localized_fit_on and loc.localized
        _ring(rt, s.driver.truth_pose)
        fits = [_turn_one_update(rt, loc) for _ in range(o.unlocalized_updates)]
        assert max(fits) < o.localized_fit_off, fits
        assert not loc.localized
        assert (
            "not localized" in loc.not_localized_reason and f"fit {loc.fit:.2f}" in loc.not_localized_reason
        )
        lost = [e for e in s.events if e.get("status") == "lost"]
        assert lost and "fit" in lost[-1]["reason"], list(s.events)[-5:]
    finally:
        rt.close()
