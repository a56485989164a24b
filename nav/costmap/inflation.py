"""Inflation layer, as Nav2's ``nav2_costmap_2d::InflationLayer``.

Every cell within ``inflation_radius`` of a lethal cell gets a cost that decays with its distance
``d`` to the nearest lethal cell (Nav2 ``computeCost``)::

    d == 0                  -> 254 LETHAL_OBSTACLE
    d <= inscribed_radius   -> 253 INSCRIBED_INFLATED_OBSTACLE (the robot centre here collides)
    otherwise               -> (unsigned char)(252 * exp(-cost_scaling_factor * (d - inscribed_radius)))

Nav2 measures ``d`` as the Euclidean distance between cell centres (in cells, times the resolution)
and propagates only to ``ceil(inflation_radius / resolution)`` cells; the C++ cast truncates. Nav2
spreads costs with a bucketed BFS; here ``scipy.ndimage.distance_transform_edt`` gives the exact
Euclidean distance to the nearest source cell in one O(N) pass, and since a squared cell distance is
an integer, the cost is a lookup table indexed by it: the same numbers Nav2 caches in
``cached_costs_``, with no per-cell Python.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from nav.types import FREE_SPACE, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION


@dataclass(frozen=True)
class InflationOptions:
    """Nav2 ``InflationLayer`` parameters."""

    inflation_radius: float = 0.55
    """Radius (m) to which costs are spread around lethal cells. Nav2 default 0.55."""
    cost_scaling_factor: float = 10.0
    """Exponential decay rate (1/m) of cost beyond the inscribed radius. Nav2 default 10.0."""
    inflate_unknown: bool = False
    """Whether unknown (255) cells may take inflation costs. Nav2 default false."""
    inflate_around_unknown: bool = False
    """Whether unknown cells act as inflation sources like lethal ones. Nav2 default false."""


def inflation_cost(
    distance: np.ndarray | float, inscribed_radius: float, options: InflationOptions
) -> np.ndarray:
    """Nav2 ``InflationLayer::computeCost`` for distances (m) to the nearest lethal cell, as uint8.
    Distances beyond the inflation radius still follow the formula (callers mask them)."""
    d = np.asarray(distance, dtype=np.float64)
    factor = np.exp(-options.cost_scaling_factor * (d - inscribed_radius))
    cost = np.trunc((INSCRIBED_INFLATED_OBSTACLE - 1) * factor)
    cost = np.where(d <= inscribed_radius, INSCRIBED_INFLATED_OBSTACLE, np.minimum(cost, 252))
    cost = np.where(d == 0, LETHAL_OBSTACLE, cost)
    return cost.astype(np.uint8)


def cell_inflation_radius(resolution: float, options: InflationOptions) -> int:
    """Nav2 ``Costmap2D::cellDistance``: ``ceil(inflation_radius / resolution)`` cells."""
    return max(0, math.ceil(options.inflation_radius / resolution))


def cost_lut(resolution: float, inscribed_radius: float, options: InflationOptions) -> np.ndarray:
    """Cost by squared cell distance ``k = di^2 + dj^2`` for k in 0..R^2 (R the cell radius); cells
    beyond R (k > R^2) are not inflated, as in Nav2's propagation limit."""
    r = cell_inflation_radius(resolution, options)
    k = np.arange(r * r + 1, dtype=np.float64)
    return inflation_cost(np.sqrt(k) * resolution, inscribed_radius, options)


@lru_cache(maxsize=16)
def _cached_lut(resolution: float, inscribed_radius: float, options: InflationOptions) -> np.ndarray:
    """``cost_lut``, read-only and shared: a costmap inflates with the same table every update."""
    lut = cost_lut(resolution, inscribed_radius, options)
    lut.flags.writeable = False
    return lut


@njit(cache=True, nogil=True)
def _column_distance(costs: np.ndarray, around_unknown: bool, cap: int) -> np.ndarray:
    """Per column, the row distance to the nearest source cell (lethal, or unknown if
    ``around_unknown``), capped at ``cap``. Branch-free inner loops over a row so LLVM vectorizes."""
    h, w = costs.shape
    g = np.empty((h, w), dtype=np.int32)
    prev = np.full(w, cap, dtype=np.int32)
    unknown_source = LETHAL_OBSTACLE if not around_unknown else NO_INFORMATION
    for i in range(h):
        row = costs[i]
        for j in range(w):
            c = row[j]
            src = (c == LETHAL_OBSTACLE) | (c == unknown_source)
            v = min(prev[j] + 1, cap)
            prev[j] = 0 if src else v
        g[i] = prev
    prev[:] = cap
    for i in range(h - 1, -1, -1):
        gi = g[i]
        for j in range(w):
            v = min(prev[j] + 1, gi[j])
            prev[j] = v
        g[i] = prev
    return g


@njit(cache=True, nogil=True)
def _inflate_kernel(
    costs: np.ndarray, r: int, lut: np.ndarray, around_unknown: bool, inflate_unknown: bool
) -> np.ndarray:
    """Exact squared Euclidean distance within ``r`` cells, then ``lut`` and Nav2's merge rules.

    Separable like Felzenszwalb & Huttenlocher (2012): a column pass gives each cell's vertical
    distance ``g`` to the nearest source in its column; then along each row
    ``d2(q) = min_{|o| <= r} g(q + o)^2 + o^2``. Because ``r`` is small (11 cells for Nav2's
    defaults) the bounded minimum is 2r+1 contiguous, branch-free sweeps that LLVM vectorizes, which
    beats the parabola envelope's divisions on cluttered maps."""
    h, w = costs.shape
    big = 1 << 20
    g = _column_distance(costs, around_unknown, r + 1)
    out = costs.copy()
    g2 = np.full(w + 2 * r, big, dtype=np.int32)
    d2 = np.empty(w, dtype=np.int32)
    rr = r * r
    for i in range(h):
        gi = g[i]
        near = False
        for j in range(w):
            v = gi[j]
            g2[j + r] = v * v if v <= r else big
            near |= v <= r
        if not near:
            continue
        d2[:] = g2[r : r + w]
        for o in range(1, r + 1):
            oo = o * o
            left = g2[r - o : r - o + w]  # slices keep indices provably in range: no wraparound checks
            right = g2[r + o : r + o + w]
            for q in range(w):
                d2[q] = min(d2[q], min(left[q], right[q]) + oo)
        orow = out[i]
        for q in range(w):
            dq = d2[q]
            if dq <= rr:
                cost = lut[dq]
                old = orow[q]
                if old == NO_INFORMATION:
                    if (inflate_unknown and cost > FREE_SPACE) or cost >= INSCRIBED_INFLATED_OBSTACLE:
                        orow[q] = cost
                elif cost > old:
                    orow[q] = cost
    return out


def inflate(
    costs: np.ndarray, resolution: float, inscribed_radius: float, options: InflationOptions
) -> np.ndarray:
    """Inflate a (H, W) uint8 master grid (static + obstacle costs) and return a new grid.

    Sources are lethal cells (plus unknown ones if ``inflate_around_unknown``). Each cell ends as
    ``max(old, inflation)``; an unknown cell only takes an inflation cost >= inscribed (any cost > 0
    if ``inflate_unknown``), as in Nav2's ``updateCosts``.
    """
    r = cell_inflation_radius(resolution, options)
    if r > 1000:
        raise ValueError(f"inflation_radius {options.inflation_radius} m is over 1000 cells")
    lut = _cached_lut(resolution, inscribed_radius, options)
    return _inflate_kernel(
        np.ascontiguousarray(costs, dtype=np.uint8),
        r,
        lut,
        options.inflate_around_unknown,
        options.inflate_unknown,
    )
