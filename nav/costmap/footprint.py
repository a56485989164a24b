"""Robot footprints and their costs over many poses (Nav2 ``FootprintCollisionChecker``).

Nav2 scores a polygon footprint by the highest cost on its outline (the inflation layer already
covers the interior's clearance) and a circular robot by the cost of its centre cell (inflation by
the inscribed radius makes that exact). Here the outline is sampled once in the robot frame at half
the costmap resolution, and all poses are transformed and looked up in one numpy expression, which
is what DWA needs to score every sampled trajectory each control cycle.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nav.types import Costmap, GridGeometry


def circle_footprint(radius: float, n: int = 16) -> np.ndarray:
    """A regular n-gon (K, 2) approximating a circular robot, in base_link."""
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack((radius * np.cos(a), radius * np.sin(a)))


def footprint_radii(polygon: np.ndarray) -> tuple[float, float]:
    """(inscribed, circumscribed) radii of a footprint polygon about base_link's origin, as Nav2's
    ``calculateMinAndMaxDistances``: nearest edge distance and farthest vertex distance."""
    p = np.asarray(polygon, dtype=float).reshape(-1, 2)
    q = np.roll(p, -1, axis=0)
    d = q - p
    len2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    t = np.clip(-np.einsum("ij,ij->i", p, d) / len2, 0.0, 1.0)
    closest = p + t[:, None] * d
    inscribed = float(np.min(np.hypot(closest[:, 0], closest[:, 1])))
    circumscribed = float(np.max(np.hypot(p[:, 0], p[:, 1])))
    return inscribed, circumscribed


def outline_points(polygon: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the closed polygon outline, at most ``spacing`` apart (vertices included)."""
    p = np.asarray(polygon, dtype=float).reshape(-1, 2)
    q = np.roll(p, -1, axis=0)
    seg = np.hypot(*(q - p).T)
    n = np.maximum(np.ceil(seg / spacing).astype(np.int64), 1)
    idx = np.repeat(np.arange(p.shape[0]), n)
    t = (np.arange(idx.size) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    return p[idx] + (q - p)[idx] * t[:, None]


def poses_array(poses: np.ndarray) -> np.ndarray:
    """Accept (3,) or (M, 3) x, y, theta; return (M, 3) float."""
    return np.asarray(poses, dtype=float).reshape(-1, 3)


def footprint_cost(costmap: Costmap, poses: np.ndarray, footprint: np.ndarray | None = None) -> np.ndarray:
    """Highest cost of the footprint at each of (M, 3) poses, as (M,) uint8.

    ``footprint`` is a (K, 2) polygon in base_link; ``None`` scores a circular robot by its centre
    cell. Cells off the map read NO_INFORMATION (255), which is higher than lethal, so callers that
    treat unknown as passable must test for it explicitly.
    """
    pz = poses_array(poses)
    if footprint is None or len(footprint) == 0:
        return costmap.cost_at(pz[:, :2])
    pts = outline_points(footprint, 0.5 * costmap.geometry.resolution)
    c, s = np.cos(pz[:, 2])[:, None], np.sin(pz[:, 2])[:, None]
    wx = pz[:, 0:1] + c * pts[None, :, 0] - s * pts[None, :, 1]
    wy = pz[:, 1:2] + s * pts[None, :, 0] + c * pts[None, :, 1]
    costs = costmap.cost_at(np.column_stack((wx.ravel(), wy.ravel()))).reshape(wx.shape)
    return costs.max(axis=1).astype(np.uint8)


@njit(cache=True, nogil=True)
def _cells_inside(
    poly: np.ndarray, r0: int, r1: int, c0: int, c1: int, res: float, ox: float, oy: float
) -> tuple[np.ndarray, np.ndarray]:
    """``cells_in_polygon`` over rows r0..r1-1, cols c0..c1-1 of an axis-aligned grid: the same
    crossing-number arithmetic per cell centre, without the (cells x edges) temporaries."""
    n = poly.shape[0]
    rows = np.empty((r1 - r0) * (c1 - c0), dtype=np.int64)
    cols = np.empty_like(rows)
    k = 0
    for r in range(r0, r1):
        y = (r + 0.5) * res + oy
        for c in range(c0, c1):
            x = (c + 0.5) * res + ox
            count = 0
            for e in range(n):
                ax, ay = poly[e, 0], poly[e, 1]
                bx, by = poly[(e + 1) % n, 0], poly[(e + 1) % n, 1]
                if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
                    count += 1
            if count % 2 == 1:
                rows[k], cols[k] = r, c
                k += 1
    return rows[:k], cols[:k]


def cells_in_polygon(geo: GridGeometry, polygon_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of grid cells whose centres lie inside a world-frame polygon (crossing-number
    test vectorized over the polygon's bounding box); used for footprint clearing."""
    poly = np.asarray(polygon_world, dtype=float).reshape(-1, 2)
    rows, cols = geo.world_to_cell(poly)
    r0, r1 = max(int(rows.min()) - 1, 0), min(int(rows.max()) + 2, geo.height)
    c0, c1 = max(int(cols.min()) - 1, 0), min(int(cols.max()) + 2, geo.width)
    if r0 >= r1 or c0 >= c1:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    if geo.origin.theta == 0.0:  # the usual axis-aligned grid: one compiled pass over the box
        return _cells_inside(poly, r0, r1, c0, c1, geo.resolution, geo.origin.x, geo.origin.y)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    rr, cc = rr.ravel(), cc.ravel()
    xy = geo.cell_to_world(rr, cc)
    x, y = xy[:, 0:1], xy[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (
            b[None, :, 1] - a[None, :, 1]
        )
    inside = (np.count_nonzero(crosses & (x < xint), axis=1) % 2) == 1
    return rr[inside], cc[inside]


__all__ = [
    "cells_in_polygon",
    "circle_footprint",
    "footprint_cost",
    "footprint_radii",
    "outline_points",
]
