"""Smoothed likelihood field of an occupancy grid, plus max-pooled copies for coarse-to-fine search.

The field is the likelihood-field sensor model (Thrun et al., *Probabilistic Robotics* 6.4):
``F = exp(-d^2 / (2 sigma^2))`` with ``d`` the distance to the nearest occupied cell. It is smooth,
so the least-squares refinement has useful gradients several cells away (the role Cartographer's
bicubic interpolation and Olson's blurred rasterized lookup table play). ``pooled[k]`` holds, for
each cell, the max of ``F`` over the ``2^k x 2^k`` block starting there: a score computed on it is an
upper bound of every finer offset inside that block (Hess et al. 2016, sec. V.C precomputation grids).
Interpolation is bilinear with its analytic gradient, for the least-squares refinement.
"""

from __future__ import annotations

import functools

import numpy as np

from nav.grid import LogOddsGrid
from nav.slam import kernels

POINTS_FIELD_MARGIN = 0.5
"""Margin (m) of a field built from points (:meth:`LikelihoodField.from_points`) around them."""


@functools.lru_cache(maxsize=16)
def _kernel(sigma: float, resolution: float) -> np.ndarray:
    """(K, 3) integer offsets (dy, dx) within 3 sigma and their weights exp(-d^2 / 2 sigma^2)."""
    rad = max(1, int(np.ceil(3.0 * sigma / resolution)))
    dy, dx = np.mgrid[-rad : rad + 1, -rad : rad + 1]
    d2 = (dy * dy + dx * dx) * resolution**2
    keep = d2 <= (3.0 * sigma) ** 2
    k = np.column_stack((dy[keep], dx[keep], np.exp(-0.5 * d2[keep] / sigma**2)))
    k.setflags(write=False)  # cached and shared
    return k


@functools.lru_cache(maxsize=16)
def _window_kernel(sigma: float, resolution: float, half: int) -> np.ndarray:
    """:func:`_kernel` spread by a +-``half`` cell window, dense ((2 (R + half) + 1)^2 float32
    weights centred on the cell, R the kernel's radius): at each offset the largest weight within
    ``half`` cells of it, so a splat of it is at least the window max of a splat of the kernel
    (``half`` 0: the kernel itself as a dense square, what the field is splatted with)."""
    k = _kernel(sigma, resolution)
    rad = int(np.abs(k[:, :2]).max())
    dense = np.zeros((2 * rad + 1, 2 * rad + 1), dtype=np.float32)
    dense[k[:, 0].astype(int) + rad, k[:, 1].astype(int) + rad] = k[:, 2]  # float32, as the field
    spread = np.zeros((2 * (rad + half) + 1,) * 2, dtype=np.float32)
    for dy in range(2 * half + 1):
        for dx in range(2 * half + 1):
            view = spread[dy : dy + 2 * rad + 1, dx : dx + 2 * rad + 1]
            np.maximum(view, dense, out=view)
    spread.setflags(write=False)  # cached and shared
    return spread


@functools.lru_cache(maxsize=16)
def _halved_window_kernels(sigma: float, resolution: float, half: int) -> np.ndarray:
    """:func:`_window_kernel` for a half-resolution grid, (2, 2, K, K) float32: for a splat centre
    of row parity ``pr`` and column parity ``pc``, ``[pr, pc, j + D, k + D]`` is the largest weight
    the full-resolution kernel puts on the 2 x 2 block ``D`` + ``j``, ``k`` half-resolution cells
    from the centre's block (what :func:`nav.slam.kernels.splat_halved` splats)."""
    spread = _window_kernel(sigma, resolution, half)
    e = spread.shape[0] // 2
    d = (e + 1) // 2
    out = np.zeros((2, 2, 2 * d + 1, 2 * d + 1), dtype=np.float32)
    for pr in range(2):
        for pc in range(2):
            for u in range(2):
                for v in range(2):
                    # full-resolution offsets 2 j + u - pr (rows) and 2 k + v - pc (columns)
                    dy = 2 * np.arange(-d, d + 1) + u - pr
                    dx = 2 * np.arange(-d, d + 1) + v - pc
                    ok_y, ok_x = np.abs(dy) <= e, np.abs(dx) <= e
                    block = out[pr, pc][np.ix_(ok_y, ok_x)]
                    out[pr, pc][np.ix_(ok_y, ok_x)] = np.maximum(
                        block, spread[np.ix_(dy[ok_y] + e, dx[ok_x] + e)]
                    )
    out.setflags(write=False)  # cached and shared
    return out


def halve_max(grid: np.ndarray) -> np.ndarray:
    """``out[R, C]`` = max of ``grid`` over the 2 x 2 block of cells (2 R .. 2 R + 1, 2 C .. 2 C + 1),
    cells past the edge counting 0."""
    h, w = grid.shape
    padded = np.zeros((h + h % 2, w + w % 2), dtype=grid.dtype)
    padded[:h, :w] = grid
    return np.maximum(
        np.maximum(padded[0::2, 0::2], padded[1::2, 0::2]), np.maximum(padded[0::2, 1::2], padded[1::2, 1::2])
    )


class LikelihoodField:
    """``F`` sampled on the grid's cells; ``origin`` is the world point of cell (0, 0)'s corner."""

    sigma: float = 0.05

    def __init__(self, field: np.ndarray, origin: np.ndarray, resolution: float, levels: int = 0) -> None:
        self.field = np.ascontiguousarray(field, dtype=np.float32)
        self.origin = np.asarray(origin, dtype=float)
        self.resolution = float(resolution)
        self.pooled: list[np.ndarray] = [self.field]
        self._window_max: dict[int, np.ndarray] = {}
        # per pooled level, its phase split (kernels.phase_split) for the top level of a search:
        # a finished submap's field is searched for many nodes' loop closures, and splitting a
        # ~200k-cell field cost half of each top level (FR079: 0.34 of 0.67 ms)
        self._phases: dict[tuple[int, int], np.ndarray] = {}
        # the cells whose kernels make up the whole field, when known (built from cells): its
        # window maxima are then bounded by splatting a spread kernel there, cheaper than a pass
        # over the grid
        self._splatted: tuple[np.ndarray, np.ndarray] | None = None
        self.ensure_levels(levels)

    @classmethod
    def from_grid(cls, grid: LogOddsGrid, sigma: float = 0.05, levels: int = 0) -> LikelihoodField:
        """Field of a log-odds grid; cells with ``l > 0`` count as occupied; ``sigma`` in metres.

        The Gaussian is truncated at 3 sigma, so ``F`` is a max of small kernels, one splatted
        around each occupied cell (compiled, :func:`nav.slam.kernels.splat_dense` of the kernel as a
        dense square, whose contiguous rows vectorize: ~2x faster than its offset list, the same
        maxima; the numpy reference is :func:`field_reference`), and updated by splatting only the
        newly occupied cells afterwards (:meth:`splat`)."""
        rows, cols = np.nonzero(grid.logodds > 0.0)
        f = np.zeros(grid.shape, dtype=np.float32)
        kernels.splat_dense(f, rows, cols, _window_kernel(sigma, grid.resolution, 0))
        obj = cls(f, grid.origin, grid.resolution, levels)
        obj.sigma = sigma
        # the occupied cells are a few percent of a submap's: its first window max splats the
        # spread kernel there (3-4x cheaper than a pass over the grid; FR079's front end rebuilt
        # a field every ~16 scans, each time paying that pass)
        obj._splatted = (rows, cols)
        return obj

    @classmethod
    def from_points(
        cls,
        points: np.ndarray,
        resolution: float,
        sigma: float = 0.05,
        margin: float = POINTS_FIELD_MARGIN,
        levels: int = 0,
    ) -> LikelihoodField:
        """Field of the cells hit by (N, 2) ``points`` (scan-to-scan matching: the reference
        scan's returns in its own frame), on a grid covering them plus ``margin`` (m); no free
        space is traced (the field only needs the occupied cells). One compiled call
        (:func:`nav.slam.kernels.points_field`; numpy reference :meth:`from_points_reference`)."""
        if points.shape[0] == 0:
            raise ValueError("no points to build a likelihood field from")
        f, lox, loy, rows, cols = kernels.points_field(
            np.ascontiguousarray(points, dtype=np.float64),
            resolution,
            margin,
            _window_kernel(sigma, resolution, 0),
        )
        obj = cls(f, np.array([lox, loy]), resolution, levels)
        obj.sigma = sigma
        obj._splatted = (rows, cols)
        return obj

    @classmethod
    def from_points_reference(
        cls, points: np.ndarray, resolution: float, sigma: float = 0.05, margin: float = POINTS_FIELD_MARGIN
    ) -> LikelihoodField:
        """Pure-numpy reference of :meth:`from_points` (the tests compare the two)."""
        if points.shape[0] == 0:
            raise ValueError("no points to build a likelihood field from")
        lo = np.floor((points.min(axis=0) - margin) / resolution) * resolution
        shape = np.floor((points.max(axis=0) + margin - lo) / resolution).astype(np.int64) + 1
        cells = np.floor((points - lo) / resolution).astype(np.int64)
        occupied = np.zeros((int(shape[1]), int(shape[0])), dtype=bool)
        occupied[cells[:, 1], cells[:, 0]] = True
        obj = cls(field_reference(occupied, sigma, resolution), lo, resolution)
        obj.sigma = sigma
        return obj

    def splat(self, cells: np.ndarray) -> None:
        """Raise ``F`` around newly occupied flat ``cells`` (same grid shape); drops pooled levels."""
        if cells.size == 0:
            return
        rows, cols = np.divmod(cells, self.field.shape[1])
        kernels.splat_dense(self.field, rows, cols, _window_kernel(self.sigma, self.resolution, 0))
        self.pooled = [self.field]
        self._phases = {}
        self._splatted = None
        for half, bound in self._window_max.items():  # the window max of a max is the max of both
            kernels.splat_halved(
                bound, rows + half, cols + half, _halved_window_kernels(self.sigma, self.resolution, half)
            )

    def ensure_levels(self, levels: int) -> None:
        """Build max-pooled grids up to ``2^levels`` cells wide."""
        while len(self.pooled) <= levels:
            s = 1 << (len(self.pooled) - 1)
            self.pooled.append(kernels.max_pool(self.pooled[-1], s))

    def phase(self, level: int, pad: int = 0) -> np.ndarray:
        """:func:`nav.slam.kernels.phase_split` of ``pooled[level]`` at ``2^level`` with ``pad``
        (built once, dropped when :meth:`splat` changes the field)."""
        if (level, pad) not in self._phases:
            self.ensure_levels(level)
            self._phases[level, pad] = kernels.phase_split(self.pooled[level], 1 << level, pad)
        return self._phases[level, pad]

    def window_max(self, half: int) -> np.ndarray:
        """The exhaustive search's per-angle bound, at half resolution: cell (r, c)'s entry is
        ``[(r + half) >> 1, (c + half) >> 1]`` and is at least ``F``'s max over the +-``half`` cell
        window of every cell of its 2 x 2 block (on a grid ``half`` cells wider on each side, then
        halved). A quarter of the cells to clear and a splat of 49 weights instead of 121: on the
        Intel scan-to-scan fields, ~22 us at full resolution, ~11 us now, for 17 % more angles
        scored (the search's result is the same whatever the bound). The first time: a splat of
        the spread kernel at the cells the field was built from (:meth:`from_grid`,
        :meth:`from_points`; the exact window max except next to the grid's edge, where it may be
        more), else the exact window max (:func:`nav.slam.kernels.window_max`, then halved); kept
        up to date by :meth:`splat` (splatting the spread kernel at the new cells: an upper bound,
        which is all the search needs, never a pass over the grid per scan)."""
        if half not in self._window_max:
            if self._splatted is not None:
                rows, cols = self._splatted
                h, w = self.field.shape
                bound = np.zeros(((h + 2 * half + 1) // 2, (w + 2 * half + 1) // 2), dtype=np.float32)
                kernels.splat_halved(
                    bound, rows + half, cols + half, _halved_window_kernels(self.sigma, self.resolution, half)
                )
            else:
                bound = halve_max(kernels.window_max(self.field, half))
            self._window_max[half] = bound
        return self._window_max[half]

    def window_max_reference(self, half: int) -> np.ndarray:
        """Pure-numpy reference of :meth:`window_max`, exact: the window max at full resolution,
        then halved (:func:`halve_max`; the tests compare the two)."""
        p = np.pad(self.field, 2 * half)
        h, w = self.field.shape
        out = np.zeros((h + 2 * half, w + 2 * half), dtype=self.field.dtype)
        for dy in range(2 * half + 1):
            for dx in range(2 * half + 1):
                np.maximum(out, p[dy : dy + h + 2 * half, dx : dx + w + 2 * half], out=out)
        return halve_max(out)

    def pooled_reference(self, level: int) -> np.ndarray:
        """Pure-numpy reference of ``pooled[level]`` (the tests compare it with the kernel's)."""
        g = self.field
        for k in range(level):
            s = 1 << k
            p = np.pad(g, ((0, s), (0, s)))
            g = np.maximum(np.maximum(p[:-s, :-s], p[s:, :-s]), np.maximum(p[:-s, s:], p[s:, s:]))
        return g

    def lookup(self, level: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``pooled[level]`` at integer cells; zero outside the grid."""
        g = self.pooled[level]
        h, w = g.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        flat = g.reshape(-1)
        return np.where(ok, flat[np.where(ok, rows * w + cols, 0)], 0.0)

    def interpolate(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of ``F`` at (N, 2) world points (cell centres are the samples);
        zero outside. ``F`` is already Gaussian-smooth, so bilinear is enough (and cheap)."""
        return self.interpolate_grad(xy)[0]

    def interpolate_grad(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``F`` and its analytic bilinear world-frame gradient (N, 2) at (N, 2) points."""
        g = self.field
        h, w = g.shape
        c = (xy - self.origin) / self.resolution - 0.5
        c0 = np.floor(c).astype(np.int64)
        f = c - c0
        x0, y0 = c0[:, 0], c0[:, 1]
        ok = (x0 >= 0) & (x0 < w - 1) & (y0 >= 0) & (y0 < h - 1)
        idx = np.where(ok, y0 * w + x0, 0)
        flat = g.reshape(-1)
        v00, v01 = flat[idx], flat[idx + 1]
        v10, v11 = flat[idx + w], flat[idx + w + 1]
        fx, fy = f[:, 0], f[:, 1]
        top = v00 + fx * (v01 - v00)
        bot = v10 + fx * (v11 - v10)
        val = np.where(ok, top + fy * (bot - top), 0.0)
        gx = np.where(ok, (1 - fy) * (v01 - v00) + fy * (v11 - v10), 0.0) / self.resolution
        gy = np.where(ok, bot - top, 0.0) / self.resolution
        return val, np.column_stack((gx, gy))


def field_reference(occupied: np.ndarray, sigma: float, resolution: float) -> np.ndarray:
    """Pure-numpy reference of the compiled splat (tests compare the two): ``F`` of a boolean
    occupancy array as the max of shifted, weighted copies of it, one per kernel offset."""
    f = np.zeros(occupied.shape, dtype=np.float32)
    occf = occupied.astype(np.float32)
    h, w = occf.shape
    for dyf, dxf, wt in _kernel(sigma, resolution):
        dy, dx = int(dyf), int(dxf)
        ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
        xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
        np.maximum(f[yd, xd], np.float32(wt) * occf[ys, xs], out=f[yd, xd])
    return f
