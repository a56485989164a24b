"""Which compiled search a plan runs: ``CanonicalSearch`` when every traversable cell costs the same
(its pruning is only valid when all steps of a kind cost alike), ``BucketSearch`` for everything else.

Real costmaps (inflation, unknown cost) are never uniform, so every navigation plan keeps the bucket
kernel and its exact paths; uniform grids (no cell costs, or ``cost_travel_multiplier`` 0, or one
common cost) get the pruned kernel, whose path may be a different one of the equally short paths.
A heuristic weight above 1 (not optimal either way) also keeps the bucket kernel.
"""

from __future__ import annotations

import numpy as np

from nav.planning.bucket_search import BUCKET_WIDTH, BucketSearch, workspace_for
from nav.planning.canonical_search import CanonicalSearch, uniform_cost
from nav.planning.grid_search import solve

GridSearch = BucketSearch | CanonicalSearch


def uniform_step_scale(
    passable: np.ndarray, cost: np.ndarray | None, cost_travel_multiplier: float
) -> float | None:
    """The factor every step's length is multiplied by when it is the same for all traversable
    cells (1 without cell costs), else None."""
    if cost is None or cost_travel_multiplier == 0.0:
        return 1.0
    if cost.shape != passable.shape:
        return None  # BucketSearch reports the mismatch
    common = uniform_cost(passable, cost)
    if common < 0:
        return None
    return 1.0 + cost_travel_multiplier * common / 252.0


def make_search(
    passable: np.ndarray,
    cost: np.ndarray | None,
    start: tuple[int, int],
    goal: tuple[int, int],
    *,
    heuristic_weight: float = 1.0,
    cost_travel_multiplier: float = 0.0,
    width: float = BUCKET_WIDTH,
    shared_workspace: bool = False,
    canonical: bool = True,
) -> GridSearch:
    """The search ``start -> goal`` on the kernel this grid allows (module docstring); arguments as
    ``BucketSearch``. ``shared_workspace`` uses this thread's reused arrays (one search at a time);
    ``canonical=False`` keeps the bucket kernel on every grid."""
    h, w = passable.shape
    workspace = workspace_for(h, w) if shared_workspace else None
    scale = uniform_step_scale(passable, cost, cost_travel_multiplier) if canonical else None
    if scale is not None and scale >= 1.0 and 0.0 <= heuristic_weight <= 1.0:
        return CanonicalSearch(
            passable,
            start,
            goal,
            step_scale=scale,
            heuristic_weight=heuristic_weight,
            width=width,
            workspace=workspace,
        )
    return BucketSearch(
        passable,
        cost,
        start,
        goal,
        heuristic_weight=heuristic_weight,
        cost_travel_multiplier=cost_travel_multiplier,
        width=width,
        workspace=workspace,
    )


def octile_search(
    passable: np.ndarray,
    start: tuple[int, int],
    goal: tuple[int, int],
    *,
    cost: np.ndarray | None = None,
    cost_travel_multiplier: float = 0.0,
    heuristic_weight: float = 1.0,
    width: float = BUCKET_WIDTH,
    canonical: bool = True,
) -> tuple[float, np.ndarray | None, int]:
    """Optimal (goal cost, (N, 2) path cells as (row, col) start first, expansions) in one call on
    the kernel ``make_search`` picks (the bucket kernel alone with ``canonical=False``), with this
    thread's reused workspace; cost ``inf`` and path None when the goal is unreachable."""
    return solve(
        make_search(
            passable,
            cost,
            start,
            goal,
            heuristic_weight=heuristic_weight,
            cost_travel_multiplier=cost_travel_multiplier,
            width=width,
            shared_workspace=True,
            canonical=canonical,
        )
    )
