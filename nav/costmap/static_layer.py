"""Static layer: an occupancy map turned into costs, as Nav2's ``nav2_costmap_2d::StaticLayer``.

``interpretValue`` (Nav2): unknown (-1) -> NO_INFORMATION when ``track_unknown_space`` else FREE;
occupancy >= ``lethal_cost_threshold`` -> LETHAL; anything else -> FREE with ``trinary_costmap``,
otherwise scaled linearly ``value / lethal_cost_threshold * 254``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.types import FREE_SPACE, LETHAL_OBSTACLE, NO_INFORMATION, GridGeometry, OccupancyGrid


@dataclass(frozen=True)
class StaticLayerOptions:
    """Nav2 ``StaticLayer`` / layered-costmap parameters."""

    lethal_cost_threshold: int = 100
    """Occupancy (0..100) at or above which a cell is lethal. Nav2 default 100 (map_server already
    thresholds trinary maps to 0/100/-1)."""
    trinary_costmap: bool = True
    """Non-lethal known cells are free (else scaled by occupancy). Nav2 default true."""
    unknown_cost_value: int = -1
    """The map value that means unknown. Nav2 default -1."""


def static_costs(
    grid: OccupancyGrid, options: StaticLayerOptions | None = None, *, track_unknown_space: bool = True
) -> np.ndarray:
    """(H, W) uint8 costs of an occupancy grid, vectorized ``interpretValue``; unknown cells become
    NO_INFORMATION when ``track_unknown_space`` (the costmap-level Nav2 parameter), else free."""
    o = options or StaticLayerOptions()
    v = grid.data.astype(np.int16)
    unknown = v == o.unknown_cost_value
    lethal = (v >= o.lethal_cost_threshold) & ~unknown
    if o.trinary_costmap:
        out = np.full(v.shape, FREE_SPACE, dtype=np.uint8)
    else:
        scaled = np.clip(v, 0, None) / float(o.lethal_cost_threshold) * LETHAL_OBSTACLE
        out = np.clip(scaled, 0, LETHAL_OBSTACLE).astype(np.uint8)
    out[lethal] = LETHAL_OBSTACLE
    out[unknown] = NO_INFORMATION if track_unknown_space else FREE_SPACE
    return out


def sample_costs(static: np.ndarray, static_geometry: GridGeometry, target: GridGeometry) -> np.ndarray:
    """Static costs looked up at the cell centres of another grid (the rolling window): nearest cell,
    NO_INFORMATION off the static map."""
    shift = _cell_shift(static_geometry, target)
    if shift is not None:  # the rolling window's usual case: a whole-cell offset, so a slice copy
        dr, dc = shift
        out = np.full((target.height, target.width), NO_INFORMATION, dtype=np.uint8)
        sr0, sr1 = max(dr, 0), min(dr + target.height, static_geometry.height)
        sc0, sc1 = max(dc, 0), min(dc + target.width, static_geometry.width)
        if sr1 > sr0 and sc1 > sc0:
            out[sr0 - dr : sr1 - dr, sc0 - dc : sc1 - dc] = static[sr0:sr1, sc0:sc1]
        return out
    rr, cc = np.mgrid[0 : target.height, 0 : target.width]
    xy = target.cell_to_world(rr.ravel(), cc.ravel())
    rows, cols = static_geometry.world_to_cell(xy)
    inside = static_geometry.in_bounds(rows, cols)
    out = np.full(rows.shape, NO_INFORMATION, dtype=np.uint8)
    out[inside] = static[rows[inside], cols[inside]]
    return out.reshape(target.height, target.width)


def _cell_shift(static_geometry: GridGeometry, target: GridGeometry) -> tuple[int, int] | None:
    """(rows, cols) of the target's cell (0, 0) in the static grid when both are axis-aligned with
    the same resolution and their origins differ by whole cells (to well under half a cell, so each
    target cell centre falls in exactly that static cell); None otherwise."""
    a, b = static_geometry.origin, target.origin
    if a.theta != 0.0 or b.theta != 0.0 or static_geometry.resolution != target.resolution:
        return None
    fc = (b.x - a.x) / target.resolution
    fr = (b.y - a.y) / target.resolution
    dc, dr = round(fc), round(fr)
    if abs(fc - dc) > 1e-3 or abs(fr - dr) > 1e-3:
        return None
    return int(dr), int(dc)
