"""TEB behind the navigator: chosen by the profile or per goal (API), run at its own
``controller_frequency``, and ``navdeck sim-nav --controller teb --people N``."""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT, make_settings

from nav.control import DwaController, GoalChecker, ProgressChecker
from nav.control.teb import TebController
from nav.navigator import Navigator, make_controller
from nav.types import Costmap, GridGeometry, Pose2D, Twist2D
from nav.types import Path as NavPath
from robot.profiles import load_profile


class _Planner:
    def plan(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> NavPath:
        import numpy as np

        n = 20
        return NavPath(
            np.column_stack(
                (np.linspace(start.x, goal.x, n), np.linspace(start.y, goal.y, n), np.full(n, goal.theta))
            )
        )


def _empty_costmap() -> Costmap:
    import numpy as np

    return Costmap(GridGeometry(0.05, 100, 100, Pose2D(-2.5, -2.5, 0.0)), np.zeros((100, 100), np.uint8))


def test_profile_names_the_controller() -> None:
    skid = load_profile("skid4")
    assert isinstance(Navigator.for_robot(skid, _Planner()).controller, DwaController)
    nav = Navigator.for_robot(replace(skid, controller="teb"), _Planner())
    assert isinstance(nav.controller, TebController) and nav.controller_name == "teb"
    assert set(nav.controllers) == {"dwa", "teb"}  # both built: a goal may switch
    # the profile's choice is overridden by an explicit one
    assert (
        Navigator.for_robot(replace(skid, controller="teb"), _Planner(), controller="dwa").controller_name
        == "dwa"
    )


@pytest.mark.parametrize("bad", ["mpc", "", "TEB"])
def test_unknown_controller_refused_naming_the_field(bad: str) -> None:
    skid = load_profile("skid4")
    with pytest.raises(ValueError, match="profile field controller must be one of dwa, teb"):
        Navigator.for_robot(replace(skid, controller=bad), _Planner())
    with pytest.raises(ValueError, match="controller must be one of dwa, teb"):
        make_controller(bad, skid)


def test_unknown_profile_controller_refused_at_start_up(tmp_path: Path) -> None:
    from app.features import localization, navigation
    from app.runtime import Runtime
    from robot.clock import VirtualClock

    text = (
        (ROOT / "robot/profiles/skid4.toml").read_text().replace('controller = "dwa"', 'controller = "mpc"')
    )
    prof = tmp_path / "bad.toml"
    prof.write_text(text)
    rt = Runtime.build(make_settings(tmp_path, profile=str(prof)), clock=VirtualClock())
    try:
        rt.features["localization"] = localization.setup(rt)
        with pytest.raises(ValueError, match="profile field controller"):
            navigation.setup(rt)
    finally:
        rt.close()


def test_select_controller_switches_resets_and_hands_over_the_path() -> None:
    nav = Navigator.for_robot(load_profile("skid4"), _Planner())
    cm = _empty_costmap()
    nav.set_goals([Pose2D(1.5, 0.0, 0.0)])
    nav.tick(0.0, Pose2D(), Twist2D(), cm)
    assert nav.path is not None
    nav.select_controller("teb")
    assert nav.controller is nav.controllers["teb"] and nav.controller_name == "teb"
    assert nav.controller.goal is not None  # the current path was handed over
    cmd = nav.tick(0.1, Pose2D(), Twist2D(), cm).cmd
    assert cmd.vx > 0.0
    with pytest.raises(ValueError, match="controller must be one of"):
        nav.select_controller("mpc")


class _Counting:
    """A controller that counts compute calls and runs at ``hz``."""

    def __init__(self, hz: float) -> None:
        from types import SimpleNamespace

        self.options = SimpleNamespace(controller_frequency=hz)
        self.calls = 0

    def set_path(self, path: NavPath) -> None:
        pass

    def reset(self) -> None:
        pass

    def compute(self, pose: Pose2D, velocity: Twist2D, costmap: Costmap):
        self.calls += 1
        return Twist2D(0.1 * self.calls, 0.0, 0.0), None


@pytest.mark.parametrize(("hz", "expected"), [(10.0, 11), (20.0, 21), (5.0, 6)])
def test_controller_runs_at_its_own_frequency(hz: float, expected: int) -> None:
    """In a 20 Hz loop a 10 Hz controller (TEB's default) computes every other tick and its
    command is held in between."""
    ctrl = _Counting(hz)
    nav = Navigator(_Planner(), ctrl, GoalChecker(), ProgressChecker())
    cm = _empty_costmap()
    nav.set_goals([Pose2D(50.0, 0.0, 0.0)])
    cmds = []
    for k in range(21):  # 0 .. 1 s at 20 Hz, both ends included
        cmds.append(nav.tick(0.05 * k, Pose2D(0.01 * k, 0.0, 0.0), Twist2D(), cm).cmd.vx)
    assert ctrl.calls == expected
    assert cmds[-1] == pytest.approx(0.1 * ctrl.calls)  # held commands are the last computed one


def test_teb_navigator_reaches_goal_with_default_options() -> None:
    """TebOptions from the skid4 profile behind the navigator, on an empty costmap, virtual time."""
    from robot.kinematics import integrate_twist

    nav = Navigator.for_robot(load_profile("skid4"), _Planner(), controller="teb")
    cm = _empty_costmap()
    goal = Pose2D(1.2, 0.3, 0.0)
    nav.set_goals([goal])
    pose, vel = Pose2D(), Twist2D()
    for k in range(400):
        tick = nav.tick(0.05 * k, pose, vel, cm)
        if tick.outcome is not None:
            break
        vel = tick.cmd
        pose = integrate_twist(pose, vel, 0.05)
    assert tick.outcome is not None and tick.outcome.kind == "reached", tick.feedback.activity
    assert pose.distance_to(goal) < 0.3


# ------------------------------------------------------------------------------------------- API


@pytest.fixture(scope="module")
def virtual_client(tmp_path_factory: pytest.TempPathFactory):
    """The app on a virtual clock: the loop thread runs the simulator as fast as the CPU allows."""
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.runtime import Runtime
    from robot.clock import VirtualClock

    tmp = tmp_path_factory.mktemp("tebapi")
    runtime = Runtime.build(make_settings(tmp), clock=VirtualClock())
    with TestClient(create_app(runtime)) as c:
        yield c


def _wait(client, pred, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    state: dict = {}
    while time.monotonic() < deadline:
        state = client.get("/api/navigation").json()
        if pred(state):
            return state
        time.sleep(0.05)
    raise AssertionError(f"timed out; last navigation state {state}")


def test_api_controller_field_validated(virtual_client) -> None:
    c = virtual_client
    assert c.get("/api/navigation").json()["controller"] == "dwa"  # skid4's profile
    r = c.post("/api/navigation/goals", json={"x": 3.0, "y": 2.2, "controller": "mpc"})
    assert r.status_code == 422 and "controller" in r.text
    r = c.post(
        "/api/navigation/goals",
        json=[{"x": 3.0, "y": 2.2, "controller": "teb"}, {"x": 3.0, "y": 2.5, "controller": "dwa"}],
    )
    assert r.status_code == 422 and "one controller" in r.json()["detail"]


def test_api_goal_with_teb_is_reached_then_default_returns(virtual_client) -> None:
    c = virtual_client
    r = c.post("/api/localization/initial_pose", json={"x": 3.0, "y": 3.5, "theta": 0.0})
    assert r.status_code == 200, r.text
    r = c.post("/api/navigation/goals", json={"x": 3.0, "y": 2.3, "theta": -math.pi / 2, "controller": "teb"})
    assert r.status_code == 200, r.text
    rt = c.app.state.runtime
    deadline = time.monotonic() + 60.0
    band = None
    while band is None and time.monotonic() < deadline:  # the 3D view gets the band's poses
        snap = rt.session.bus.latest
        band = None if snap is None else snap.extras.get("teb_band")
        time.sleep(0.01)
    assert band is not None and band.ndim == 2 and band.shape[1] == 3 and len(band) >= 3
    state = _wait(c, lambda s: s["outcome"] is not None and not s["active"])
    assert state["outcome"]["kind"] == "succeeded", state
    assert state["controller"] == "teb"
    assert rt.session.collisions == 0
    assert rt.session.driver.truth_pose.distance_to(Pose2D(3.0, 2.3)) < 0.35
    accepted = [
        e for e in rt.session.events if e["type"] == "navigation" and e.get("status") == "goal accepted"
    ]
    assert accepted[-1]["controller"] == "teb"
    # a request that names none drives with the profile's controller again; the goal is queued for the
    # loop's next tick, so wait for this request's own outcome (a new "t"), not the previous one
    first = state["outcome"]
    r = c.post("/api/navigation/goals", json={"x": 3.0, "y": 3.3, "theta": math.pi / 2})
    assert r.status_code == 200, r.text
    state = _wait(c, lambda s: s["outcome"] not in (None, first) and not s["active"])
    assert state["controller"] == "dwa" and state["outcome"]["kind"] == "succeeded", state


# ------------------------------------------------------------------------------------------- CLI


def test_sim_nav_teb_with_people(capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    code = main(
        [
            "sim-nav",
            "--map",
            str(ROOT / "maps/stock/office.yaml"),
            "--start",
            "2,10,0",
            "--goal",
            "3.5,10,0",
            "--controller",
            "teb",
            "--people",
            "2",
            "--timeout",
            "40",
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["controller"] == "teb" and out["reached"] is True and out["collisions"] == 0
    assert out["min_person_clearance_m"] is not None  # the walkers were there
    for key in ("time_s", "path_length_m", "recoveries", "min_clearance_m", "localization_error_m"):
        assert key in out


def test_sim_nav_bad_controller_or_people_refused(capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    base = ["sim-nav", "--map", str(ROOT / "maps/stock/office.yaml"), "--start", "2,10,0", "--goal", "3,10,0"]
    with pytest.raises(SystemExit):
        main([*base, "--controller", "mpc"])
    assert main([*base, "--people", "-1"]) == 2
    assert "--people" in capsys.readouterr().err
