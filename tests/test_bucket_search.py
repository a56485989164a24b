"""The bucketed A* kernel (nav.planning.bucket_search) against the references: the heap kernel
(grid_search) and scipy's csgraph Dijkstra on the same 8-connected graph, on seeded random grids
with and without cell costs, and the MovingAI optimal lengths."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest
from test_planning_reference import reference_costs

from bench.datasets import MOVINGAI
from bench.peers import load_movingai_map, load_scenarios
from nav.planning import kernel
from nav.planning.bucket_search import BucketSearch, workspace_for
from nav.planning.grid_search import BUDGET, EXHAUSTED, FOUND, SearchState, _octile, octile_of_offsets
from nav.types import LETHAL_OBSTACLE

SQRT2 = math.sqrt(2.0)
# the one-call search on the bucket kernel alone (the canonical one would take the uniform grids)
octile_search = partial(kernel.octile_search, canonical=False)


def heap_cost(passable, cost, start, goal, weight, heuristic_weight) -> float:
    state = SearchState.create(
        passable, cost, start, goal, heuristic_weight=heuristic_weight, cost_travel_multiplier=weight
    )
    return state.cost_to(*goal) if state.run(1 << 62) == FOUND else math.inf


def path_cost(cells: np.ndarray, passable: np.ndarray, cost: np.ndarray, weight: float) -> float:
    """The path's cost re-added step by step, checking every step is legal."""
    steps = np.diff(cells, axis=0)
    assert np.all(np.abs(steps).max(axis=1) == 1), "not 8-connected unit moves"
    assert passable[cells[1:, 0], cells[1:, 1]].all(), "enters a blocked cell"
    diag = np.all(steps != 0, axis=1)
    a, b = cells[:-1][diag], cells[1:][diag]
    assert passable[a[:, 0], b[:, 1]].all() and passable[b[:, 0], a[:, 1]].all(), "cuts a corner"
    base = np.where(diag, SQRT2, 1.0)
    return float(np.sum(base * (1.0 + weight * cost[cells[1:, 0], cells[1:, 1]] / 252.0)))


@pytest.mark.parametrize("seed", range(40))
def test_same_cost_as_references_on_random_grids(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(3, 60)), int(rng.integers(3, 60))
    costs = rng.integers(0, 253, (h, w)).astype(np.uint8)
    costs[rng.random((h, w)) < rng.uniform(0.0, 0.4)] = LETHAL_OBSTACLE
    passable = costs < 253
    start = tuple(int(v) for v in rng.integers(0, (h, w)))
    goal = tuple(int(v) for v in rng.integers(0, (h, w)))
    weight = float(rng.choice([0.0, 1.0, 2.0, 5.0]))
    hw = float(rng.choice([0.0, 1.0]))  # Dijkstra and A*
    ref = reference_costs(costs, weight, start)[goal]
    found, cells, _ = octile_search(
        passable, start, goal, cost=costs, cost_travel_multiplier=weight, heuristic_weight=hw
    )
    assert found == pytest.approx(heap_cost(passable, costs, start, goal, weight, hw), rel=1e-12)
    if math.isinf(ref):
        assert math.isinf(found) and cells is None
        return
    assert found == pytest.approx(ref, rel=1e-12, abs=1e-9)
    assert tuple(cells[0]) == start and tuple(cells[-1]) == goal
    assert path_cost(cells, passable, costs, weight) == pytest.approx(found, rel=1e-12)


@pytest.mark.parametrize("width", [0.05, 0.5, 3.0])
def test_bucket_width_never_changes_the_cost(width: float) -> None:
    # Wide buckets expand cells before their cheapest path is known: re-opening keeps it exact.
    rng = np.random.default_rng(12)  # a seed whose corners are connected
    passable = rng.random((120, 150)) >= 0.3
    passable[0, 0] = passable[-1, -1] = True
    costs = rng.integers(0, 200, passable.shape).astype(np.uint8)
    for weight in (0.0, 3.0):
        ref = heap_cost(passable, costs, (0, 0), (119, 149), weight, 1.0)
        assert math.isfinite(ref)
        got, cells, _ = octile_search(
            passable, (0, 0), (119, 149), cost=costs, cost_travel_multiplier=weight, width=width
        )
        assert got == pytest.approx(ref, rel=1e-12)
        assert path_cost(cells, passable, costs, weight) == pytest.approx(got, rel=1e-12)


def test_open_list_grows_past_its_first_allocation() -> None:
    # Dijkstra from the middle of a 1000 x 1000 floor with 3-cell-wide buckets: one bucket holds a
    # 3-cell-deep ring of up to 8 * 500 cells, more than the first 4096-entry stacks: they must grow.
    free = np.ones((1000, 1000), dtype=bool)
    got, cells, expansions = octile_search(free, (500, 500), (999, 999), heuristic_weight=0.0, width=3.0)
    assert got == pytest.approx(499 * SQRT2)
    assert len(cells) == 500 and expansions > 990_000
    assert workspace_for(1000, 1000).buckets.shape[1] > 4096


def test_reused_workspace_forgets_the_previous_search() -> None:
    # Same grid size, different walls: the second search must not see the first one's cells.
    open_floor = np.ones((50, 50), dtype=bool)
    walled = open_floor.copy()
    walled[25, :49] = False
    a, _, _ = octile_search(open_floor, (0, 0), (49, 0))
    b, cells, _ = octile_search(walled, (0, 0), (49, 0))
    assert a == pytest.approx(49.0)
    assert b == pytest.approx(heap_cost(walled, np.zeros((50, 50), np.uint8), (0, 0), (49, 0), 0.0, 1.0))
    assert b > 49.0 and (cells[:, 1] == 49).any()
    walled[25, 49] = False  # sealed: unreachable, and the open floor again afterwards
    assert octile_search(walled, (0, 0), (49, 0))[0] == math.inf
    assert octile_search(open_floor, (0, 0), (49, 0))[0] == pytest.approx(49.0)


def test_start_in_a_blocked_cell_leaves_it_and_blocked_goal_is_unreachable() -> None:
    passable = np.ones((5, 5), dtype=bool)
    passable[2, 2] = False
    assert octile_search(passable, (2, 2), (2, 4))[0] == pytest.approx(2.0)
    assert octile_search(passable, (0, 0), (2, 2))[0] == math.inf
    assert octile_search(passable, (2, 2), (2, 2))[0] == 0.0


def test_branch_free_heuristic_is_the_heap_kernels_bit_for_bit() -> None:
    # the kernel's heuristic must return _octile's float exactly (the golden digests depend on it),
    # including the ties |d_row| == |d_col| and offsets far beyond any test grid
    rng = np.random.default_rng(3)
    far = rng.integers(-(2**30), 2**30, size=(2000, 2))
    near = np.array([(r, c) for r in range(-40, 41) for c in range(-40, 41)])
    for r, c in np.concatenate((near, far)):
        r, c = int(r), int(c)
        expected = _octile(r, c, 0, 0)
        got = octile_of_offsets(float(r), float(c))
        assert got == expected and math.copysign(1.0, got) == math.copysign(1.0, expected), (r, c)


def test_bad_input_is_refused() -> None:
    passable = np.ones((5, 5), dtype=bool)
    with pytest.raises(ValueError, match="outside"):
        octile_search(passable, (0, 0), (5, 0))
    with pytest.raises(ValueError, match="outside"):
        octile_search(passable, (-1, 0), (1, 1))
    with pytest.raises(ValueError, match="heuristic_weight"):
        octile_search(passable, (0, 0), (1, 1), heuristic_weight=math.nan)
    with pytest.raises(ValueError, match="shape"):
        octile_search(passable, (0, 0), (1, 1), cost=np.zeros((4, 5), np.uint8), cost_travel_multiplier=1.0)


DEN312D = MOVINGAI / "mapf" / "den312d"


@pytest.mark.skipif(not DEN312D.exists(), reason="movingai dataset not available")
@pytest.mark.parametrize("name", ["den312d", "maze-32-32-2", "random-32-32-10"])
def test_movingai_optimal_lengths(name: str) -> None:
    root = MOVINGAI / "mapf" / name
    passable = load_movingai_map(root / f"{name}.map")
    for start, goal, optimal in load_scenarios(root / f"{name}-random-1.scen", 200):
        got, cells, _ = octile_search(passable, start, goal)
        assert got == pytest.approx(optimal, abs=1e-6), (start, goal)
        assert path_cost(cells, passable, np.zeros(passable.shape, np.uint8), 0.0) == pytest.approx(got)


def test_resumed_in_slices_gives_the_same_result() -> None:
    # The planner runs the search in budgets of expansions to check its deadline between them.
    rng = np.random.default_rng(7)  # a seed whose corners are connected
    passable = rng.random((200, 200)) >= 0.25
    passable[0, 0] = passable[-1, -1] = True
    costs = rng.integers(0, 200, passable.shape).astype(np.uint8)
    whole = BucketSearch(passable, costs, (0, 0), (199, 199), cost_travel_multiplier=2.0)
    assert whole.run(1 << 62) == FOUND
    sliced = BucketSearch(passable, costs, (0, 0), (199, 199), cost_travel_multiplier=2.0)
    calls = 0
    while (status := sliced.run(500)) == BUDGET:
        calls += 1
    assert status == FOUND and calls > 10
    assert sliced.goal_cost == whole.goal_cost == sliced.cost_to(199, 199)
    assert sliced.expansions == whole.expansions
    assert np.array_equal(sliced.path, whole.path)
    rows, cols = sliced.cells_to(199, 199)
    assert np.array_equal(np.column_stack((rows, cols)), whole.path)
    assert sliced.run(500) == FOUND  # finished: another call changes nothing


def test_exhausted_search_closes_every_reachable_cell() -> None:
    passable = np.ones((20, 20), dtype=bool)
    passable[10, :] = False  # the goal's half is cut off
    search = BucketSearch(passable, None, (0, 0), (15, 5))
    assert search.run(1 << 62) == EXHAUSTED
    assert math.isinf(search.goal_cost)
    assert np.array_equal(search.closed, np.arange(20)[:, None] < 10 * np.ones((1, 20), dtype=bool))
    assert search.cost_to(9, 9) == pytest.approx(9 * SQRT2)
