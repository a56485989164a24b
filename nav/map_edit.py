"""Map edits: brush strokes, polygons and line walls setting cells free, occupied or unknown.

An edit is a list of operations applied in order to a copy of an occupancy grid (nav_msgs values:
0 free, 100 occupied, -1 unknown). Every operation becomes a boolean mask over a bounding box of
cell centres, vectorized (polygons by ``nav.costmap.filter_layer``'s scanline, discs and line walls
by distance to the stroke), so a 10,000-cell edit on a 2000 x 2000 map costs a few ms.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from nav.costmap.filter_layer import rasterize_polygons
from nav.types import GridGeometry, OccupancyGrid

CellValue = Literal["free", "occupied", "unknown"]
VALUES: dict[str, int] = {"free": 0, "occupied": 100, "unknown": -1}

Bounds = tuple[int, int, int, int]
"""(r0, r1, c0, c1), half-open cell bounds."""


class EditError(ValueError):
    """An operation that cannot be applied (bad geometry); the message says why."""


@dataclass(frozen=True)
class Stroke:
    """A brush stroke (``radius`` > 0) or a line wall (``radius`` = half its width) through points."""

    points: np.ndarray  # (N, 2) map frame, metres
    radius: float
    value: CellValue


@dataclass(frozen=True)
class Fill:
    """A polygon filled with one value (erase a region: ``unknown`` or ``free``)."""

    polygon: np.ndarray  # (K, 2)
    value: CellValue


Operation = Stroke | Fill


def _grid_xy(geometry: GridGeometry, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
    """Map-frame x, y of the cell centres of a block, (r1 - r0, c1 - c0) each."""
    rr, cc = np.mgrid[r0:r1, c0:c1]
    xy = geometry.cell_to_world(rr.ravel(), cc.ravel())
    return xy[:, 0].reshape(rr.shape), xy[:, 1].reshape(rr.shape)


def _stroke_mask(geometry: GridGeometry, stroke: Stroke) -> tuple[Bounds, np.ndarray] | None:
    pts = np.asarray(stroke.points, dtype=float).reshape(-1, 2)
    if len(pts) == 0 or not np.isfinite(pts).all() or not stroke.radius > 0:
        raise EditError("a stroke needs finite points and a positive radius")
    rows, cols = geometry.world_to_cell(pts)
    pad = int(np.ceil(stroke.radius / geometry.resolution)) + 1
    r0, r1 = max(int(rows.min()) - pad, 0), min(int(rows.max()) + pad + 1, geometry.height)
    c0, c1 = max(int(cols.min()) - pad, 0), min(int(cols.max()) + pad + 1, geometry.width)
    if r1 <= r0 or c1 <= c0:
        return None
    x, y = _grid_xy(geometry, r0, r1, c0, c1)
    mask = np.zeros(x.shape, dtype=bool)
    r2 = stroke.radius * stroke.radius
    segs = [(pts[i], pts[i + 1]) for i in range(len(pts) - 1)] or [(pts[0], pts[0])]
    for a, b in segs:  # per segment of the stroke (a handful), each vectorized over the block
        d = b - a
        n2 = float(d @ d)
        t = np.zeros(x.shape) if n2 == 0 else np.clip(((x - a[0]) * d[0] + (y - a[1]) * d[1]) / n2, 0.0, 1.0)
        mask |= (x - a[0] - t * d[0]) ** 2 + (y - a[1] - t * d[1]) ** 2 <= r2
    return (r0, r1, c0, c1), mask


def apply_edits(grid: OccupancyGrid, operations: list[Operation]) -> tuple[OccupancyGrid, Bounds | None, int]:
    """A new grid with ``operations`` applied in order, the bounds of the changed cells (None if none)
    and how many cells changed."""
    geo = grid.geometry
    data = grid.data.copy()
    for op in operations:
        value = VALUES[op.value]
        if isinstance(op, Fill):
            data[rasterize_polygons([np.asarray(op.polygon, dtype=float)], geo)] = value
            continue
        got = _stroke_mask(geo, op)
        if got is not None:
            (r0, r1, c0, c1), mask = got
            data[r0:r1, c0:c1][mask] = value
    changed = data != grid.data
    n = int(changed.sum())
    if n == 0:
        return OccupancyGrid(geo, data), None, 0
    rows = np.flatnonzero(changed.any(axis=1))
    cols = np.flatnonzero(changed.any(axis=0))
    return OccupancyGrid(geo, data), (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1), n
