"""Issue 5's scenario suite in its quick variant (one trial), and its configuration: the full
50-trial sets per controller are benchmarks (``navdeck bench scenarios.dwa`` / ``scenarios.teb``)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.scenarios import issue5
from bench.scenarios.suite import GREENHOUSE_AISLES, person_trials


def test_person_stepping_in_quick_variant() -> None:
    res = person_trials(1, seed=3, controller="dwa")
    assert res.n == 1 and res.name == "person steps in (dwa)"
    r = res.trials[0].result
    assert r.reached and r.collisions == 0, res.failures()
    assert r.controller == "dwa"
    # the person did step in front of the robot (it starts >= 0.8 m to the side of the line)
    assert r.min_person_clearance_m is not None and 0.0 < r.min_person_clearance_m < 0.5


def test_every_set_registered_per_controller() -> None:
    names = {b.name for b in issue5.BENCHMARKS}
    for c in ("dwa", "teb"):
        for key in ("straight", "turns", "obstacle", "person", "greenhouse"):
            assert f"scenarios.{c}.{key}" in names
    assert all(b.group == "slow" for b in issue5.BENCHMARKS)


def test_trial_count_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NAVDECK_SCENARIO_TRIALS", raising=False)
    assert issue5.trial_count() == 50
    monkeypatch.setenv("NAVDECK_SCENARIO_TRIALS", "3")
    assert issue5.trial_count() == 3
    for bad in ("0", "many"):
        monkeypatch.setenv("NAVDECK_SCENARIO_TRIALS", bad)
        with pytest.raises(ValueError, match="NAVDECK_SCENARIO_TRIALS"):
            issue5.trial_count()


def test_greenhouse_trial_world_has_mounds_the_map_lacks() -> None:
    """The row run's obstacles are in the simulated world only, and each aisle keeps a way past
    them wide enough for the omni robot (0.5 m)."""
    from maps.stock import stock_world_path
    from robot.sim import World
    from robot.sim.scenario import load_scenario, sidecar_path

    path = stock_world_path("greenhouse")
    world = World.from_yaml(path)
    obstacles = load_scenario(sidecar_path(path)).obstacles
    assert {o.kind for o in obstacles} == {"mound", "puddle"}
    for o in obstacles:
        world.add_polygon(o.polygon, kind=o.kind)
    map_free = world.grid.free_mask()
    for o in obstacles:
        r, c = world.geometry.world_to_cell(np.array([o.center]))
        assert map_free[r[0], c[0]]  # not in the map
        assert not world.is_free(np.array([o.center]))[0]  # but in the world
        aisle = min(GREENHOUSE_AISLES, key=lambda y: abs(y - o.center[1]))
        ys = np.linspace(aisle - 0.6, aisle + 0.6, 49)
        free = world.is_free(np.column_stack((np.full(ys.size, o.center[0]), ys)))
        assert free.sum() * (ys[1] - ys[0]) >= 0.5


def test_amcl_does_not_settle_inside_the_l_corridors_solid_core() -> None:
    """TEB turns trial 34 (seed 0): the operator's initial pose is right, but the Gaussian cloud
    round it reaches into the L's solid 6 x 6 m core, where every beam endpoint lands on an
    occupied cell (a perfect likelihood-field fit). The first update used to jump 1.9 m into the
    wall and the planner failed with StartOccupied; a particle inside a wall now gets no weight."""
    from bench.scenarios.suite import _l_corridor, fresh_stack
    from nav.types import Pose2D

    start = Pose2D(6.636241941941821, 1.0759038774518521, np.pi)
    stack = fresh_stack(_l_corridor(), start, 34, controller="teb")
    try:
        s = stack.session
        for _ in range(3):
            s.clock.sleep_until(s.clock.now() + s.period)
            s.step()
        assert stack.localization.updates >= 1
        assert s.pose.distance_to(stack.driver.truth_pose) < 0.2
    finally:
        stack.session.close()
