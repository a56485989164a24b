"""Free-space clearing along lidar beams, compiled: Amanatides & Woo's grid traversal per beam.

Why a kernel: clearing is the obstacle layer's hot path (360 beams x up to 60 cells, every scan of
both costmaps). The vectorized ``nav.raycast.traversed_cells`` builds (beams x longest beam) arrays
of candidate cells and filters them, ~1.5 ms per scan; walking each beam's cells directly and
writing them in place is ~50 µs and visits the same cells (the supercover: every cell whose
interior the segment crosses). Segments are clipped to the grid first (Liang & Barsky), so a 3 m
beam in a 3 x 3 m rolling window walks only its cells inside the window.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nav.types import GridGeometry

NO_STAMP = np.empty((0, 0))
"""The ``stamp`` argument of ``_clear`` when observation times are not kept."""


@njit(cache=True, nogil=True)
def _clip(x0: float, y0: float, dx: float, dy: float, w: float, h: float) -> tuple[float, float]:
    """Liang-Barsky: parameter interval [t0, t1] of p0 + t d (t in [0, 1]) inside [0, w] x [0, h];
    t0 > t1 when the segment misses the box."""
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0), (dx, w - x0), (-dy, y0), (dy, h - y0)):
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            r = q / p
            if p < 0.0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
    return t0, t1


@njit(cache=True, nogil=True)
def _clear(
    costs: np.ndarray,
    seg: np.ndarray,
    value: np.uint8,
    include_end: np.ndarray,
    stop: np.ndarray,
    stop_value: np.uint8,
    stamp: np.ndarray,
    now: float,
) -> np.ndarray:
    """Walk and write every segment; a segment flagged in ``stop`` ends at the first cell holding
    ``stop_value`` (written too: it clears that surface but nothing behind it). Every written cell
    gets ``now`` in ``stamp`` (when it last was observed) unless ``stamp`` is empty."""
    h, w = costs.shape
    bounds = np.array([h, -1, w, -1], dtype=np.int64)  # row0, row1 (inclusive here), col0, col1
    for i in range(seg.shape[0]):
        x0, y0, x1, y1 = seg[i, 0], seg[i, 1], seg[i, 2], seg[i, 3]
        dx, dy = x1 - x0, y1 - y0
        t0, t1 = _clip(x0, y0, dx, dy, float(w), float(h))
        if t0 > t1 or (t1 - t0) * max(abs(dx), abs(dy)) < 1e-12:
            continue
        end_c, end_r = math.floor(x1), math.floor(y1)
        # start inside the first cell, even when the entry lies exactly on the grid's border
        sx, sy = x0 + t0 * dx, y0 + t0 * dy
        c = min(max(math.floor(sx), 0), w - 1)
        r = min(max(math.floor(sy), 0), h - 1)
        step_c = 1 if dx > 0 else -1
        step_r = 1 if dy > 0 else -1
        # parameter t (along the whole segment) at the next column / row boundary
        tmx = ((c + (dx > 0)) - x0) / dx if dx != 0.0 else np.inf
        tmy = ((r + (dy > 0)) - y0) / dy if dy != 0.0 else np.inf
        tdx = abs(1.0 / dx) if dx != 0.0 else np.inf
        tdy = abs(1.0 / dy) if dy != 0.0 else np.inf
        while True:
            if include_end[i] or c != end_c or r != end_r:
                was = costs[r, c]
                costs[r, c] = value
                if stamp.shape[0]:
                    stamp[r, c] = now
                bounds[0] = min(bounds[0], r)
                bounds[1] = max(bounds[1], r)
                bounds[2] = min(bounds[2], c)
                bounds[3] = max(bounds[3], c)
                if stop[i] and was == stop_value:
                    break
            if tmx < tmy:
                if tmx >= t1:
                    break
                c += step_c
                tmx += tdx
            else:
                if tmy >= t1:
                    break
                r += step_r
                tmy += tdy
            if c < 0 or c >= w or r < 0 or r >= h:
                break
    return bounds


def clear_segments(
    costs: np.ndarray,
    geometry: GridGeometry,
    starts: np.ndarray,
    ends: np.ndarray,
    value: int,
    include_end: bool | np.ndarray = False,
    stop_at: int | None = None,
    stop: bool | np.ndarray = True,
    stamp: np.ndarray | None = None,
    now: float = 0.0,
) -> tuple[int, int, int, int] | None:
    """Set every cell of ``costs`` (over ``geometry``) whose interior a world segment
    ``starts[i] -> ends[i]`` crosses to ``value``, except the cell holding the segment's end unless
    ``include_end`` (it holds the return; a bool, or one per segment). With ``stop_at``, the
    segments flagged in ``stop`` (a bool, or one per segment) end at the first cell holding that
    value, which is written but nothing behind it. ``stamp`` (same shape as ``costs``) gets ``now``
    in every written cell. Returns the written region (row0, row1, col0,
    col1), half-open, or None when nothing was written."""
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2)
    if starts.shape[0] == 0:
        return None
    o = geometry.origin
    both = np.concatenate((starts, ends), axis=1).reshape(-1, 2) - (o.x, o.y)
    if o.theta != 0.0:
        c, s = math.cos(o.theta), math.sin(o.theta)
        both = both @ np.array([[c, -s], [s, c]])
    seg = np.ascontiguousarray((both / geometry.resolution).reshape(-1, 4))
    # writable copies: a read-only (broadcast) flag array is another numba signature
    n = seg.shape[0]
    flags = np.array(np.broadcast_to(np.asarray(include_end, dtype=np.bool_), (n,)))
    stops = np.array(np.broadcast_to(np.asarray(stop_at is not None and stop, dtype=np.bool_), (n,)))
    stamps = NO_STAMP if stamp is None else stamp
    b = _clear(
        costs,
        seg,
        np.uint8(value),
        flags,
        stops,
        np.uint8(0 if stop_at is None else stop_at),
        stamps,
        float(now),
    )
    if b[1] < 0:
        return None
    return int(b[0]), int(b[1]) + 1, int(b[2]), int(b[3]) + 1


__all__ = ["NO_STAMP", "clear_segments"]
