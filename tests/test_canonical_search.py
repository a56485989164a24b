"""The canonical-ordering kernel (nav.planning.canonical_search: jump point search's pruning on the
bucketed A*) against the references: scipy's csgraph Dijkstra on the explicit 8-connected graph and
the unpruned bucket kernel, on uniform-cost grids; and the kernel choice (nav.planning.kernel),
which must leave every non-uniform costmap to the bucket kernel, path for path."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest
from test_bucket_search import path_cost
from test_planning_reference import reference_costs

from bench.datasets import MOVINGAI
from bench.peers import load_movingai_map, load_scenarios
from nav.costmap import Costmap2D, CostmapOptions
from nav.planning import AStarPlanner, DijkstraPlanner, PlannerOptions
from nav.planning import base as planner_base
from nav.planning.bucket_search import BucketSearch, Workspace
from nav.planning.canonical_search import CanonicalSearch, uniform_cost
from nav.planning.grid_search import BUDGET, EXHAUSTED, FOUND
from nav.planning.kernel import make_search, octile_search, uniform_step_scale
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, OccupancyGrid, Pose2D

SQRT2 = math.sqrt(2.0)
bucket_octile_search = partial(octile_search, canonical=False)


def unit_cost(passable: np.ndarray) -> np.ndarray:
    return np.zeros(passable.shape, np.uint8)


def check_against_references(passable: np.ndarray, start, goal, heuristic_weight: float = 1.0) -> float:
    """The kernel's cost equals the csgraph and bucket references; its path is legal and that long."""
    costs = np.where(passable, 0, LETHAL_OBSTACLE).astype(np.uint8)
    ref = reference_costs(costs, 0.0, start)[goal]
    bucket = bucket_octile_search(passable, start, goal, heuristic_weight=heuristic_weight)[0]
    got, cells, _ = octile_search(passable, start, goal, heuristic_weight=heuristic_weight)
    if math.isinf(ref):
        assert math.isinf(got) and math.isinf(bucket) and cells is None
        return got
    assert got == pytest.approx(ref, rel=1e-12, abs=1e-9)
    assert got == pytest.approx(bucket, rel=1e-12, abs=1e-9)
    assert tuple(cells[0]) == tuple(start) and tuple(cells[-1]) == tuple(goal)
    assert path_cost(cells, passable, unit_cost(passable), 0.0) == pytest.approx(got, rel=1e-12)
    return got


@pytest.mark.parametrize("seed", range(60))
def test_optimal_on_random_grids(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 60)), int(rng.integers(1, 60))
    passable = rng.random((h, w)) >= rng.uniform(0.0, 0.4)
    start = tuple(int(v) for v in rng.integers(0, (h, w)))
    goal = tuple(int(v) for v in rng.integers(0, (h, w)))  # blocked or unreachable at times
    check_against_references(passable, start, goal, heuristic_weight=float(rng.choice([0.0, 1.0])))


@pytest.mark.parametrize("seed", range(20))
def test_optimal_among_blocks_and_walls_with_gaps(seed: int) -> None:
    # Rectangles and walls pierced by 1-cell gaps: many forced neighbours and long straight runs.
    rng = np.random.default_rng(1000 + seed)
    h, w = int(rng.integers(20, 90)), int(rng.integers(20, 90))
    passable = np.ones((h, w), dtype=bool)
    for _ in range(int(rng.integers(5, 40))):
        r, c = rng.integers(0, h), rng.integers(0, w)
        passable[r : r + rng.integers(1, 9), c : c + rng.integers(1, 9)] = False
    for r in range(2, h, int(rng.integers(3, 7))):
        passable[r, :] = rng.random(w) < 0.1
    free = np.argwhere(passable)
    for _ in range(5):
        start, goal = (tuple(int(v) for v in free[i]) for i in rng.integers(0, len(free), 2))
        check_against_references(passable, start, goal)


def test_large_random_grids_match_the_bucket_kernel() -> None:
    for seed, density in ((0, 0.1), (1, 0.2), (2, 0.3)):
        passable = np.random.default_rng(seed).random((300, 400)) >= density
        passable[0, 0] = passable[-1, -1] = True
        got = check_against_references(passable, (0, 0), (299, 399))
        assert math.isfinite(got)


def test_start_goal_and_blocked_cells() -> None:
    passable = np.ones((5, 5), dtype=bool)
    passable[2, 2] = False
    assert octile_search(passable, (2, 2), (2, 4))[0] == pytest.approx(2.0)  # leaves a blocked start
    assert octile_search(passable, (0, 0), (2, 2))[0] == math.inf  # blocked goal
    cost, cells, _ = octile_search(passable, (3, 3), (3, 3))
    assert cost == 0.0 and cells.tolist() == [[3, 3]]
    assert octile_search(passable, (2, 2), (2, 2))[0] == 0.0
    sealed = np.ones((9, 9), dtype=bool)
    sealed[4, :] = False
    cost, cells, _ = octile_search(sealed, (0, 0), (8, 8))
    assert cost == math.inf and cells is None


def test_diagonal_squeezes_are_not_cut() -> None:
    # Two blocked cells touching at a corner leave a diagonal gap no step may pass.
    squeeze = np.array([[1, 0], [0, 1]], dtype=bool)
    assert octile_search(squeeze, (0, 0), (1, 1))[0] == math.inf
    # A diagonal wall of corner-touching cells seals one half of the grid from the other.
    n = 30
    wall = np.ones((n, n), dtype=bool)
    wall[np.arange(n), np.arange(n)[::-1]] = False
    assert octile_search(wall, (0, 0), (n - 1, n - 1))[0] == math.inf
    wall[n // 2, n - 1 - n // 2] = True  # one cell of it opened: now passable through that cell
    check_against_references(wall, (0, 0), (n - 1, n - 1))
    # A forced neighbour behind a corner: the path turns round it without cutting it.
    turn = np.ones((6, 6), dtype=bool)
    turn[1:, 2] = False
    got = check_against_references(turn, (5, 0), (5, 4))
    # up the left side, straight past the wall's free top end (no diagonal there), down the right
    assert got == pytest.approx(10 + 2 * SQRT2)


def test_one_cell_corridors() -> None:
    # A serpentine of 1-cell corridors: every turn is a forced neighbour.
    h, w = 21, 30
    maze = np.zeros((h, w), dtype=bool)
    maze[::2, :] = True
    for i, r in enumerate(range(1, h, 2)):
        maze[r, w - 1 if i % 2 == 0 else 0] = True
    got = check_against_references(maze, (0, 0), (h - 1, 0))
    assert got == pytest.approx(10 * (w - 1) + 20)
    check_against_references(maze, (0, 5), (h - 1, w - 1), heuristic_weight=0.0)


DEN312D = MOVINGAI / "mapf" / "den312d"


@pytest.mark.skipif(not DEN312D.exists(), reason="movingai dataset not available")
@pytest.mark.parametrize("name", ["den312d", "maze-32-32-2", "random-32-32-10", "room-64-64-8"])
def test_movingai_optimal_lengths(name: str) -> None:
    root = MOVINGAI / "mapf" / name
    passable = load_movingai_map(root / f"{name}.map")
    for start, goal, optimal in load_scenarios(root / f"{name}-random-1.scen", 200):
        got, cells, _ = octile_search(passable, start, goal)
        assert got == pytest.approx(optimal, abs=1e-6), (start, goal)
        assert path_cost(cells, passable, unit_cost(passable), 0.0) == pytest.approx(got)


def test_resumed_in_slices_gives_the_same_result() -> None:
    rng = np.random.default_rng(7)
    passable = rng.random((200, 200)) >= 0.25
    passable[0, 0] = passable[-1, -1] = True
    whole = CanonicalSearch(passable, (0, 0), (199, 199))
    assert whole.run(1 << 62) == FOUND
    sliced = CanonicalSearch(passable, (0, 0), (199, 199))
    calls = 0
    while (status := sliced.run(300)) == BUDGET:
        calls += 1
    assert status == FOUND and calls > 10
    assert sliced.goal_cost == whole.goal_cost == sliced.cost_to(199, 199)
    assert sliced.expansions == whole.expansions
    assert np.array_equal(sliced.path, whole.path)
    rows, cols = sliced.cells_to(199, 199)
    assert np.array_equal(np.column_stack((rows, cols)), whole.path)
    assert sliced.run(300) == FOUND


def test_exhausted_search_closes_the_same_cells_as_the_bucket_kernel() -> None:
    # The planner falls back to the nearest closed cell: both kernels must close every reachable
    # cell, with its exact cost and a legal path to it.
    rng = np.random.default_rng(3)
    passable = rng.random((60, 80)) >= 0.3
    passable[:3, :3] = passable[59, 79] = True  # the start not walled in
    passable[30, :] = False  # the goal's half is cut off
    pruned = CanonicalSearch(passable, (0, 0), (59, 79))
    full = BucketSearch(passable, None, (0, 0), (59, 79))
    assert pruned.run(1 << 62) == EXHAUSTED and full.run(1 << 62) == EXHAUSTED
    assert math.isinf(pruned.goal_cost)
    assert np.array_equal(pruned.closed, full.closed) and pruned.closed.sum() > 100
    ref = reference_costs(np.where(passable, 0, LETHAL_OBSTACLE).astype(np.uint8), 0.0, (0, 0))
    for r, c in np.argwhere(pruned.closed)[::37]:
        assert pruned.cost_to(r, c) == pytest.approx(ref[r, c], rel=1e-12)
        cells = np.column_stack(pruned.cells_to(r, c))
        assert path_cost(cells, passable, unit_cost(passable), 0.0) == pytest.approx(ref[r, c])


def test_open_list_grows_past_its_first_allocation() -> None:
    # Stacks of 16 entries (instead of 4096): Dijkstra from the middle of an open floor overflows
    # them at once; they must grow and keep every entry.
    free = np.ones((300, 300), dtype=bool)
    ws = Workspace(300, 300)
    search = CanonicalSearch(free, (150, 150), (299, 299), heuristic_weight=0.0, width=3.0, workspace=ws)
    ws.buckets = np.empty((ws.buckets.shape[0], 16), dtype=np.int32)
    assert search.run(1 << 62) == FOUND
    assert search.goal_cost == pytest.approx(149 * SQRT2) and len(search.path) == 150
    assert ws.buckets.shape[1] > 16 and search.expansions > 80_000


def test_uniform_cost_detection() -> None:
    passable = np.array([[True, False], [True, True]])
    cost = np.array([[7, 200], [7, 7]], dtype=np.uint8)
    assert uniform_cost(passable, cost) == 7  # the blocked cell's cost does not count
    cost[1, 1] = 8
    assert uniform_cost(passable, cost) == -1
    assert uniform_cost(np.zeros((2, 2), bool), cost) == -1
    assert uniform_step_scale(passable, None, 2.0) == 1.0
    assert uniform_step_scale(passable, cost, 0.0) == 1.0
    assert uniform_step_scale(passable, cost, 2.0) is None
    cost[1, 1] = 7
    assert uniform_step_scale(passable, cost, 2.0) == pytest.approx(1.0 + 2.0 * 7 / 252)


def test_kernel_choice() -> None:
    rng = np.random.default_rng(5)
    passable = rng.random((40, 50)) >= 0.2
    passable[0, 0] = passable[-1, -1] = True
    varied = rng.integers(0, 250, passable.shape).astype(np.uint8)
    assert isinstance(make_search(passable, None, (0, 0), (39, 49)), CanonicalSearch)
    assert isinstance(make_search(passable, varied, (0, 0), (39, 49)), CanonicalSearch)  # weight 0
    assert isinstance(
        make_search(passable, varied, (0, 0), (39, 49), cost_travel_multiplier=2.0), BucketSearch
    )
    assert isinstance(make_search(passable, None, (0, 0), (39, 49), heuristic_weight=1.5), BucketSearch)
    # one common cost: every step scaled alike, the same optimum as the bucket kernel's
    common = np.full(passable.shape, 90, np.uint8)
    search = make_search(passable, common, (0, 0), (39, 49), cost_travel_multiplier=2.0)
    assert isinstance(search, CanonicalSearch) and search.run(1 << 62) == FOUND
    ref = bucket_octile_search(passable, (0, 0), (39, 49), cost=common, cost_travel_multiplier=2.0)[0]
    assert search.goal_cost == pytest.approx(ref, rel=1e-12)
    assert path_cost(search.path, passable, common, 2.0) == pytest.approx(ref, rel=1e-12)


def test_bad_input_is_refused() -> None:
    passable = np.ones((5, 5), dtype=bool)
    with pytest.raises(ValueError, match="outside"):
        octile_search(passable, (0, 0), (5, 0))
    with pytest.raises(ValueError, match="step_scale"):
        CanonicalSearch(passable, (0, 0), (1, 1), step_scale=0.5)
    with pytest.raises(ValueError, match="heuristic_weight"):
        CanonicalSearch(passable, (0, 0), (1, 1), heuristic_weight=math.nan)


def inflated_costmap(seed: int) -> Costmap:
    """A seeded map of random rectangles, inflated as the navigation stack does (non-uniform)."""
    rng = np.random.default_rng(seed)
    h, w = 120, 160
    data = np.zeros((h, w), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    for _ in range(25):
        r, c = rng.integers(0, h), rng.integers(0, w)
        data[r : r + rng.integers(2, 12), c : c + rng.integers(2, 12)] = 100
    grid = OccupancyGrid(GridGeometry(0.05, w, h, Pose2D(0.0, 0.0, 0.0)), data)
    return Costmap2D.from_map(grid, CostmapOptions(robot_radius=0.15)).costmap()


@pytest.mark.parametrize("seed", range(6))
def test_planner_paths_on_non_uniform_costmaps_are_unchanged(seed: int, monkeypatch) -> None:
    # Navigation plans on inflated costmaps: the kernel choice must give exactly the bucket
    # kernel's path (bit for bit), expansions and cost.
    cm = inflated_costmap(seed)
    free = np.argwhere(cm.costs == 0)
    rng = np.random.default_rng(seed)
    queries = []
    for _ in range(4):
        (sr, sc), (gr, gc) = free[rng.integers(0, len(free), 2)]
        queries.append(
            (
                Pose2D(*cm.geometry.cell_to_world(np.array([sr]), np.array([sc]))[0]),
                Pose2D(*cm.geometry.cell_to_world(np.array([gr]), np.array([gc]))[0], 0.3),
            )
        )
    planners = [AStarPlanner(), DijkstraPlanner(), AStarPlanner(PlannerOptions(cost_travel_multiplier=5.0))]
    now = [[p.plan_with_stats(cm, s, g) for s, g in queries] for p in planners]
    # the planner's search before the kernel choice: always the bucket kernel
    monkeypatch.setattr(planner_base, "make_search", partial(make_search, canonical=False))
    before = [[p.plan_with_stats(cm, s, g) for s, g in queries] for p in planners]
    for got_all, ref_all in zip(now, before, strict=True):
        for (path, stats), (ref_path, ref_stats) in zip(got_all, ref_all, strict=True):
            assert np.array_equal(path.poses, ref_path.poses)
            assert stats.expansions == ref_stats.expansions
            assert stats.search_cost == ref_stats.search_cost
            assert stats.goal_cell == ref_stats.goal_cell


def test_planner_on_a_uniform_grid_is_optimal() -> None:
    rng = np.random.default_rng(11)
    h, w = 80, 100
    costs = np.where(rng.random((h, w)) < 0.25, LETHAL_OBSTACLE, 0).astype(np.uint8)
    costs[2, 2] = costs[77, 97] = 0
    cm = Costmap(GridGeometry(1.0, w, h), costs)
    ref = reference_costs(costs, 0.0, (2, 2))[77, 97]
    opts = PlannerOptions(smooth_path=False, tolerance=0.0)
    for planner in (AStarPlanner(opts), DijkstraPlanner(opts)):
        path, stats = planner.plan_with_stats(cm, Pose2D(2.5, 2.5), Pose2D(97.5, 77.5))
        assert stats.goal_reached_exactly and stats.search_cost == pytest.approx(ref, rel=1e-12)
        cells = np.floor(path.poses[:, [1, 0]]).astype(int)
        assert path_cost(cells, costs < 253, costs, 0.0) == pytest.approx(ref, rel=1e-12)


def test_one_call_search_without_the_canonical_kernel_is_the_bucket_kernel() -> None:
    # One entry point for both kernels: canonical=False must give exactly BucketSearch's answer,
    # the default exactly CanonicalSearch's on a uniform grid.
    rng = np.random.default_rng(21)
    passable = rng.random((90, 110)) >= 0.25
    passable[0, 0] = passable[-1, -1] = True
    bucket = BucketSearch(passable, None, (0, 0), (89, 109))
    pruned = CanonicalSearch(passable, (0, 0), (89, 109))
    assert bucket.run(1 << 62) == FOUND and pruned.run(1 << 62) == FOUND
    cost, cells, expansions = octile_search(passable, (0, 0), (89, 109), canonical=False)
    assert (cost, expansions) == (bucket.goal_cost, bucket.expansions)
    assert np.array_equal(cells, bucket.path)
    cost, cells, expansions = octile_search(passable, (0, 0), (89, 109))
    assert (cost, expansions) == (pruned.goal_cost, pruned.expansions)
    assert np.array_equal(cells, pruned.path)
    assert isinstance(make_search(passable, None, (0, 0), (89, 109), canonical=False), BucketSearch)
    assert not isinstance(make_search(passable, None, (0, 0), (89, 109), canonical=False), CanonicalSearch)
