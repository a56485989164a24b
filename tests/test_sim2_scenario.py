"""Stock scenarios: obstacles only in the simulated world, people that keep to free space."""

from __future__ import annotations

import numpy as np
import pytest

from maps.stock import STOCK_DIR, available_worlds
from nav.types import Pose2D
from robot.sim import World
from robot.sim.scenario import ScenarioError, load_scenario, parse_scenario, sidecar_path


@pytest.mark.parametrize("name", available_worlds())
def test_stock_scenarios_load_and_people_stay_in_free_space(name: str) -> None:
    plain = World.stock(name)
    world = World.stock(name, scenario=True)
    assert sidecar_path(STOCK_DIR / f"{name}.yaml").is_file()
    assert np.array_equal(world.grid.data, plain.grid.data)  # the map is untouched
    assert len(world.people) >= 2
    far = Pose2D(-50.0, -50.0, 0.0)  # the robot out of everyone's way
    start = world.people.xy.copy()
    for _ in range(2000):  # 20 s at 100 Hz
        world.people.step(0.01, far)
        rows, cols = world.geometry.world_to_cell(world.people.xy)
        # each person's centre keeps at least its radius (less a cell's half-diagonal) from walls
        assert np.all(world.clearance_map[rows, cols] >= 0.15 - 0.036), world.people.list()
    assert np.all(np.hypot(*(world.people.xy - start).T) > 0.3) or name == "office"


def test_greenhouse_mounds_and_puddles_are_seen_but_not_mapped() -> None:
    plain = World.stock("greenhouse")
    world = World.stock("greenhouse", scenario=True)
    kinds = [k for k, _ in world.features]
    assert kinds.count("mound") == 3 and kinds.count("puddle") == 2
    added = world.static_occupied & ~plain.static_occupied
    assert added.sum() > 50
    # the robot's lidar sees a mound that the map does not hold: cast along the aisle at y = 3.95
    r_world = world.raycaster.cast(np.array([3.0, 3.95]), np.array([0.0]), 10.0)[0, 0]
    r_map = plain.raycaster.cast(np.array([3.0, 3.95]), np.array([0.0]), 10.0)[0, 0]
    assert r_world == pytest.approx(6.0 - 0.4 - 3.0, abs=0.06) and r_map > r_world + 5.0
    # every aisle keeps at least 0.8 m free across it next to each obstacle
    for _, poly in world.features:
        x = float(poly[:, 0].mean())
        col = world.static_occupied[:, round(x / 0.05)]
        y0 = round(float(poly[:, 1].mean()) / 0.05)
        lo, hi = y0, y0
        while lo > 0 and col[lo]:
            lo -= 1
        while hi < col.size - 1 and col[hi]:
            hi += 1
        free_below = np.flatnonzero(col[:lo][::-1])
        free_above = np.flatnonzero(col[hi:])
        gap = max(free_below[0] if free_below.size else 0, free_above[0] if free_above.size else 0)
        assert gap * 0.05 >= 0.8


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"person": [{"kind": "fly", "at": [1, 1]}]}, "kind"),
        ({"person": [{"kind": "loop", "waypoints": [[1, 1]]}]}, "at least 2"),
        ({"person": [{"kind": "stand", "at": [1, 1], "speed": 5}]}, "speed"),
        ({"mound": [{"center": [1, 1], "radii": [0.0, 0.2]}]}, "radii"),
        ({"puddle": [{"center": "here", "radii": [0.2, 0.2]}]}, "center"),
        ({"tree": []}, "unknown"),
    ],
)
def test_bad_scenarios_are_refused_naming_the_field(data: dict, match: str) -> None:
    with pytest.raises(ScenarioError, match=match):
        parse_scenario(data)


def test_missing_scenario_file(tmp_path) -> None:
    with pytest.raises(ScenarioError, match="no scenario"):
        load_scenario(tmp_path / "x.scenario.toml")
