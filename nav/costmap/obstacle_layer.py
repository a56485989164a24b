"""Obstacle layer: lidar returns marked as lethal, free space cleared along each beam, as Nav2's
``nav2_costmap_2d::ObstacleLayer`` (``raytraceFreespace`` then marking, per observation).

Clearing walks every beam's cells with ``nav.costmap.raytrace.clear_segments`` (Amanatides & Woo
supercover, compiled; the cells ``nav.raycast.traversed_cells`` lists), stopping before the cell
that holds the return (Nav2's Bresenham also stops one cell short) and at
``raytrace_max_range``; marking sets the cells of returns within
``obstacle_max_range`` to LETHAL. Clearing runs before marking, so a return always survives its own
scan, and the layer keeps its state between scans (obstacles persist until a beam passes through).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.costmap.raytrace import clear_segments
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


class ObstacleLayer:
    """Per-cell obstacle state over a grid: LETHAL, FREE, or NO_INFORMATION when tracking unknown."""

    def __init__(
        self,
        geometry: GridGeometry,
        options: ObstacleLayerOptions | None = None,
        track_unknown_space: bool = False,
    ) -> None:
        self.geometry = geometry
        self.options = options or ObstacleLayerOptions()
        self.default_value = NO_INFORMATION if track_unknown_space else FREE_SPACE
        self.costs = np.full((geometry.height, geometry.width), self.default_value, dtype=np.uint8)

    def reset(self) -> None:
        """Forget every observation (Nav2 ``ObstacleLayer::reset``; the clear-costmap behaviour)."""
        self.costs.fill(self.default_value)

    def set_geometry(self, geometry: GridGeometry) -> None:
        """Move the grid to a new origin (same resolution and size), keeping the overlapping cells,
        as Nav2 ``Costmap2D::updateOrigin`` does for rolling windows. Origins must differ by whole cells."""
        old = self.geometry
        res = old.resolution
        dc = round((geometry.origin.x - old.origin.x) / res)
        dr = round((geometry.origin.y - old.origin.y) / res)
        h, w = self.costs.shape
        new = np.full((h, w), self.default_value, dtype=np.uint8)
        src_r0, src_c0 = max(dr, 0), max(dc, 0)
        dst_r0, dst_c0 = max(-dr, 0), max(-dc, 0)
        nr, nc = h - abs(dr), w - abs(dc)
        if nr > 0 and nc > 0:
            new[dst_r0 : dst_r0 + nr, dst_c0 : dst_c0 + nc] = self.costs[
                src_r0 : src_r0 + nr, src_c0 : src_c0 + nc
            ]
        self.costs = new
        self.geometry = geometry

    def clear_cells(self, rows: np.ndarray, cols: np.ndarray) -> Bounds | None:
        """Set cells to FREE (footprint clearing)."""
        self.costs[rows, cols] = FREE_SPACE
        return _bounds_of(rows, cols)

    def update(
        self, points: np.ndarray, sensor_origin: np.ndarray, no_return_points: np.ndarray | None = None
    ) -> Bounds | None:
        """Apply one scan: (N, 2) world-frame returns seen from ``sensor_origin`` (2,), plus optional
        (M, 2) far points of beams without a return (cleared, never marked). Returns the changed bounds."""
        o = self.options
        geo = self.geometry
        origin = np.asarray(sensor_origin, dtype=float).reshape(2)
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        bounds: Bounds | None = None
        if o.clearing:
            ends = pts
            if no_return_points is not None:
                far_pts = np.asarray(no_return_points, dtype=float).reshape(-1, 2)
                ends = np.vstack((pts, far_pts[np.isfinite(far_pts).all(axis=1)]))
            if ends.shape[0]:
                d = ends - origin
                dist = np.hypot(d[:, 0], d[:, 1])
                ok = dist > max(o.raytrace_min_range, 1e-9)
                d, dist = d[ok], dist[ok]
                unit = d / dist[:, None]
                far = origin + unit * np.minimum(dist, o.raytrace_max_range)[:, None]
                near = origin + unit * o.raytrace_min_range
                # A beam clipped at raytrace_max_range clears its last cell too (it holds no return).
                clipped = dist > o.raytrace_max_range
                for sel, include_end in ((~clipped, False), (clipped, True)):
                    if sel.any():
                        b = clear_segments(self.costs, geo, near[sel], far[sel], FREE_SPACE, include_end)
                        bounds = _union(bounds, b)
        if o.marking and pts.shape[0]:
            d = pts - origin
            dist = np.hypot(d[:, 0], d[:, 1])
            keep = (dist <= o.obstacle_max_range) & (dist >= o.obstacle_min_range)
            rows, cols = geo.world_to_cell(pts[keep])
            inside = geo.in_bounds(rows, cols)
            rows, cols = rows[inside], cols[inside]
            self.costs[rows, cols] = LETHAL_OBSTACLE
            bounds = _union(bounds, _bounds_of(rows, cols))
        return bounds
