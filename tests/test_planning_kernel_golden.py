"""The compiled A* kernels (bucket and canonical-ordering) and the planner on top of them return,
bit for bit, what they returned when this fixture was recorded (main 4c1b5cd, before the kernels
shared their open-list code): path, goal cost, expansions, closed set, the expansions after every
budget slice of a resumed search, and the planner's poses and stats.

Why a golden fixture: the background scenario sets plan with these kernels on real, non-uniform
costmaps, so a refactor or a speed-up of them must not move a single path. The inputs come from
seeded generators and the stored maps (stock maps, the ROS maps and MovingAI maps of the datasets
when present); ``tests/data/planning_kernel_golden.json`` holds digests of the outputs. Re-record
it only for an intended change of results: ``python tests/test_planning_kernel_golden.py``.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from bench.datasets import MOVINGAI, ROS_MAPS
from bench.peers import load_movingai_map, load_scenarios
from maps.mapio import load_map_yaml
from nav.costmap import Costmap2D, CostmapOptions
from nav.planning import AStarPlanner, DijkstraPlanner, PlannerError, PlannerOptions
from nav.planning.bucket_search import BucketSearch
from nav.planning.canonical_search import CanonicalSearch
from nav.planning.grid_search import BUDGET, FOUND
from nav.planning.kernel import make_search, octile_search
from nav.types import Costmap, Pose2D

GOLDEN = Path(__file__).parent / "data" / "planning_kernel_golden.json"
STOCK = Path(__file__).resolve().parents[1] / "maps" / "stock"
MAPF = MOVINGAI / "mapf"

Record = dict[str, object]
Case = tuple[str, Callable[[], Record]]


def digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.sha256(f"{a.dtype}{a.shape}".encode() + a.tobytes()).hexdigest()[:20]


def search_record(search: BucketSearch | CanonicalSearch, budget: int | None = None) -> Record:
    """Everything a search leaves: status, cost, expansions, path, closed cells and their costs."""
    slices = []
    if budget is None:
        status = search.run(1 << 62)
    else:
        while (status := search.run(budget)) == BUDGET:
            slices.append(search.expansions)
    h, w = search.shape
    closed = search.closed
    rec: Record = {
        "kind": type(search).__name__,
        "status": int(status),
        "expansions": search.expansions,
        "cost": float(search.goal_cost).hex(),
        "closed": digest(closed),
        "closed_g": digest(search.ws.g.reshape(h + 2, w + 2)[1:-1, 1:-1][closed]),
    }
    if status == FOUND:
        rec["path"] = digest(search.path)
    else:  # the planner falls back to a closed cell: a few of their paths
        cells = np.argwhere(closed)
        some = cells[:: max(1, len(cells) // 5)][:6]
        rec["fallback_paths"] = [digest(np.column_stack(search.cells_to(*cell))) for cell in some]
    if budget is not None:
        rec["slices"] = digest(np.array(slices, dtype=np.int64))
    return rec


def one_call_record(result: tuple[float, np.ndarray | None, int]) -> Record:
    cost, cells, expansions = result
    return {
        "cost": float(cost).hex(),
        "expansions": expansions,
        "path": None if cells is None else digest(cells),
    }


def plan_record(planner: AStarPlanner | DijkstraPlanner, cm: Costmap, start: Pose2D, goal: Pose2D) -> Record:
    try:
        path, stats = planner.plan_with_stats(cm, start, goal)
    except PlannerError as e:
        return {"error": type(e).__name__}
    return {
        "poses": digest(path.poses),
        "expansions": stats.expansions,
        "cost": float(stats.search_cost).hex(),
        "goal_cell": [int(v) for v in stats.goal_cell],
        "exact": bool(stats.goal_reached_exactly),
    }


def random_grid_cases() -> Iterator[Case]:
    """Seeded random grids, 0-40 % blocked cells, random (sometimes blocked) start and goal."""
    for seed in range(120):
        rng = np.random.default_rng(50_000 + seed)
        h, w = int(rng.integers(1, 150)), int(rng.integers(1, 150))
        passable = rng.random((h, w)) >= rng.uniform(0.0, 0.4)
        costs = rng.integers(0, 253, (h, w)).astype(np.uint8)
        start = tuple(int(v) for v in rng.integers(0, (h, w)))
        goal = tuple(int(v) for v in rng.integers(0, (h, w)))
        hw = float(rng.choice([0.0, 1.0]))
        ctm = float(rng.choice([1.0, 2.0, 5.0]))
        width = float(rng.choice([0.1, 0.1, 0.5]))
        bucket_hw = float(rng.choice([0.0, 1.0, 1.5]))
        budget = None if seed % 3 else int(rng.integers(1, 200))
        if seed % 2:
            passable[goal] = True  # else blocked at times: unreachable
        yield (
            f"random/{seed}/canonical",
            lambda p=passable, s=start, g=goal, hw=hw, b=budget: search_record(
                CanonicalSearch(p, s, g, heuristic_weight=hw), b
            ),
        )
        yield (
            f"random/{seed}/bucket",
            lambda p=passable, s=start, g=goal, hw=bucket_hw, wd=width, b=budget: search_record(
                BucketSearch(p, None, s, g, heuristic_weight=hw, width=wd), b
            ),
        )
        yield (
            f"random/{seed}/costs",
            lambda p=passable, c=costs, s=start, g=goal, m=ctm, hw=bucket_hw, b=budget: search_record(
                BucketSearch(p, c, s, g, heuristic_weight=hw, cost_travel_multiplier=m), b
            ),
        )
        common = np.full((h, w), int(rng.integers(0, 253)), np.uint8)
        yield (
            f"random/{seed}/make_search",
            lambda p=passable, c=common, s=start, g=goal, m=ctm: search_record(
                make_search(p, c, s, g, cost_travel_multiplier=m, shared_workspace=True)
            ),
        )
        yield (
            f"random/{seed}/octile_search",
            lambda p=passable, c=costs, s=start, g=goal, m=ctm: one_call_record(
                octile_search(p, s, g, cost=c, cost_travel_multiplier=m)
            ),
        )


def large_grid_cases() -> Iterator[Case]:
    """The 2000 x 2000 peers grid (20 % blocked, seed 0) and a 600 x 700 grid with cell costs."""

    def big() -> np.ndarray:
        free = np.random.default_rng(0).random((2000, 2000)) >= 0.2
        free[0, 0] = free[-1, -1] = True
        return free

    yield "large/2000/canonical", lambda: search_record(CanonicalSearch(big(), (0, 0), (1999, 1999)))
    yield "large/2000/bucket", lambda: search_record(BucketSearch(big(), None, (0, 0), (1999, 1999)))

    def costed(budget: int | None, hw: float) -> Record:
        rng = np.random.default_rng(77)
        passable = rng.random((600, 700)) >= 0.25
        passable[0, 0] = passable[-1, -1] = True
        costs = rng.integers(0, 253, passable.shape).astype(np.uint8)
        return search_record(
            BucketSearch(
                passable, costs, (0, 0), (599, 699), heuristic_weight=hw, cost_travel_multiplier=2.0
            ),
            budget,
        )

    yield "large/600x700/costs", lambda: costed(None, 1.0)
    yield "large/600x700/costs/resumed", lambda: costed(4096, 1.0)
    yield "large/600x700/costs/dijkstra", lambda: costed(None, 0.0)


def _costmaps() -> Iterator[tuple[str, Costmap]]:
    maps = [
        *sorted(STOCK.glob("*.yaml")),
        ROS_MAPS / "navigation_stage/willow-full-0.05.yaml",
        ROS_MAPS / "nav2_bringup/tb3_sandbox.yaml",
        ROS_MAPS / "nav2_bringup/warehouse.yaml",
        ROS_MAPS / "turtlebot3_navigation2/map.yaml",
    ]
    for path in maps:
        for radius in (0.1, 0.2):
            name = f"{path.parent.name}/{path.stem}@{radius}"
            if path.exists():
                grid = load_map_yaml(path)
                yield name, Costmap2D.from_map(grid, CostmapOptions(robot_radius=radius)).costmap()
            else:
                yield name, None


def costmap_cases() -> Iterator[Case]:
    """Plans on the inflated stock and ROS maps (non-uniform costs: the bucket kernel), as the
    navigation stack plans them, and the raw searches on their cost arrays."""
    planners = {
        "astar": AStarPlanner(),
        "dijkstra": DijkstraPlanner(),
        "astar_ctm5": AStarPlanner(PlannerOptions(cost_travel_multiplier=5.0)),
        "astar_unknown": AStarPlanner(PlannerOptions(allow_unknown=False, tolerance=0.0, smooth_path=False)),
    }
    for i, (name, cm) in enumerate(_costmaps()):
        if cm is None:
            yield f"costmap/{name}", None
            continue
        rng = np.random.default_rng(900 + i)
        free = np.argwhere(cm.costs < 128)
        pairs = [free[rng.integers(0, len(free), 2)] for _ in range(4)]
        for q, ((sr, sc), (gr, gc)) in enumerate(pairs):
            start = Pose2D(*cm.geometry.cell_to_world(np.array([sr]), np.array([sc]))[0], 0.0)
            goal = Pose2D(*cm.geometry.cell_to_world(np.array([gr]), np.array([gc]))[0], 0.7)
            for pname, planner in planners.items():
                if pname == "dijkstra" and q > 1:
                    continue
                yield (
                    f"costmap/{name}/{q}/{pname}",
                    lambda p=planner, c=cm, s=start, g=goal: plan_record(p, c, s, g),
                )
        (sr, sc), (gr, gc) = pairs[0]
        passable = cm.costs < 253
        passable[sr, sc] = passable[gr, gc] = True
        yield (
            f"costmap/{name}/raw",
            lambda p=passable, c=cm.costs, s=(sr, sc), g=(gr, gc): search_record(
                BucketSearch(p, c, s, g, cost_travel_multiplier=2.0)
            ),
        )
        yield (
            f"costmap/{name}/raw/resumed",
            lambda p=passable, c=cm.costs, s=(sr, sc), g=(gr, gc): search_record(
                BucketSearch(p, c, s, g, cost_travel_multiplier=2.0), 1000
            ),
        )


def movingai_cases() -> Iterator[Case]:
    """The first 30 scenarios of each MovingAI map present, on both kernels."""
    names = (
        "den312d",
        "maze-32-32-2",
        "random-32-32-10",
        "room-32-32-4",
        "room-64-64-8",
        "warehouse-10-20-10-2-1",
    )
    for name in names:
        root = MAPF / name
        if not (root / f"{name}.map").exists():
            yield f"movingai/{name}", None
            continue
        passable = load_movingai_map(root / f"{name}.map")
        for k, (start, goal, _) in enumerate(load_scenarios(root / f"{name}-random-1.scen", 30)):
            budget = 64 if k % 5 == 0 else None  # some resumed in slices
            yield (
                f"movingai/{name}/{k}/canonical",
                lambda s=start, g=goal, p=passable, b=budget: search_record(CanonicalSearch(p, s, g), b),
            )
            yield (
                f"movingai/{name}/{k}/bucket",
                lambda s=start, g=goal, p=passable: search_record(BucketSearch(p, None, s, g)),
            )


def special_cases() -> Iterator[Case]:
    """Blocked starts, the start as goal, sealed halves, open floors (stack growth)."""
    passable = np.ones((9, 9), dtype=bool)
    passable[4, :8] = False
    passable[2, 2] = False
    for kind in (CanonicalSearch, BucketSearch):
        args = (passable,) if kind is CanonicalSearch else (passable, None)
        for s, g in (((2, 2), (8, 8)), ((0, 0), (0, 0)), ((2, 2), (2, 2)), ((0, 0), (8, 0))):
            yield (
                f"special/{kind.__name__}/{s}/{g}",
                lambda k=kind, a=args, s=s, g=g: search_record(k(*a, s, g)),
            )
    sealed = passable.copy()
    sealed[4, 8] = False
    yield "special/sealed", lambda: search_record(CanonicalSearch(sealed, (0, 0), (8, 8)))
    yield "special/sealed/bucket", lambda: search_record(BucketSearch(sealed, None, (0, 0), (8, 8)))
    floor = np.ones((400, 400), dtype=bool)
    yield (
        "special/floor/dijkstra",
        lambda: search_record(
            CanonicalSearch(floor, (200, 200), (399, 399), heuristic_weight=0.0, width=3.0)
        ),
    )
    yield (
        "special/floor/bucket",
        lambda: search_record(
            BucketSearch(floor, None, (200, 200), (399, 399), heuristic_weight=0.0, width=3.0)
        ),
    )


def all_cases() -> Iterator[Case]:
    for gen in (random_grid_cases, large_grid_cases, costmap_cases, movingai_cases, special_cases):
        yield from gen()


def record_all() -> dict[str, Record]:
    return {key: fn() for key, fn in all_cases() if fn is not None}


@pytest.fixture(scope="module")
def golden() -> dict[str, Record]:
    return json.loads(GOLDEN.read_text())


GROUPS = ("random", "large", "costmap", "movingai", "special")


@pytest.mark.parametrize("group", GROUPS)
def test_kernels_return_the_recorded_results(group: str, golden: dict[str, Record]) -> None:
    checked = 0
    for key, fn in all_cases():
        if not key.startswith(group + "/"):
            continue
        if fn is None:
            continue  # its dataset is not present here
        assert key in golden, f"{key} was not recorded"
        assert fn() == golden[key], key
        checked += 1
    generated = {"random": 500, "large": 5, "special": 12}  # no dataset needed: always all there
    assert checked >= generated.get(group, 0)
    if checked == 0:
        pytest.skip(f"no {group} inputs present")


def test_fixture_covers_a_few_hundred_searches(golden: dict[str, Record]) -> None:
    assert len(golden) >= 300
    statuses = {rec.get("status") for rec in golden.values()}
    assert {0, 1} <= statuses  # found and exhausted searches
    assert any("slices" in rec for rec in golden.values())  # resumed searches
    assert all(math.isfinite(rec["expansions"]) for rec in golden.values() if "expansions" in rec)


if __name__ == "__main__":
    records = record_all()
    GOLDEN.write_text(json.dumps(records, indent=0, sort_keys=True) + "\n")
    print(f"recorded {len(records)} cases into {GOLDEN}", file=sys.stderr)
