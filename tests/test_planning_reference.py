"""A* and Dijkstra against an independent reference: scipy.sparse.csgraph.dijkstra on the same
8-connected graph (no corner cutting, step (1|sqrt2) * (1 + w * cost/252)), on random costmaps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from nav.planning import AStarPlanner, DijkstraPlanner, NoValidPathFound, PlannerOptions, traversable_mask
from nav.types import Costmap, GridGeometry, Pose2D


def reference_costs(costs: np.ndarray, weight: float, start: tuple[int, int]) -> np.ndarray:
    h, w = costs.shape
    ok = traversable_mask(costs, allow_unknown=False)
    ok_start = ok.copy()
    ok_start[start] = True  # the start is always expanded
    rows, cols, vals = [], [], []
    idx = np.arange(h * w).reshape(h, w)
    for dr, dc in [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]:
        r0, r1 = max(0, -dr), h - max(0, dr)
        c0, c1 = max(0, -dc), w - max(0, dc)
        src = idx[r0:r1, c0:c1]
        dst = idx[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
        valid = ok_start[r0:r1, c0:c1] & ok[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
        if dr and dc:
            valid &= ok[r0 + dr : r1 + dr, c0:c1] & ok[r0:r1, c0 + dc : c1 + dc]
        base = math.sqrt(2.0) if dr and dc else 1.0
        cost = base * (1.0 + weight * costs[r0 + dr : r1 + dr, c0 + dc : c1 + dc] / 252.0)
        rows.append(src[valid])
        cols.append(dst[valid])
        vals.append(cost[valid])
    graph = coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w, h * w)
    )
    return dijkstra(graph.tocsr(), indices=start[0] * w + start[1]).reshape(h, w)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), weight=st.sampled_from([0.0, 1.0, 2.0, 5.0]))
def test_matches_csgraph_reference(seed: int, weight: float) -> None:
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(5, 30)), int(rng.integers(5, 30))
    costs = rng.integers(0, 200, (h, w)).astype(np.uint8)
    costs[rng.random((h, w)) < 0.25] = 254
    costs[rng.random((h, w)) < 0.05] = 253
    cm = Costmap(GridGeometry(1.0, w, h), costs)
    free = np.argwhere(costs < 253)
    if len(free) < 2:
        return
    (sr, sc), (gr, gc) = free[rng.choice(len(free), 2, replace=False)]
    ref = reference_costs(costs, weight, (sr, sc))[gr, gc]
    opts = PlannerOptions(
        cost_travel_multiplier=weight, tolerance=0.0, allow_unknown=False, smooth_path=False
    )
    start, goal = Pose2D(sc + 0.5, sr + 0.5), Pose2D(gc + 0.5, gr + 0.5)
    for planner in (AStarPlanner(opts), DijkstraPlanner(opts)):
        if math.isinf(ref):
            with pytest.raises(NoValidPathFound):
                planner.plan(cm, start, goal)
        else:
            _, stats = planner.plan_with_stats(cm, start, goal)
            assert stats.search_cost == pytest.approx(ref, rel=1e-12, abs=1e-9)
