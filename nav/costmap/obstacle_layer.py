"""Obstacle layer: lidar returns marked as lethal, free space cleared along each beam, as Nav2's
``nav2_costmap_2d::ObstacleLayer`` (``raytraceFreespace`` then marking, per observation).

Clearing walks every beam's cells with ``nav.costmap.raytrace.clear_segments`` (Amanatides & Woo
supercover, compiled; the cells ``nav.raycast.traversed_cells`` lists), stopping before the cell
that holds the return (Nav2's Bresenham also stops one cell short) and at
``raytrace_max_range``. A beam without return (issue 16) clears up to and including the first
LETHAL cell on its way, never behind it: it cannot tell a surface it missed (a dropout) from open
space, so it must not fan free space out through walls, yet a mark a walker left in open space
(no return behind it ever) still wears away, a cell per scan; marking sets the cells of returns within
``obstacle_max_range`` to LETHAL. Clearing runs before marking, so a return always survives its own
scan, and the layer keeps its state between scans (obstacles persist until a beam passes through).
On an axis-aligned grid (every costmap here) the whole update is one compiled pass (``_apply_scan``)
with the numpy path's arithmetic: a scan's ~40 small numpy operations cost more than the clearing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from nav.costmap.raytrace import NO_STAMP, _clear, clear_segments
from nav.types import FREE_SPACE, LETHAL_OBSTACLE, NO_INFORMATION, GridGeometry

Bounds = tuple[int, int, int, int]
"""Changed region as (row0, row1, col0, col1), half-open."""


@dataclass(frozen=True)
class ObstacleLayerOptions:
    """Nav2 ``ObstacleLayer`` observation-source parameters."""

    obstacle_max_range: float = 2.5
    """Returns farther than this (m) from the sensor are not marked. Nav2 default 2.5."""
    obstacle_min_range: float = 0.0
    """Returns nearer than this (m) are not marked. Nav2 default 0.0."""
    raytrace_max_range: float = 3.0
    """Beams clear free space up to this range (m). Nav2 default 3.0."""
    raytrace_min_range: float = 0.0
    """Clearing starts this far (m) from the sensor. Nav2 default 0.0."""
    clearing: bool = True
    """Whether the source clears free space. Nav2 default true (for a laser)."""
    marking: bool = True
    """Whether the source marks obstacles. Nav2 default true."""
    footprint_clearing_enabled: bool = True
    """Clear the cells under the robot footprint each update. Nav2 default true."""


def _union(a: Bounds | None, b: Bounds | None) -> Bounds | None:
    if a is None:
        return b
    if b is None:
        return a
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


def _bounds_of(rows: np.ndarray, cols: np.ndarray) -> Bounds | None:
    if rows.size == 0:
        return None
    return (int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1)


@njit(cache=True, nogil=True)
def _beam_segments(
    pts: np.ndarray, far_pts: np.ndarray, x0: float, y0: float, ranges: np.ndarray, grid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clearing segments in cell units (rows of x0, y0, x1, y1), whether each was clipped at
    ``raytrace_max_range`` and whether it is a beam without return, for the finite returns then
    the finite no-return points: the numpy path's arithmetic, one beam at a time."""
    n = pts.shape[0] + far_pts.shape[0]
    seg = np.empty((n, 4))
    clipped = np.empty(n, dtype=np.bool_)
    no_return = np.empty(n, dtype=np.bool_)
    lo, hi = ranges[0], ranges[1]
    ox, oy, res = grid[0], grid[1], grid[2]
    k = 0
    for i in range(n):
        x = pts[i, 0] if i < pts.shape[0] else far_pts[i - pts.shape[0], 0]
        y = pts[i, 1] if i < pts.shape[0] else far_pts[i - pts.shape[0], 1]
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        dx, dy = x - x0, y - y0
        dist = math.hypot(dx, dy)
        if not dist > max(lo, 1e-9):
            continue
        ux, uy = dx / dist, dy / dist
        reach = min(dist, hi)
        seg[k, 0] = (x0 + ux * lo - ox) / res
        seg[k, 1] = (y0 + uy * lo - oy) / res
        seg[k, 2] = (x0 + ux * reach - ox) / res
        seg[k, 3] = (y0 + uy * reach - oy) / res
        clipped[k] = dist > hi
        no_return[k] = i >= pts.shape[0]
        k += 1
    return seg[:k], clipped[:k], no_return[:k]


@njit(cache=True, nogil=True)
def _apply_scan(
    costs: np.ndarray,
    pts: np.ndarray,
    far_pts: np.ndarray,
    x0: float,
    y0: float,
    ranges: np.ndarray,
    grid: np.ndarray,
    clearing: bool,
    marking: bool,
    stamp: np.ndarray,
    now: float,
) -> np.ndarray:
    """``ObstacleLayer.update`` on an axis-aligned grid: clear every beam (``_clear``), then mark
    the finite returns within the obstacle range. ``ranges``: raytrace min/max, obstacle min/max;
    ``grid``: origin x, y and resolution. Returns the written bounds (row0, row1, col0, col1),
    inclusive, row1 < 0 when nothing was written."""
    h, w = costs.shape
    bounds = np.array([h, -1, w, -1], dtype=np.int64)
    if clearing:
        seg, clipped, no_return = _beam_segments(pts, far_pts, x0, y0, ranges, grid)
        if seg.shape[0]:
            bounds = _clear(
                costs, seg, np.uint8(FREE_SPACE), clipped, no_return, np.uint8(LETHAL_OBSTACLE), stamp, now
            )
    if marking:
        ox, oy, res = grid[0], grid[1], grid[2]
        for i in range(pts.shape[0]):
            x, y = pts[i, 0], pts[i, 1]
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            dist = math.hypot(x - x0, y - y0)
            if not (ranges[2] <= dist <= ranges[3]):
                continue
            c = math.floor((x - ox) / res)
            r = math.floor((y - oy) / res)
            if 0 <= r < h and 0 <= c < w:
                costs[r, c] = LETHAL_OBSTACLE
                if stamp.shape[0]:
                    stamp[r, c] = now
                bounds[0], bounds[1] = min(bounds[0], r), max(bounds[1], r)
                bounds[2], bounds[3] = min(bounds[2], c), max(bounds[3], c)
    return bounds


class ObstacleLayer:
    """Per-cell obstacle state over a grid: LETHAL, FREE, or NO_INFORMATION when tracking unknown.

    With ``keep_stamps`` each cell also remembers when a beam (or the footprint) last observed it
    (``seen``, -inf never), so ``expire`` can return free cells not observed for a while to unknown:
    space seen long ago may no longer be free (issue 18, "never drive into space not seen")."""

    def __init__(
        self,
        geometry: GridGeometry,
        options: ObstacleLayerOptions | None = None,
        track_unknown_space: bool = False,
        keep_stamps: bool = False,
    ) -> None:
        self.geometry = geometry
        self.options = options or ObstacleLayerOptions()
        self.default_value = NO_INFORMATION if track_unknown_space else FREE_SPACE
        self.costs = np.full((geometry.height, geometry.width), self.default_value, dtype=np.uint8)
        self.seen = np.full(self.costs.shape, -np.inf) if keep_stamps else NO_STAMP
        self.now = 0.0
        """Time stamped on the cells the next updates observe (``Costmap2D.update``'s ``stamp``)."""

    def reset(self) -> None:
        """Forget every observation (Nav2 ``ObstacleLayer::reset``; the clear-costmap behaviour)."""
        self.costs.fill(self.default_value)
        self.seen.fill(-np.inf)

    def expire(self, max_age: float) -> Bounds | None:
        """Return FREE cells last observed more than ``max_age`` s before ``now`` to the default
        value (unknown when tracking it); vectorized over the grid. Returns the changed bounds."""
        if not self.seen.shape[0] or self.default_value == FREE_SPACE:
            return None
        stale = (self.seen < self.now - max_age) & (self.costs == FREE_SPACE)
        rows, cols = np.nonzero(stale)
        self.costs[rows, cols] = self.default_value
        return _bounds_of(rows, cols)

    def set_geometry(self, geometry: GridGeometry) -> None:
        """Move the grid to a new origin (same resolution and size), keeping the overlapping cells,
        as Nav2 ``Costmap2D::updateOrigin`` does for rolling windows. Origins must differ by whole cells."""
        old = self.geometry
        res = old.resolution
        dc = round((geometry.origin.x - old.origin.x) / res)
        dr = round((geometry.origin.y - old.origin.y) / res)
        h, w = self.costs.shape
        src_r0, src_c0 = max(dr, 0), max(dc, 0)
        dst_r0, dst_c0 = max(-dr, 0), max(-dc, 0)
        nr, nc = h - abs(dr), w - abs(dc)

        def shifted(old_grid: np.ndarray, fill: float) -> np.ndarray:
            new = np.full(old_grid.shape, fill, dtype=old_grid.dtype)
            if nr > 0 and nc > 0:
                new[dst_r0 : dst_r0 + nr, dst_c0 : dst_c0 + nc] = old_grid[
                    src_r0 : src_r0 + nr, src_c0 : src_c0 + nc
                ]
            return new

        self.costs = shifted(self.costs, self.default_value)
        if self.seen.shape[0]:
            self.seen = shifted(self.seen, -np.inf)
        self.geometry = geometry

    def clear_cells(self, rows: np.ndarray, cols: np.ndarray) -> Bounds | None:
        """Set cells to FREE (footprint clearing); they count as observed now."""
        self.costs[rows, cols] = FREE_SPACE
        if self.seen.shape[0]:
            self.seen[rows, cols] = self.now
        return _bounds_of(rows, cols)

    def update(
        self, points: np.ndarray, sensor_origin: np.ndarray, no_return_points: np.ndarray | None = None
    ) -> Bounds | None:
        """Apply one scan: (N, 2) world-frame returns seen from ``sensor_origin`` (2,), plus optional
        (M, 2) far points of beams without a return (cleared, never marked). Returns the changed bounds."""
        o = self.options
        geo = self.geometry
        origin = np.asarray(sensor_origin, dtype=float).reshape(2)
        if geo.origin.theta != 0.0:
            return self._update_numpy(points, origin, no_return_points)
        # the usual axis-aligned grid: one compiled pass, the same arithmetic as _update_numpy
        far_pts = np.zeros((0, 2)) if no_return_points is None else no_return_points
        b = _apply_scan(
            self.costs,
            np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2),
            np.ascontiguousarray(far_pts, dtype=np.float64).reshape(-1, 2),
            float(origin[0]),
            float(origin[1]),
            np.array(
                [o.raytrace_min_range, o.raytrace_max_range, o.obstacle_min_range, o.obstacle_max_range]
            ),
            np.array([geo.origin.x, geo.origin.y, geo.resolution]),
            o.clearing,
            o.marking,
            self.seen,
            float(self.now),
        )
        return None if b[1] < 0 else (int(b[0]), int(b[1]) + 1, int(b[2]), int(b[3]) + 1)

    def _update_numpy(
        self, points: np.ndarray, origin: np.ndarray, no_return_points: np.ndarray | None
    ) -> Bounds | None:
        """``update`` for any grid (also a rotated one), in numpy."""
        o = self.options
        geo = self.geometry
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        bounds: Bounds | None = None
        if o.clearing:
            ends = pts
            if no_return_points is not None:
                far_pts = np.asarray(no_return_points, dtype=float).reshape(-1, 2)
                ends = np.vstack((pts, far_pts[np.isfinite(far_pts).all(axis=1)]))
            if ends.shape[0]:
                no_return = np.arange(ends.shape[0]) >= pts.shape[0]
                d = ends - origin
                dist = np.hypot(d[:, 0], d[:, 1])
                ok = dist > max(o.raytrace_min_range, 1e-9)
                d, dist, no_return = d[ok], dist[ok], no_return[ok]
                unit = d / dist[:, None]
                far = origin + unit * np.minimum(dist, o.raytrace_max_range)[:, None]
                near = origin + unit * o.raytrace_min_range
                # A beam clipped at raytrace_max_range clears its last cell too (it holds no return).
                # One compiled pass for all beams: every write is FREE, so the order cannot matter.
                clipped = dist > o.raytrace_max_range
                if clipped.size:
                    bounds = _union(
                        bounds,
                        clear_segments(
                            self.costs,
                            geo,
                            near,
                            far,
                            FREE_SPACE,
                            clipped,
                            LETHAL_OBSTACLE,
                            no_return,
                            stamp=self.seen if self.seen.shape[0] else None,
                            now=self.now,
                        ),
                    )
        if o.marking and pts.shape[0]:
            d = pts - origin
            dist = np.hypot(d[:, 0], d[:, 1])
            keep = (dist <= o.obstacle_max_range) & (dist >= o.obstacle_min_range)
            rows, cols = geo.world_to_cell(pts[keep])
            inside = geo.in_bounds(rows, cols)
            rows, cols = rows[inside], cols[inside]
            self.costs[rows, cols] = LETHAL_OBSTACLE
            if self.seen.shape[0]:
                self.seen[rows, cols] = self.now
            bounds = _union(bounds, _bounds_of(rows, cols))
        return bounds
