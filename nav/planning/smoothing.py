"""Path smoothing and orientations, after Nav2's ``nav2_smoother::SimpleSmoother``.

The simple smoother is gradient descent on ``w_data * |y - x|^2 + w_smooth * |y_{i+1} - 2 y_i +
y_{i-1}|^2`` (Thrun's "AI for Robotics" smoother, as used by Nav2): each interior point ``y_i`` moves
by ``w_data (x_i - y_i) + w_smooth (y_{i+1} + y_{i-1} - 2 y_i)`` until the total change per sweep
falls below ``tolerance``. Nav2 aborts the whole smoothing on a collision; here a single move is
rejected when it (or the midpoints to its neighbours) would enter a cell of higher cost than the
cell the grid path put that point in, so smoothing never pulls a path closer to obstacles than the
planner chose. The sweep is Gauss-Seidel in place like Nav2's, compiled with numba (it is O(its * N)
scalar work that numpy cannot vectorize without changing the method).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, wrap_angle


@dataclass(frozen=True)
class SmootherOptions:
    """Nav2 ``SimpleSmoother`` parameters."""

    tolerance: float = 1e-10
    """Stop when the summed change of one sweep (cells) is below this. Nav2 default 1e-10."""
    max_its: int = 1000
    """Maximum sweeps. Nav2 default 1000."""
    w_data: float = 0.2
    """Weight pulling points back to the original path. Nav2 default 0.2."""
    w_smooth: float = 0.3
    """Weight of the smoothness term. Nav2 default 0.3."""


@njit(cache=True, nogil=True)
def _cost_at(costs: np.ndarray, x: float, y: float) -> int:
    h, w = costs.shape
    c = math.floor(x)
    r = math.floor(y)
    if r < 0 or r >= h or c < 0 or c >= w:
        return 255
    return int(costs[r, c])


@njit(cache=True, nogil=True)
def _smooth(
    xy: np.ndarray, costs: np.ndarray, tolerance: float, max_its: int, w_data: float, w_smooth: float
) -> np.ndarray:
    n = xy.shape[0]
    y = xy.copy()
    allowed = np.empty(n, dtype=np.int64)
    for i in range(n):
        allowed[i] = _cost_at(costs, xy[i, 0], xy[i, 1])
    for _ in range(max_its):
        change = 0.0
        for i in range(1, n - 1):
            nx = (
                y[i, 0] + w_data * (xy[i, 0] - y[i, 0]) + w_smooth * (y[i + 1, 0] + y[i - 1, 0] - 2 * y[i, 0])
            )
            ny = (
                y[i, 1] + w_data * (xy[i, 1] - y[i, 1]) + w_smooth * (y[i + 1, 1] + y[i - 1, 1] - 2 * y[i, 1])
            )
            lim = allowed[i]
            if _cost_at(costs, nx, ny) > lim:
                continue
            lim_prev = max(lim, allowed[i - 1])
            lim_next = max(lim, allowed[i + 1])
            if _cost_at(costs, 0.5 * (nx + y[i - 1, 0]), 0.5 * (ny + y[i - 1, 1])) > lim_prev:
                continue
            if _cost_at(costs, 0.5 * (nx + y[i + 1, 0]), 0.5 * (ny + y[i + 1, 1])) > lim_next:
                continue
            change += abs(nx - y[i, 0]) + abs(ny - y[i, 1])
            y[i, 0] = nx
            y[i, 1] = ny
        if change < tolerance:
            break
    return y


def smooth_cells(cells_xy: np.ndarray, costs: np.ndarray, options: SmootherOptions) -> np.ndarray:
    """Smooth an (N, 2) path in continuous cell coordinates (col + 0.5, row + 0.5 at cell centres)
    over a (H, W) uint8 cost grid; endpoints stay fixed. Returns a new (N, 2) array."""
    pts = np.ascontiguousarray(cells_xy, dtype=np.float64)
    if pts.shape[0] < 3:
        return pts.copy()
    out = _smooth(
        pts,
        np.ascontiguousarray(costs, dtype=np.uint8),
        options.tolerance,
        options.max_its,
        options.w_data,
        options.w_smooth,
    )
    return out


def path_is_traversable(
    costmap: Costmap, xy: np.ndarray, *, max_cost: int = INSCRIBED_INFLATED_OBSTACLE - 1, step: float = 0.25
) -> bool:
    """True when every point sampled along the polyline (every ``step`` cells) has cost <= max_cost
    or is unknown. Vectorized; used to validate a smoothed path before it replaces the grid path."""
    if xy.shape[0] < 2:
        return True
    seg = np.diff(xy, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    n = np.maximum(np.ceil(seg_len / (step * costmap.geometry.resolution)).astype(np.int64), 1)
    idx = np.repeat(np.arange(seg.shape[0]), n)
    t = (np.arange(idx.shape[0]) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    samples = np.vstack((xy[idx] + seg[idx] * t[:, None], xy[-1:]))
    c = costmap.cost_at(samples)
    return bool(np.all((c <= max_cost) | (c == 255)))


def orientations(xy: np.ndarray, final_theta: float) -> np.ndarray:
    """Headings along an (N, 2) polyline: each pose faces along the chord from its predecessor to its
    successor (forward/backward difference at the ends); the last pose takes ``final_theta`` (the
    goal heading, as Nav2 planners do)."""
    n = xy.shape[0]
    theta = np.empty(n)
    if n == 1:
        theta[0] = final_theta
        return theta
    d = np.empty_like(xy)
    d[1:-1] = xy[2:] - xy[:-2]
    d[0] = xy[1] - xy[0]
    d[-1] = xy[-1] - xy[-2]
    theta[:] = np.arctan2(d[:, 1], d[:, 0])
    theta[-1] = final_theta
    return np.asarray(wrap_angle(theta))
