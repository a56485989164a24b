"""Costmap filter masks from polygons (Nav2 costmap filters: KeepoutFilter, SpeedFilter).

Zones are polygons in the map frame. ``validate_polygon`` says what is wrong with one (too few
points, a self-intersection, a vertex off the map); ``rasterize_polygons`` turns polygons into a
boolean mask over the cell centres of a grid by the even-odd rule, with a vectorized scanline:
every edge toggles, on each row it crosses, the cells right of its crossing; a cumulative sum along
the row then counts crossings left of each centre. Work is O(edges x rows spanned) + O(cells in the
polygons' bounding box), with no per-cell Python loop, so a zone on a 2000 x 2000 map takes a few ms.

``points_in_polygon`` is the same rule for a few points (the robot's position every tick).
"""

from __future__ import annotations

import numpy as np

from nav.types import GridGeometry

MAX_VERTICES = 1000
"""A zone's vertex limit: the self-intersection test is O(n^2) and the UI draws far fewer."""


class PolygonError(ValueError):
    """An invalid zone polygon; the message says why."""


def _grid_frame(points: np.ndarray, geometry: GridGeometry) -> np.ndarray:
    """Map-frame points in the grid's own frame (origin at the lower-left corner, axes along the
    rows and columns), so a rotated map origin needs no special case."""
    o = geometry.origin
    c, s = np.cos(o.theta), np.sin(o.theta)
    d = np.asarray(points, dtype=float) - np.array([o.x, o.y])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))


def _segments_cross(p: np.ndarray) -> tuple[int, int] | None:
    """The first pair of non-adjacent edges of closed polygon ``p`` (N, 2) that touch or cross, by
    orientation signs over all edge pairs at once; None for a simple polygon."""
    n = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # the closing edge is adjacent to the first one
    i, j = i[keep], j[keep]

    def orient(p0, p1, q):
        return np.sign(
            (p1[:, 0] - p0[:, 0]) * (q[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (q[:, 0] - p0[:, 0])
        )

    o1 = orient(a[i], b[i], a[j])
    o2 = orient(a[i], b[i], b[j])
    o3 = orient(a[j], b[j], a[i])
    o4 = orient(a[j], b[j], b[i])
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)

    def on_segment(p0, p1, q, o):  # collinear q within the bounding box of p0-p1
        return (
            (o == 0)
            & (np.minimum(p0[:, 0], p1[:, 0]) <= q[:, 0])
            & (q[:, 0] <= np.maximum(p0[:, 0], p1[:, 0]))
            & (np.minimum(p0[:, 1], p1[:, 1]) <= q[:, 1])
            & (q[:, 1] <= np.maximum(p0[:, 1], p1[:, 1]))
        )

    touch = (
        on_segment(a[i], b[i], a[j], o1)
        | on_segment(a[i], b[i], b[j], o2)
        | on_segment(a[j], b[j], a[i], o3)
        | on_segment(a[j], b[j], b[i], o4)
    )
    hit = np.flatnonzero(proper | touch)
    return None if hit.size == 0 else (int(i[hit[0]]), int(j[hit[0]]))


def validate_polygon(points: object, geometry: GridGeometry | None = None) -> np.ndarray:
    """The polygon as (N, 2) float, or ``PolygonError``: fewer than 3 distinct vertices, more than
    ``MAX_VERTICES``, non-finite values, zero area, edges that cross or touch, or (with ``geometry``)
    a vertex off the map. A repeated closing vertex (first == last) is dropped."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise PolygonError("a polygon is a list of [x, y] vertices")
    if not np.isfinite(p).all():
        raise PolygonError("polygon vertices must be finite numbers")
    if len(p) >= 2 and np.array_equal(p[0], p[-1]):
        p = p[:-1]
    if len(p) < 3:
        raise PolygonError(f"a polygon needs at least 3 vertices, got {len(p)}")
    if len(p) > MAX_VERTICES:
        raise PolygonError(f"a polygon has at most {MAX_VERTICES} vertices, got {len(p)}")
    if np.any(np.all(p == np.roll(p, -1, axis=0), axis=1)):
        raise PolygonError("two consecutive vertices are equal")
    crossing = _segments_cross(p)
    if crossing is not None:
        e0, e1 = crossing
        raise PolygonError(f"the polygon intersects itself (edges {e0} and {e1})")
    x, y = p[:, 0], p[:, 1]
    area = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    if abs(area) < 1e-12:
        raise PolygonError("the polygon has no area")
    if geometry is not None:
        g = _grid_frame(p, geometry)
        w, h = geometry.size_m
        off = (g[:, 0] < -1e-9) | (g[:, 1] < -1e-9) | (g[:, 0] > w + 1e-9) | (g[:, 1] > h + 1e-9)
        if off.any():
            k = int(np.flatnonzero(off)[0])
            where = f"({p[k, 0]:.3f}, {p[k, 1]:.3f})"
            raise PolygonError(f"vertex {k} {where} is off the map ({w:.2f} x {h:.2f} m from its origin)")
    return p


def rasterize_polygons(polygons: list[np.ndarray], geometry: GridGeometry) -> np.ndarray:
    """(H, W) bool: cells whose centre lies inside any of ``polygons`` (map frame), even-odd rule
    per polygon. Polygons are OR-ed (a cell in two overlapping zones is still in a zone)."""
    mask = np.zeros((geometry.height, geometry.width), dtype=bool)
    for poly in polygons:
        r0, r1, c0, c1, inside = _rasterize_one(np.asarray(poly, dtype=float), geometry)
        if inside is not None:
            mask[r0:r1, c0:c1] |= inside
    return mask


def _cell_bounds(g: np.ndarray, geometry: GridGeometry) -> tuple[int, int, int, int] | None:
    res = geometry.resolution
    r0 = max(int(np.floor(g[:, 1].min() / res)), 0)
    r1 = min(int(np.ceil(g[:, 1].max() / res)) + 1, geometry.height)
    c0 = max(int(np.floor(g[:, 0].min() / res)), 0)
    c1 = min(int(np.ceil(g[:, 0].max() / res)) + 1, geometry.width)
    return None if r1 <= r0 or c1 <= c0 else (r0, r1, c0, c1)


def _rasterize_one(poly: np.ndarray, geometry: GridGeometry) -> tuple[int, int, int, int, np.ndarray | None]:
    g = _grid_frame(poly, geometry)
    bounds = _cell_bounds(g, geometry)
    if bounds is None:
        return 0, 0, 0, 0, None
    r0, r1, c0, c1 = bounds
    res = geometry.resolution
    x0, y0 = g[:, 0], g[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    # rows whose centre y each edge crosses: half-open (ymin <= cy < ymax), so a vertex on a row's
    # centre line is counted once, and horizontal edges never
    lo = np.maximum(np.ceil(np.minimum(y0, y1) / res - 0.5).astype(np.int64), r0)
    hi = np.minimum(np.ceil(np.maximum(y0, y1) / res - 0.5).astype(np.int64), r1)  # exclusive
    counts = np.maximum(hi - lo, 0)
    total = int(counts.sum())
    toggles = np.zeros((r1 - r0, c1 - c0 + 1), dtype=np.int32)
    if total:
        edge = np.repeat(np.arange(len(g)), counts)
        start = np.repeat(np.cumsum(counts) - counts, counts)
        rows = np.repeat(lo, counts) + (np.arange(total) - start)
        cy = (rows + 0.5) * res
        t = (cy - y0[edge]) / (y1[edge] - y0[edge])
        xc = x0[edge] + t * (x1[edge] - x0[edge])
        # first column whose centre lies right of the crossing
        col = np.floor(xc / res - 0.5).astype(np.int64) + 1
        col = np.clip(col, c0, c1) - c0
        np.add.at(toggles, (rows - r0, col), 1)
    inside = (np.cumsum(toggles[:, :-1], axis=1) & 1).astype(bool)
    return r0, r1, c0, c1, inside


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(N,) bool: which of (N, 2) points lie inside ``polygon`` (even-odd crossing test)."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    poly = np.asarray(polygon, dtype=float)
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    px, py = pts[:, :1], pts[:, 1:2]
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    return ((straddle & (px < xc)).sum(axis=1) & 1).astype(bool)
