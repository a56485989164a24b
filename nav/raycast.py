"""Exact, vectorized ray casting on occupancy grids.

Used by the simulated lidar, by AMCL's beam model (Thrun et al., *Probabilistic Robotics*, ch. 6:
the expected range ``z*`` of each beam) and by costmap free-space clearing.

Method (Amanatides & Woo 1987, "A fast voxel traversal algorithm", vectorized): each ray is walked
along its *major* axis, the one it advances fastest on. With ``|slope| <= 1`` a ray touches at most
two cells per column it crosses: the one it enters through the column boundary and the one it
enters through a row boundary inside the column. Both entry parameters are closed-form; a compiled
loop (``_march``) walks each ray's columns in a padded occupancy table and stops at the first
column with an occupied cell, so the cost follows the distance to the nearest wall rather than
``max_range``. (It replaced a numpy version that built (rays, columns) arrays in growing windows:
the same arithmetic, 7-15x slower.) The result is the exact distance to the boundary of the first
occupied cell, equal to a brute-force ray/box test.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

from nav.types import GridGeometry

OCCUPIED = 255  # march_ray's walk table: an occupied cell (other values: cells it may jump)


def _to_local(geometry: GridGeometry, origins: np.ndarray) -> np.ndarray:
    """World points -> grid-local continuous cell coordinates (u along columns, v along rows)."""
    o = geometry.origin
    local = origins - np.array([o.x, o.y])
    if o.theta != 0.0:
        c, s = math.cos(o.theta), math.sin(o.theta)
        local = local @ np.array([[c, -s], [s, c]])
    return local / geometry.resolution


@njit(cache=True, nogil=True)
def march_ray(
    walk: np.ndarray,
    n: int,
    stride: int,
    u0: float,
    v0: float,
    du: float,
    dv: float,
    t_max: float,
    t_start: float,
) -> float:
    """One ray (cell units, grid-local): the entry distance of the first occupied cell, or inf.
    The major-axis walk of the module doc, one column at a time from the column holding the point
    at ``t_start``, stopping at the first column with a hit (later columns are entered later) or
    once columns are entered beyond ``t_max``.

    ``walk`` is the padded table, one byte per cell: ``OCCUPIED``, else a whole number of cells no
    occupied cell can be hit within from any point of that cell (its clearance minus one cell
    diagonal; 0 without a clearance). At each column the walk restarts that far ahead when it is
    worth it, so a ray crosses an open room in a few jumps instead of one step per column: the
    result is the same, since the columns jumped over hold no occupied cell on the ray. One byte
    table for both keeps the walk's dependent loads in cache."""
    hi = n + 1
    swap = abs(dv) > abs(du)  # major axis is v (rows)
    # coordinates shifted by +1 cell into the padded table
    a0 = (v0 if swap else u0) + 1.0
    b0 = (u0 if swap else v0) + 1.0
    da = dv if swap else du
    db = du if swap else dv
    if db == 0.0:
        db = 1e-300  # a ray along the axis never crosses a minor boundary
    ada = abs(da)  # >= 1/sqrt(2)
    fa = math.floor(a0)
    frac = a0 - fa
    gap = frac if da > 0 else 1.0 - frac  # major distance to the first column boundary
    k = math.floor(min(t_start, t_max) * ada + gap)
    sgn = 1 if da > 0 else (-1 if da < 0 else 0)
    slope, inv_a, inv_b = db / ada, 1.0 / ada, 1.0 / db
    off = (1.0 if db < 0 else 0.0) - b0
    s_major = stride if swap else 1
    s_minor = 1 if swap else stride
    best = np.inf
    # major distance travelled on entering column k (k = 0: the start) and the minor cell there
    m = max(k - gap, 0.0)
    fb_in = math.floor(b0 + slope * m)
    while True:
        t_in = m * inv_a
        if t_in > t_max or t_in > best:
            break
        col = fa + sgn * k
        # off the table every cell is free, and a ray that has left it on its way does not return
        if (col > hi and sgn > 0) or (col < 0 and sgn < 0):
            break
        if (fb_in > hi and slope > 0) or (fb_in < 0 and slope < 0):
            break
        col_in = 0 <= col <= hi
        base = col * s_major
        m_next = max(k + 1.0 - gap, 0.0)
        fb_out = math.floor(b0 + slope * m_next)
        if col_in and 0 <= fb_in <= hi:
            cell = fb_in * s_minor + base
            v = walk[cell]
            if v == OCCUPIED:
                best = min(best, t_in)
            elif v > 2 and best == np.inf:  # a jump of >= 3 cells pays for the restart
                k_next = math.floor(min(t_in + v, t_max) * ada + gap)
                if k_next > k:
                    k = k_next
                    m = max(k - gap, 0.0)
                    fb_in = math.floor(b0 + slope * m)
                    continue
        # entering the second cell of the column through a minor boundary; when there is no
        # second cell this is the same cell, and max() keeps its time no earlier than t_in
        if col_in and 0 <= fb_out <= hi and walk[fb_out * s_minor + base] == OCCUPIED:
            best = min(best, max((fb_out + off) * inv_b, t_in))
        m, fb_in = m_next, fb_out
        k += 1
    return best if best <= t_max else np.inf


@njit(cache=True, nogil=True)
def _march(
    walk: np.ndarray,
    n: int,
    stride: int,
    u0: np.ndarray,
    v0: np.ndarray,
    du: np.ndarray,
    dv: np.ndarray,
    t_max: float,
    t_start: np.ndarray,
    out: np.ndarray,
) -> None:
    """``march_ray`` for every ray."""
    for i in range(u0.shape[0]):
        out[i] = march_ray(walk, n, stride, u0[i], v0[i], du[i], dv[i], t_max, t_start[i])


def occupancy_mask(occupied: np.ndarray, geometry: GridGeometry) -> np.ndarray:
    """``occupied`` as a bool array, checked to be (height, width) of ``geometry``."""
    occupied = np.asarray(occupied, dtype=bool)
    if occupied.shape != (geometry.height, geometry.width):
        raise ValueError(
            f"mask shape {occupied.shape} != grid (height, width) {(geometry.height, geometry.width)}"
        )
    return occupied


class RayCaster:
    """Casts many rays on one static occupancy mask (the padded lookup table is built once).

    Each ray is walked along its *major* axis (the one it advances fastest on): in every column
    (or row) it crosses, a ray with ``|slope| <= 1`` touches at most two cells, the one it enters
    through the column boundary and the one it enters through a minor-axis boundary inside the
    column. A 360-beam scan is a few numpy operations to set the rays up and one compiled walk.
    """

    def __init__(
        self, occupied: np.ndarray, geometry: GridGeometry, clearance: np.ndarray | bool = False
    ) -> None:
        """``clearance``: True to compute (or an (H, W) array in metres to reuse) the Euclidean
        distance transform of the free space. With it, every ray starts marching at the clearance
        of its origin (nothing can be hit closer) and jumps across open space on the way (see
        ``march_ray``), which pays off for many casts on a static map; results are identical
        either way."""
        occupied = occupancy_mask(occupied, geometry)
        self.geometry = geometry
        h, w = occupied.shape
        # A square table with a free border: indices clipped to [0, n + 1] on both axes land on free
        # cells when off the grid, so one scalar clip replaces all bounds checks.
        self._n = max(h, w)
        self._stride = self._n + 2
        pad = np.zeros((self._stride, self._stride), dtype=bool)
        pad[1 : h + 1, 1 : w + 1] = occupied
        self._flat = pad.ravel()
        # march_ray's walk table: OCCUPIED, or the whole cells no ray can hit within from anywhere
        # in the cell (the transform measures centre to centre, hence minus a cell diagonal);
        # 0 (no jump) without a clearance and on the free border. Only this byte table is kept.
        walk = np.zeros((self._stride, self._stride), dtype=np.uint8)
        cells_clear: np.ndarray | None = None
        if isinstance(clearance, np.ndarray):
            cells_clear = np.asarray(clearance, dtype=np.float64) / geometry.resolution
        elif clearance:
            cells_clear = (
                distance_transform_edt(~occupied) if occupied.any() else np.full(occupied.shape, np.inf)
            )
        if cells_clear is not None:
            cells = np.floor(np.maximum(cells_clear - math.sqrt(2.0) - 1e-6, 0.0))
            walk[1 : h + 1, 1 : w + 1] = np.minimum(cells, OCCUPIED - 1)
        walk[pad] = OCCUPIED
        self._walk = walk.ravel()

    @property
    def tables(self) -> tuple[np.ndarray, int, int]:
        """(walk table, n, stride): ``march_ray``'s map arguments."""
        return self._walk, self._n, self._stride

    def to_local(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> grid-local continuous cell coordinates (``march_ray``'s origins)."""
        return _to_local(self.geometry, np.asarray(xy, dtype=np.float64).reshape(-1, 2))

    def occupied_at(self, xy: np.ndarray) -> np.ndarray:
        """Per (N, 2) world point: whether it lies in an occupied cell (off-grid counts as free)."""
        local = _to_local(self.geometry, np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        idx = np.clip(np.floor(local) + 1.0, 0.0, float(self._n + 1)) @ np.array([1.0, float(self._stride)])
        return self._flat.take(idx.astype(np.intp))

    def any_occupied(self, xy: np.ndarray) -> bool:
        """True if any (N, 2) world point lies in an occupied cell (off-grid counts as free)."""
        return bool(self.occupied_at(xy).any())

    def any_occupied_at_pose(self, points: np.ndarray, x: float, y: float, theta: float) -> bool:
        """``any_occupied`` for (N, 2) points given in a body frame at pose (x, y, theta): body ->
        world -> padded-table index folded into one affine map (the per-substep collision check)."""
        g = self.geometry
        o = g.origin
        c0, s0 = math.cos(-o.theta), math.sin(-o.theta)
        dx, dy = x - o.x, y - o.y
        inv = 1.0 / g.resolution
        tu, tv = (c0 * dx - s0 * dy) * inv + 1.0, (s0 * dx + c0 * dy) * inv + 1.0
        c, s = math.cos(theta - o.theta) * inv, math.sin(theta - o.theta) * inv
        uv = points @ np.array([[c, s], [-s, c]]) + np.array([tu, tv])
        idx = np.clip(np.floor(uv), 0.0, float(self._n + 1)) @ np.array([1.0, float(self._stride)])
        return bool(self._flat.take(idx.astype(np.intp)).any())

    def cast(self, origins: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
        """See ``cast_rays``."""
        origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
        p = origins.shape[0]
        angles = np.asarray(angles, dtype=np.float64)
        if angles.ndim == 1:
            angles = np.broadcast_to(angles, (p, angles.shape[0]))
        if angles.shape[0] != p:
            raise ValueError(f"angles has {angles.shape[0]} rows for {p} origins")
        b = angles.shape[1]
        if p == 0 or b == 0:
            return np.full((p, b), np.inf)
        g = self.geometry
        local = _to_local(g, origins)
        a = angles - g.origin.theta
        du = np.cos(a).ravel()
        dv = np.sin(a).ravel()
        u0 = np.repeat(local[:, 0], b)
        v0 = np.repeat(local[:, 1], b)
        t_max = float(max_range) / g.resolution
        t_start = np.repeat(self._start_distance(local), b)
        out = np.empty(u0.size)
        _march(self._walk, self._n, self._stride, u0, v0, du, dv, t_max, t_start, out)
        out *= g.resolution
        return out.reshape(p, b)

    def _start_distance(self, local: np.ndarray) -> np.ndarray:
        """Per origin (cell units): a distance below which no occupied cell can be hit, the walk
        table's value at the origin's cell (0 in an occupied cell and off the grid)."""
        cols = np.clip(np.floor(local[:, 0]) + 1.0, 0.0, float(self._n + 1)).astype(np.intp)
        rows = np.clip(np.floor(local[:, 1]) + 1.0, 0.0, float(self._n + 1)).astype(np.intp)
        v = self._walk[rows * self._stride + cols].astype(np.float64)
        return np.where(v == OCCUPIED, 0.0, v)


def cast_rays(
    occupied: np.ndarray,
    geometry: GridGeometry,
    origins: np.ndarray,
    angles: np.ndarray,
    max_range: float,
) -> np.ndarray:
    """Distance from each origin to the first occupied cell along each world-frame angle.

    Args:
        occupied: (H, W) bool mask over ``geometry`` (True = obstacle).
        geometry: the grid's geometry (resolution, size, origin pose).
        origins: (P, 2) world points (a single (2,) point is accepted).
        angles: (P, B) world-frame angles per origin, or (B,) shared by all origins.
        max_range: metres; hits farther than this report ``inf``.

    Returns:
        (P, B) float64 metres, ``np.inf`` where no occupied cell lies within ``max_range``. Cells off
        the grid count as free. An origin inside an occupied cell reads 0. For repeated casts on
        the same mask build a ``RayCaster`` once instead.
    """
    return RayCaster(occupied, geometry).cast(origins, angles, max_range)


def bresenham_cells(
    start_cells: np.ndarray, end_cells: np.ndarray, include_end: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bresenham lines between integer cells, many at once.

    For each segment with major-axis length ``n = max(|dr|, |dc|)`` the cells are
    ``start + round_half_up(i * d / n)``, i = 0..n, the classic Bresenham (1965) choice.

    Args:
        start_cells, end_cells: (N, 2) integer (row, col) pairs.
        include_end: whether the end cell is returned (costmap clearing usually excludes it: it
            holds the obstacle that produced the return).

    Returns:
        ``(rows, cols, segment_index)`` flat int64 arrays.
    """
    s = np.asarray(start_cells, dtype=np.int64).reshape(-1, 2)
    e = np.asarray(end_cells, dtype=np.int64).reshape(-1, 2)
    d = e - s
    n = np.abs(d).max(axis=1)
    counts = n + 1 if include_end else n
    total = int(counts.sum())
    seg = np.repeat(np.arange(s.shape[0]), counts)
    first = np.cumsum(counts) - counts
    i = np.arange(total) - np.repeat(first, counts)
    nn = np.maximum(n[seg], 1)
    dd = d[seg]
    # round_half_up(i * |d| / n) with the sign of d, in integer arithmetic
    step = (2 * i[:, None] * np.abs(dd) + nn[:, None]) // (2 * nn[:, None])
    cells = s[seg] + np.sign(dd) * step
    return cells[:, 0], cells[:, 1], seg


def traversed_cells(
    geometry: GridGeometry, starts: np.ndarray, ends: np.ndarray, include_end: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every grid cell whose interior the world segments ``starts[i] -> ends[i]`` pass through
    (Amanatides & Woo supercover), for free-space clearing along lidar beams.

    Uses the same major-axis walk as ``RayCaster``: per column crossed, the cell entered through
    the column boundary and, if the segment also crosses a minor boundary there, the second cell.

    Args:
        geometry: grid geometry.
        starts, ends: (N, 2) world points.
        include_end: whether the cell holding each end point is returned.

    Returns:
        ``(rows, cols, segment_index)`` int64 arrays, only cells inside the grid; each cell appears
        once per segment (a segment through an exact cell corner may repeat it, harmlessly).
    """
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2)
    if starts.shape[0] == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    ls, le = _to_local(geometry, starts), _to_local(geometry, ends)
    d = le - ls
    length = np.hypot(d[:, 0], d[:, 1])
    zero = length == 0.0
    safe = np.where(zero, 1.0, length)
    du, dv = np.where(zero, 1.0, d[:, 0] / safe), np.where(zero, 0.0, d[:, 1] / safe)
    swap = np.abs(dv) > np.abs(du)
    a0, b0 = np.where(swap, ls[:, 1], ls[:, 0]), np.where(swap, ls[:, 0], ls[:, 1])
    da, db = np.where(swap, dv, du), np.where(swap, du, dv)
    db = np.where(db == 0.0, 1e-300, db)
    ada = np.abs(da)
    fa = np.floor(a0)
    gap = np.where(da > 0, a0 - fa, 1.0 - (a0 - fa))
    n = math.ceil(float((length * ada).max())) + 2
    k = np.arange(n + 1, dtype=np.float64)
    m = np.maximum(k - gap[:, None], 0.0)
    fb = np.floor(b0[:, None] + (db / ada)[:, None] * m)
    fb_in, fb_out = fb[:, :n], fb[:, 1:]
    t_in = m[:, :n] / ada[:, None]
    t_mid = (fb_out + ((db < 0) - b0)[:, None]) / db[:, None]
    col = fa[:, None] + np.sign(da)[:, None] * k[:n]
    lim = length[:, None]
    keep_in = t_in < lim
    keep_mid = (fb_out != fb_in) & (t_mid < lim)
    seg_ids = np.broadcast_to(np.arange(ls.shape[0])[:, None], t_in.shape)
    major = np.concatenate((col[keep_in], col[keep_mid])).astype(np.int64)
    minor = np.concatenate((fb_in[keep_in], fb_out[keep_mid])).astype(np.int64)
    g = np.concatenate((seg_ids[keep_in], seg_ids[keep_mid]))
    sw = swap[g]
    r, c = np.where(sw, major, minor), np.where(sw, minor, major)
    end_r, end_c = np.floor(le[:, 1]).astype(np.int64), np.floor(le[:, 0]).astype(np.int64)
    not_end = (r != end_r[g]) | (c != end_c[g])
    r, c, g = r[not_end], c[not_end], g[not_end]
    if include_end:
        r, c = np.concatenate((r, end_r)), np.concatenate((c, end_c))
        g = np.concatenate((g, np.arange(le.shape[0])))
    inside = (r >= 0) & (r < geometry.height) & (c >= 0) & (c < geometry.width)
    return r[inside], c[inside], g[inside]
