"""A* and Dijkstra reproduce the Moving AI benchmark optimal lengths (Sturtevant 2012): 8-connected,
diagonal sqrt2, no cutting past a blocked corner. See datasets/movingai/SOURCE.md in the shared folder."""

from __future__ import annotations

from pathlib import Path as FsPath

import numpy as np
import pytest

from bench.datasets import MOVINGAI
from nav.planning import AStarPlanner, DijkstraPlanner, PlannerOptions
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Pose2D

ROOT = MOVINGAI / "mapf"
MAPS = [
    "random-32-32-10",
    "maze-32-32-2",
    "room-32-32-4",
    "room-64-64-8",
    "warehouse-10-20-10-2-1",
    "den312d",
]
PER_MAP = 150  # scenarios sampled per map (from the random-1 and even-1 files)

pytestmark = pytest.mark.skipif(not ROOT.exists(), reason="movingai dataset not available")


def load_map(path: FsPath) -> Costmap:
    """A Moving AI ``.map`` as a costmap with 1 m cells: '.' and 'G' free, anything else lethal.
    Scenario y counts rows from the top, so map row y becomes grid row height-1-y."""
    lines = path.read_text().splitlines()
    h = int(lines[1].split()[1])
    w = int(lines[2].split()[1])
    rows = lines[4 : 4 + h]
    chars = np.array([list(r[:w]) for r in rows])
    free = (chars == ".") | (chars == "G")
    costs = np.where(free, 0, LETHAL_OBSTACLE).astype(np.uint8)[::-1].copy()
    return Costmap(GridGeometry(1.0, w, h), costs)


def load_scenarios(name: str, rng: np.random.Generator) -> list[tuple[int, int, int, int, float]]:
    out: list[tuple[int, int, int, int, float]] = []
    for kind in ("random-1", "even-1"):
        for line in (ROOT / name / f"{name}-{kind}.scen").read_text().splitlines()[1:]:
            f = line.split("\t")
            if len(f) >= 9:
                out.append((int(f[4]), int(f[5]), int(f[6]), int(f[7]), float(f[8])))
    idx = rng.choice(len(out), size=min(PER_MAP, len(out)), replace=False)
    return [out[i] for i in sorted(idx)]


def _pose(costmap: Costmap, x: int, y: int) -> Pose2D:
    return Pose2D(x + 0.5, costmap.geometry.height - 1 - y + 0.5, 0.0)


GEOMETRY_ONLY = PlannerOptions(
    tolerance=0.0, cost_travel_multiplier=0.0, smooth_path=False, allow_unknown=False, max_planning_time=30.0
)


@pytest.mark.parametrize("planner_cls", [AStarPlanner, DijkstraPlanner])
@pytest.mark.parametrize("name", MAPS)
def test_optimal_lengths(name: str, planner_cls: type) -> None:
    costmap = load_map(ROOT / name / f"{name}.map")
    planner = planner_cls(GEOMETRY_ONLY)
    rng = np.random.default_rng(7)
    for sx, sy, gx, gy, optimal in load_scenarios(name, rng):
        path, stats = planner.plan_with_stats(costmap, _pose(costmap, sx, sy), _pose(costmap, gx, gy))
        assert stats.goal_reached_exactly
        assert stats.search_cost == pytest.approx(optimal, abs=1e-6), (sx, sy, gx, gy)
        assert path.length == pytest.approx(optimal, abs=1e-6)
        # Every step is one of the 8 moves and never enters or cuts a blocked cell.
        cells = np.floor(path.poses[:, :2]).astype(int)
        steps = np.abs(np.diff(cells, axis=0))
        assert np.all(steps.max(axis=1) == 1)
        free = costmap.costs == 0
        assert free[cells[:, 1], cells[:, 0]].all()
        assert free[cells[:-1, 1], cells[1:, 0]].all() and free[cells[1:, 1], cells[:-1, 0]].all()


def test_astar_expands_no_more_than_dijkstra() -> None:
    costmap = load_map(ROOT / "den312d" / "den312d.map")
    rng = np.random.default_rng(3)
    for sx, sy, gx, gy, _ in load_scenarios("den312d", rng)[:10]:
        s, g = _pose(costmap, sx, sy), _pose(costmap, gx, gy)
        _, a = AStarPlanner(GEOMETRY_ONLY).plan_with_stats(costmap, s, g)
        _, d = DijkstraPlanner(GEOMETRY_ONLY).plan_with_stats(costmap, s, g)
        assert a.expansions <= d.expansions
        assert a.search_cost == pytest.approx(d.search_cost, abs=1e-9)
