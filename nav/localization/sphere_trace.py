"""Exact ray casting by sphere tracing on a clearance table, for the beam model's expected ranges.

A ray from a point jumps straight ahead by a lower bound of the distance from that point to any
occupied cell (nothing occupied can lie closer, so nothing is jumped over), and near obstacles,
where the bound is too small to pay, walks cell by cell (Amanatides & Woo 1987) until it enters an
occupied cell or reaches open space again. The bound per cell is the Euclidean distance transform
between cell centres minus one cell diagonal (from any point of the cell to any point of an
occupied one), uncapped, so a ray crosses a room in a jump or two. The result is the entry
distance of the first occupied cell on the ray, as ``nav.raycast.march_ray``'s column walk gives
it (tests compare both and the numpy reference); only the arithmetic of a boundary crossing differs
(a few ulps). ``nav.raycast`` is left to the simulated lidar and the costmaps.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

from nav.raycast import _to_local, occupancy_mask
from nav.types import GridGeometry

BLOCKED = np.float32(-1.0)  # the clearance table's value for an occupied cell
# A jump shorter than this (cells) costs more than the cell steps it saves; the walk then steps
# cell by cell until a cell offers at least WALK_EXIT again.
JUMP_MIN = 1.0
WALK_EXIT = 2.0


@njit(cache=True, nogil=True, inline="always")
def ray_span(
    width: int, height: int, u0: float, v0: float, du: float, dv: float, t_max: float
) -> tuple[float, float]:
    """(t_lo, t_hi): the part of a ray within ``t_max`` inside the grid's box [0, width] x [0,
    height] (slab test), empty if t_lo > t_hi. The grid is convex: a ray that leaves it never
    comes back, and off it every cell is free. A NaN or infinite origin or direction has an
    empty span: the walk must never index the table with one."""
    if not (math.isfinite(u0) and math.isfinite(v0) and math.isfinite(du) and math.isfinite(dv)):
        return np.inf, -np.inf
    t_lo, t_hi = 0.0, t_max
    if du != 0.0:
        ta, tb = -u0 / du, (width - u0) / du
        t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
    elif u0 < 0.0 or u0 > width:
        return np.inf, -np.inf
    if dv != 0.0:
        ta, tb = -v0 / dv, (height - v0) / dv
        t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
    elif v0 < 0.0 or v0 > height:
        return np.inf, -np.inf
    return t_lo, t_hi


@njit(cache=True, nogil=True)
def trace_from(
    clear: np.ndarray, stride: int, u0: float, v0: float, du: float, dv: float, t: float, t_hi: float
) -> float:
    """A ray (grid-local cell units, origin (u0, v0), unit direction (du, dv)) from the point at
    ``t`` inside its span, with nothing occupied before it: the entry distance of the first
    occupied cell, ``t`` itself if that point is in one, inf if none is entered by ``t_hi``.
    ``clear`` is the flat padded table (one free cell of border, ``stride`` = width + 2):
    ``BLOCKED`` or a clearance lower bound in cells."""
    inv_du = 1.0 / du if du != 0.0 else np.inf
    inv_dv = 1.0 / dv if dv != 0.0 else np.inf
    sx = 1 if du > 0.0 else -1
    sy = stride if dv > 0.0 else -stride
    dtx, dty = abs(inv_du), abs(inv_dv)
    u1, v1 = u0 + 1.0, v0 + 1.0  # shifted by the table's border
    while True:
        # the padded table's cell of a point inside [0, width] x [0, height] (up to rounding, so
        # > -1): truncation of the shifted coordinate is its floor
        px = int(u1 + t * du)
        py = int(v1 + t * dv)
        cell = py * stride + px
        c = clear[cell]
        if c >= JUMP_MIN:
            t += c
            if t > t_hi:
                return np.inf
            continue
        if c < 0.0:  # the origin (or the grid's edge where the ray enters) is in an occupied cell
            return t
        # cell by cell: the times the ray crosses its next column and row boundaries
        tx = ((px - (0 if du > 0.0 else 1)) - u0) * inv_du if du != 0.0 else np.inf
        ty = ((py - (0 if dv > 0.0 else 1)) - v0) * inv_dv if dv != 0.0 else np.inf
        while True:
            # selects rather than a branch: which boundary comes next is a coin flip per step
            x_first = tx < ty
            t = min(tx, ty)
            cell += sx if x_first else sy
            tx = tx + dtx if x_first else tx
            ty = ty if x_first else ty + dty
            if t > t_hi:
                return np.inf
            c = clear[cell]
            if c < 0.0:
                return t
            if c >= WALK_EXIT:
                # jump from the crossing point, which the cell just entered bounds (re-finding its
                # cell by floor could pick the neighbour left behind and walk it again forever)
                t += c
                if t > t_hi:
                    return np.inf
                break


@njit(cache=True, nogil=True)
def trace_ray(
    clear: np.ndarray,
    stride: int,
    width: int,
    height: int,
    u0: float,
    v0: float,
    du: float,
    dv: float,
    t_max: float,
) -> float:
    """One ray in grid-local cell units (origin (u0, v0), unit direction (du, dv)): the entry
    distance of the first occupied cell, 0 from inside one, inf if none is entered within
    ``t_max``. Cells off the grid are free."""
    t_lo, t_hi = ray_span(width, height, u0, v0, du, dv, t_max)
    if t_lo > t_hi:
        return np.inf
    return trace_from(clear, stride, u0, v0, du, dv, t_lo, t_hi)


@njit(cache=True, nogil=True)
def trace_fan(
    clear: np.ndarray,
    stride: int,
    width: int,
    height: int,
    u0: float,
    v0: float,
    du: np.ndarray,
    dv: np.ndarray,
    t_max: float,
    t: np.ndarray,
    t_hi: np.ndarray,
    active: np.ndarray,
    out: np.ndarray,
) -> None:
    """``trace_ray`` for rays sharing an origin (directions ``du``, ``dv``) into ``out``; ``t``,
    ``t_hi`` and ``active`` are work arrays of the same length, reused across calls. The open
    space jumps of all rays go first, in rounds over the rays still jumping: one ray's jumps
    form a chain of dependent loads, and interleaving independent chains lets the CPU overlap
    them. Each ray then finishes alone (``trace_from``: the cell walk near the obstacle)."""
    n = 0
    for k in range(du.shape[0]):
        lo, hi = ray_span(width, height, u0, v0, du[k], dv[k], t_max)
        t[k], t_hi[k] = lo, hi
        active[n] = k
        n += lo <= hi
    u1, v1 = u0 + 1.0, v0 + 1.0
    while n > 0:
        m = 0
        for j in range(n):
            k = active[j]
            tk = t[k]
            c = clear[int(v1 + tk * dv[k]) * stride + int(u1 + tk * du[k])]
            go = c >= JUMP_MIN and tk + c <= t_hi[k]
            t[k] = tk + c if go else tk
            active[m] = k
            m += go
        n = m
    for k in range(du.shape[0]):
        out[k] = np.inf if t[k] > t_hi[k] else trace_from(clear, stride, u0, v0, du[k], dv[k], t[k], t_hi[k])


class ClearanceTracer:
    """``trace_ray``'s table for one static occupancy mask, built once per map."""

    def __init__(self, occupied: np.ndarray, geometry: GridGeometry) -> None:
        occupied = occupancy_mask(occupied, geometry)
        self.geometry = geometry
        h, w = occupied.shape
        pad = np.zeros((h + 2, w + 2), dtype=bool)
        pad[1:-1, 1:-1] = occupied
        if pad.any():
            # centre-to-centre distance minus a cell diagonal: from any point of the cell to any
            # point of an occupied cell; the margin keeps a jump's end strictly short of it
            bound = distance_transform_edt(~pad) - math.sqrt(2.0) - 1e-6
        else:
            bound = np.full(pad.shape, np.inf)
        bound = np.maximum(bound, 0.0)
        table = bound.astype(np.float32)
        # float32 must not round a bound up past the true clearance
        table = np.where(table > bound, np.nextafter(table, np.float32(0.0)), table)
        table[pad] = BLOCKED
        self._table = table.ravel()
        self._stride = w + 2

    @property
    def tables(self) -> tuple[np.ndarray, int, int, int]:
        """(flat table, stride, width, height): ``trace_ray``'s map arguments."""
        return self._table, self._stride, self.geometry.width, self.geometry.height

    def to_local(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> grid-local continuous cell coordinates (``trace_ray``'s origins)."""
        return _to_local(self.geometry, np.asarray(xy, dtype=np.float64).reshape(-1, 2))
