"""The way out for a start that stands where the planner's ``max_cost`` forbids.

The gap rule (issue 18, ``PlannerOptions.max_cost`` below the inscribed cost) blocks every cell
nearer than inscribed radius + ``gap_margin`` to an obstacle. A robot pressed against a wall or a
chair leg stands in such a cell, and so do all its neighbours: the search expanded only the start
and the robot could never be planned out (issue 16's tightest spots). Like DWA's ObstacleFootprint
escape (a robot already in contact may take motions that do not deepen it), a path may leave the
start through those cells while every step strictly lowers the cost, i.e. moves away from the
obstacles; it can never climb into a gap the rule keeps closed.
"""

from __future__ import annotations

import numpy as np

from nav.types import LETHAL_OBSTACLE

_STEPS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def descent_from_start(costs: np.ndarray, start: tuple[int, int], max_cost: int) -> np.ndarray:
    """Bool mask over ``costs``: the cells costlier than ``max_cost`` (and not lethal or unknown)
    reachable from ``start`` by 8-connected steps that each strictly lower the cost. Empty (all
    False) when the start's own cost is at most ``max_cost``.

    Each step lowers the cost by at least one, so the descent ends within ``cost(start) -
    max_cost`` cells of the start: only that crop is evaluated, one vectorized pass per step."""
    out = np.zeros(costs.shape, dtype=bool)
    sr, sc = start
    top = int(costs[sr, sc])
    if top <= max_cost or top >= LETHAL_OBSTACLE:
        return out
    reach = top - max_cost
    r0, r1 = max(sr - reach, 0), min(sr + reach + 1, costs.shape[0])
    c0, c1 = max(sc - reach, 0), min(sc + reach + 1, costs.shape[1])
    # crop padded with LETHAL (never entered, never lower than a neighbour's cost)
    crop = np.pad(costs[r0:r1, c0:c1].astype(np.int16), 1, constant_values=LETHAL_OBSTACLE)
    band = (crop > max_cost) & (crop < LETHAL_OBSTACLE)
    h, w = crop.shape
    region = np.zeros((h, w), dtype=bool)
    region[sr - r0 + 1, sc - c0 + 1] = True
    frontier = region.copy()
    for _ in range(reach):
        grown = np.zeros_like(region)
        for dr, dc in _STEPS:
            # cells (r, c) of the frontier and their neighbour (r + dr, c + dc), inside the padding
            src = frontier[1 : h - 1, 1 : w - 1]
            src_cost = crop[1 : h - 1, 1 : w - 1]
            dst = (slice(1 + dr, h - 1 + dr), slice(1 + dc, w - 1 + dc))
            grown[dst] |= src & band[dst] & (crop[dst] < src_cost)
        frontier = grown & ~region
        if not frontier.any():
            break
        region |= frontier
    out[r0:r1, c0:c1] = region[1:-1, 1:-1]
    return out


__all__ = ["descent_from_start"]
