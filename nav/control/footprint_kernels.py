"""Compiled kernels behind ``nav.control.footprint.CostWindow``: the window crop, the "near a
lethal cell" mask and the per-pose footprint gathers, each one pass over its poses with the same
cell and heading-bin arithmetic as the numpy code paths they replace (results are identical).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from nav.types import LETHAL_OBSTACLE, NO_INFORMATION


@njit(cache=True, nogil=True)
def _xy_bounds(xy: np.ndarray) -> tuple[float, float, float, float]:
    """(x min, x max, y min, y max) of (N, 2+) points in one pass."""
    x0 = x1 = xy[0, 0]
    y0 = y1 = xy[0, 1]
    for i in range(1, xy.shape[0]):
        x, y = xy[i, 0], xy[i, 1]
        x0, x1 = min(x0, x), max(x1, x)
        y0, y1 = min(y0, y), max(y1, y)
    return x0, x1, y0, y1


@njit(cache=True, nogil=True)
def _crop(costs: np.ndarray, r0: int, r1: int, c0: int, c1: int, unknown: int) -> np.ndarray:
    """Rows r0..r1-1, cols c0..c1-1 of ``costs``: LETHAL off the grid, NO_INFORMATION -> ``unknown``."""
    h, w = costs.shape
    out = np.empty((r1 - r0, c1 - c0), dtype=np.uint8)
    for r in range(r0, r1):
        for c in range(c0, c1):
            v = costs[r, c] if 0 <= r < h and 0 <= c < w else LETHAL_OBSTACLE
            out[r - r0, c - c0] = unknown if v == NO_INFORMATION else v
    return out


@njit(cache=True, nogil=True)
def _near_lethal(costs: np.ndarray, disc: np.ndarray) -> np.ndarray:
    """Cells within the disc offsets (N, 2) of a lethal cell: the distance-transform test
    ``edt(costs < LETHAL) <= reach`` without the transform. Only lethal cells with a non-lethal
    4-neighbour are stamped: the lethal cell nearest any other cell always has one (a step towards
    that cell would otherwise be a nearer lethal cell)."""
    h, w = costs.shape
    near = np.zeros((h, w), dtype=np.bool_)
    for r in range(h):
        for c in range(w):
            if costs[r, c] < 254:
                continue
            near[r, c] = True
            edge = (
                (r > 0 and costs[r - 1, c] < 254)
                or (r + 1 < h and costs[r + 1, c] < 254)
                or (c > 0 and costs[r, c - 1] < 254)
                or (c + 1 < w and costs[r, c + 1] < 254)
            )
            if not edge:
                continue
            for j in range(disc.shape[0]):
                rr, cc = r + disc[j, 0], c + disc[j, 1]
                if 0 <= rr < h and 0 <= cc < w:
                    near[rr, cc] = True
    return near


@njit(cache=True, nogil=True)
def _pose_cell(x: float, y: float, x0: float, y0: float, inv: float, h: int, w: int) -> tuple[int, int]:
    """``CostWindow.cells`` for one pose of an axis-aligned window (same arithmetic)."""
    c = math.floor((x - x0) * inv)
    r = math.floor((y - y0) * inv)
    return min(max(r, 0), h - 1), min(max(c, 0), w - 1)


@njit(cache=True, nogil=True)
def _pose_bin(theta: float, theta0: float, scale: float, bins: int) -> int:
    """``CostWindow._bins`` for one heading (np.rint: round half to even, like numpy)."""
    if bins == 1:
        return 0
    return int(np.rint((theta - theta0) * scale)) % bins


@njit(cache=True, nogil=True)
def _lethal_poses(
    levels: np.ndarray,
    near: np.ndarray,
    poses: np.ndarray,
    origin: np.ndarray,
    spans: np.ndarray,
    counts: np.ndarray,
) -> np.ndarray:
    """(K, T) whether the footprint touches a lethal cell at each of the (K, T, 3) poses (any
    layout: the trajectories' future poses are a strided view): poses off the ``near`` mask are
    clear; the rest query their heading bin's row runs in the row-maximum table ``levels`` (see
    ``_span_max``) up to the first lethal one."""
    _, h, w = levels.shape
    lg = _floor_log2(w)
    x0, y0, theta0, inv = origin[0], origin[1], origin[2], origin[3]
    bins = spans.shape[0]
    scale = bins / (2.0 * math.pi)
    out = np.zeros(poses.shape[:2], dtype=np.bool_)
    for k in range(poses.shape[0]):
        for i in range(poses.shape[1]):
            r, c = _pose_cell(poses[k, i, 0], poses[k, i, 1], x0, y0, inv, h, w)
            if not near[r, c]:
                continue
            b = _pose_bin(poses[k, i, 2], theta0, scale, bins)
            for s in range(counts[b]):
                rr = min(max(r + spans[b, s, 0], 0), h - 1)
                lo = min(max(c + spans[b, s, 1], 0), w - 1)
                hi = min(max(c + spans[b, s, 2], 0), w - 1)
                j = lg[hi - lo + 1]
                if max(levels[j, rr, lo], levels[j, rr, hi - (1 << j) + 1]) >= 254:
                    out[k, i] = True
                    break
    return out


@lru_cache(maxsize=32)
def _disc(resolution: float, reach: float) -> np.ndarray:
    """(N, 2) integer cell offsets within ``reach`` metres, by the same float test as
    ``edt * resolution <= reach`` (so the mask equals the distance-transform test). Cached: one
    robot asks for the same one or two every cycle."""
    r = math.floor(reach / resolution) + 1
    idx = np.arange(-r, r + 1)
    dr, dc = np.meshgrid(idx, idx, indexing="ij")
    keep = np.sqrt((dr * dr + dc * dc).astype(np.float64)) * resolution <= reach
    return np.column_stack((dr[keep], dc[keep])).astype(np.int64)


@njit(cache=True, nogil=True)
def _lower_envelope(f: np.ndarray, out: np.ndarray, v: np.ndarray, z: np.ndarray) -> None:
    """Felzenszwalb & Huttenlocher's 1-D squared distance transform: ``out[q] = min_p (q - p)^2 +
    f[p]`` (``f`` = inf where there is no site), with work arrays ``v`` (n,) and ``z`` (n + 1,)."""
    n = f.shape[0]
    k = -1
    for q in range(n):
        if f[q] == np.inf:
            continue
        if k < 0:
            k = 0
            v[0] = q
            z[0] = -np.inf
            z[1] = np.inf
            continue
        s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        while s <= z[k]:
            k -= 1
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    if k < 0:
        out[:] = np.inf
        return
    k = 0
    for q in range(n):
        while z[k + 1] < q:
            k += 1
        d = q - v[k]
        out[q] = d * d + f[v[k]]


@njit(cache=True, nogil=True)
def _lethal_sq_distance(costs: np.ndarray) -> np.ndarray:
    """(H, W) squared distance (cells^2) from each cell centre to the nearest lethal cell centre,
    exact (two 1-D passes of ``_lower_envelope``); inf without a lethal cell. The same values as
    ``scipy.ndimage.distance_transform_edt(costs < 254) ** 2``, a fraction of its cost on one
    small window per cycle."""
    h, w = costs.shape
    n = max(h, w)
    v = np.empty(n, dtype=np.int64)
    z = np.empty(n + 1)
    col = np.empty(h)
    tmp = np.empty(n)
    out = np.empty((h, w))
    for c in range(w):
        for r in range(h):
            col[r] = 0.0 if costs[r, c] >= 254 else np.inf
        _lower_envelope(col, tmp[:h], v, z)
        for r in range(h):
            out[r, c] = tmp[r]
    row = np.empty(w)
    for r in range(h):
        for c in range(w):
            row[c] = out[r, c]
        _lower_envelope(row, tmp[:w], v, z)
        for c in range(w):
            out[r, c] = tmp[c]
    return out


@njit(cache=True, nogil=True)
def _lethal_round_dt(
    costs: np.ndarray,
    dist: np.ndarray,
    poses: np.ndarray,
    origin: np.ndarray,
    ring: np.ndarray,
    ring_r: np.ndarray,
    resolution: float,
    radius: float,
) -> np.ndarray:
    """(K, T) whether a lethal cell's centre lies strictly within ``radius`` of each of the (K, T, 3)
    poses' exact position (a round robot; a lethal cell is a point obstacle at its centre, as TEB's
    ``centre_collisions``), from the window's distance transform (``dist``: m from each cell
    centre to the nearest lethal cell centre): a pose lies within half a cell diagonal ``h`` of its
    cell's centre, so ``dist - h >= radius`` is clear and ``dist + h < radius`` collides. Only poses
    in between test lethal cells exactly, and only those whose centre distance from the cell's
    centre lies in [dist, radius + h) (``ring``: cell offsets sorted by their distance ``ring_r``,
    m): an annulus about 1.4 cells wide, so the cost grows with the radius, not the disc's area."""
    h, w = costs.shape
    x0, y0, inv, res = origin[0], origin[1], origin[3], resolution
    half = 0.7072 * res  # > sqrt(2) / 2 cell: bounds the pose's offset from its cell's centre
    r2 = radius * radius
    out = np.zeros(poses.shape[:2], dtype=np.bool_)
    for k in range(poses.shape[0]):
        for i in range(poses.shape[1]):
            x, y = poses[k, i, 0], poses[k, i, 1]
            r, c = _pose_cell(x, y, x0, y0, inv, h, w)
            d = dist[r, c]
            if d - half >= radius:
                continue
            if d + half < radius:
                out[k, i] = True
                continue
            j = np.searchsorted(ring_r, d - 1e-9)
            while j < ring_r.shape[0] and ring_r[j] < radius + half:
                rr, cc = r + ring[j, 0], c + ring[j, 1]
                j += 1
                if rr < 0 or rr >= h or cc < 0 or cc >= w or costs[rr, cc] < 254:
                    continue
                dx = x0 + (cc + 0.5) * res - x
                dy = y0 + (rr + 0.5) * res - y
                if dx * dx + dy * dy < r2:
                    out[k, i] = True
                    break
    return out


@lru_cache(maxsize=32)
def _ring(resolution: float, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) cell offsets within ``reach`` m sorted by their distance, and those distances (m)."""
    disc = _disc(resolution, reach)
    r = np.sqrt((disc * disc).sum(axis=1).astype(np.float64)) * resolution
    order = np.argsort(r, kind="stable")
    return np.ascontiguousarray(disc[order]), r[order]


@njit(cache=True, nogil=True)
def _row_max_levels(costs: np.ndarray, levels: int) -> np.ndarray:
    """(levels, H, W) sparse table of row-wise maxima: ``out[j, r, c]`` = max of ``costs[r, c :
    c + 2^j]`` (clipped at the row's end). Any run of a row then has its maximum in two lookups."""
    h, w = costs.shape
    out = np.empty((levels, h, w), dtype=np.uint8)
    out[0] = costs
    for j in range(1, levels):
        half = 1 << (j - 1)
        for r in range(h):
            for c in range(w):
                a = out[j - 1, r, c]
                if c + half < w:
                    b = out[j - 1, r, c + half]
                    if b > a:
                        a = b
                out[j, r, c] = a
    return out


@njit(cache=True, nogil=True)
def _floor_log2(n: int) -> np.ndarray:
    """(n + 1,) floor(log2(x)) for x = 1..n (entry 0 unused): a run's sparse-table level."""
    lg = np.zeros(n + 1, dtype=np.int64)
    for x in range(2, n + 1):
        lg[x] = lg[x >> 1] + 1
    return lg


@njit(cache=True, nogil=True)
def _span_max(
    levels: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    bins: np.ndarray,
    spans: np.ndarray,
    counts: np.ndarray,
) -> np.ndarray:
    """(N,) max cost under the footprint at cells (rows, cols) with heading bins ``bins``: the
    footprint of a bin is ``counts[bin]`` row runs ``spans[bin, s] = (row offset, first col offset,
    last col offset)``, each run's maximum two lookups in the sparse table. Cells off the window
    read its nearest edge cell (``ndimage`` mode "nearest")."""
    _, h, w = levels.shape
    lg = _floor_log2(w)
    out = np.zeros(rows.shape[0], dtype=np.uint8)
    for i in range(rows.shape[0]):
        b = bins[i]
        best = 0
        for s in range(counts[b]):
            rr = min(max(rows[i] + spans[b, s, 0], 0), h - 1)
            lo = min(max(cols[i] + spans[b, s, 1], 0), w - 1)
            hi = min(max(cols[i] + spans[b, s, 2], 0), w - 1)
            j = lg[hi - lo + 1]
            v = max(levels[j, rr, lo], levels[j, rr, hi - (1 << j) + 1])
            if v > best:
                best = v
        out[i] = best
    return out
