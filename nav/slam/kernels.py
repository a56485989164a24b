"""Compiled kernels of the scan matcher (numba); the pure-numpy references they must agree with live
beside their callers (``matcher.score_candidates_reference``, ``matcher.correlative_search_reference``,
``matcher.refine_pose_reference``, ``field.field_reference``, ``LikelihoodField.from_points_reference``,
``LikelihoodField.pooled_reference``) and the tests compare the two.

Scores are float32 sums in numpy's pairwise order (:func:`pairwise_sum32`), so the compiled searches
return bit for bit what the numpy references return: the field's values come from a handful of
kernel weights, equal sums are common, and the earlier float64 sums broke those ties differently
from the numpy code (the benchmark logs' mean errors moved by 0.3-0.6 mm).

Why kernels: a front-end match scores ~1000 candidate poses x 100 points and then runs up to 20
Gauss-Newton steps over ~200 points. In numpy each step builds (candidates x points) int64 index
arrays and masks, or a dozen small arrays per Gauss-Newton iteration, so per-call overhead and
temporaries dominated (4.6 ms per scan-to-scan match against karto-scanmatcher's 1.2 ms, issue 20).
Here every lookup is one load and every sum is accumulated in place.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.np.linalg import ensure_lapack

ensure_lapack()  # scipy's LAPACK, which numba's np.linalg.solve calls too
_DGESV = types.ExternalFunction(
    "numba_xgesv",  # numba's own entry to LAPACK's ?gesv, the one np.linalg.solve uses
    types.intc(
        types.char, types.intp, types.intp, types.CPointer(types.float64), types.intp,
        types.CPointer(types.int32), types.CPointer(types.float64), types.intp,
    ),
)  # fmt: skip


@njit(cache=True, nogil=True)
def _block_sum32(v: np.ndarray, lo: int, n: int) -> np.float32:
    """numpy's float32 sum of a block of n <= 128 values: sequential below 8, else 8 interleaved
    partial sums combined as a tree, then the n % 8 rest added in order."""
    if n < 8:
        res = np.float32(0.0)
        for i in range(n):
            res += v[lo + i]
        return res
    r0, r1, r2, r3 = v[lo], v[lo + 1], v[lo + 2], v[lo + 3]
    r4, r5, r6, r7 = v[lo + 4], v[lo + 5], v[lo + 6], v[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += v[lo + i]
        r1 += v[lo + i + 1]
        r2 += v[lo + i + 2]
        r3 += v[lo + i + 3]
        r4 += v[lo + i + 4]
        r5 += v[lo + i + 5]
        r6 += v[lo + i + 6]
        r7 += v[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += v[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True)
def pairwise_sum32(v: np.ndarray, lo: int, n: int) -> np.float32:
    """Sum of float32 ``v[lo:lo + n]`` in float32, in numpy's order (``pairwise_sum`` of
    numpy/_core/src/umath/loops_utils.h.src: blocks of <= 128 by :func:`_block_sum32`, longer runs
    split in halves rounded down to a multiple of 8), so the result is bit-identical to
    ``v[lo:lo + n].sum()`` and to a row of ``array.sum(axis=1)``. Scores equal to the bit keep
    ties (the field's values come from a handful of kernel weights, so equal sums are common)
    breaking as in the numpy reference. numpy recurses; this walks the same tree with a stack
    (numba's cached functions cannot call a recursive one)."""
    if n <= 128:
        return _block_sum32(v, lo, n)
    los = np.empty(128, dtype=np.int64)  # pending nodes; the tree is ~log2(n) deep
    ns = np.empty(128, dtype=np.int64)
    split = np.zeros(128, dtype=np.bool_)
    sums = np.empty(128, dtype=np.float32)  # finished subtrees' sums
    top, nsum = 1, 0
    los[0], ns[0] = lo, n
    while top > 0:
        k = top - 1
        if ns[k] <= 128:
            sums[nsum] = _block_sum32(v, los[k], ns[k])
            nsum += 1
            top -= 1
        elif split[k]:  # both halves done: left + right
            sums[nsum - 2] = sums[nsum - 2] + sums[nsum - 1]
            nsum -= 1
            split[k] = False
            top -= 1
        else:
            n2 = ns[k] // 2
            n2 -= n2 % 8
            split[k] = True
            los[top], ns[top] = los[k] + n2, ns[k] - n2  # right half, done second
            los[top + 1], ns[top + 1] = los[k], n2  # left half, popped first
            split[top] = split[top + 1] = False
            top += 2
    return sums[0]


@njit(cache=True, nogil=True)
def score_candidates(
    grid: np.ndarray, rows0: np.ndarray, cols0: np.ndarray, cand: np.ndarray, step: int
) -> np.ndarray:
    """float32 mean of ``grid`` at the points of each candidate ``(angle index, dy, dx)`` (offsets
    in units of ``step`` cells); ``rows0`` / ``cols0`` (A, N) are the points' cells at each angle
    and zero offset. Cells outside the grid count 0. Summed as numpy sums (:func:`pairwise_sum32`)."""
    h, w = grid.shape
    n = rows0.shape[1]
    out = np.empty(cand.shape[0], dtype=np.float32)
    vals = np.empty(n, dtype=np.float32)
    nf = np.float32(n)
    for k in range(cand.shape[0]):
        a = cand[k, 0]
        dy = cand[k, 1] * step
        dx = cand[k, 2] * step
        for i in range(n):
            r = rows0[a, i] + dy
            c = cols0[a, i] + dx
            vals[i] = grid[r, c] if 0 <= r < h and 0 <= c < w else np.float32(0.0)
        out[k] = pairwise_sum32(vals, 0, n) / nf
    return out


@njit(cache=True, nogil=True)
def phase_split(grid: np.ndarray, step: int, pad: int = 0) -> np.ndarray:
    """``phase[pr, pc, R + pad, C + pad] = grid[R step + pr, C step + pc]`` (zero past the grid's
    edge, and ``pad`` zero cells around each phase): cells ``step`` (a power of 2, the pooled
    levels' block width) apart in ``grid`` are adjacent in one phase. ``step`` 1 (no ``pad``) is
    the grid itself. With ``pad`` >= a search's block count every block of it lies within the
    padded phases or wholly outside the grid (:func:`block_scores`)."""
    h, w = grid.shape
    if step < 1 or step & (step - 1):
        raise ValueError("step must be a power of 2")
    if step == 1 and pad == 0:
        return grid.reshape((1, 1, h, w))
    shift = 0
    while (1 << shift) < step:
        shift += 1
    phase = np.zeros((step, step, -(-h // step) + 2 * pad, -(-w // step) + 2 * pad), dtype=grid.dtype)
    # row by row: one contiguous read of the grid (phase by phase read each cache line ``step``
    # times: ~1.5x the time)
    for r in range(h):
        pr, rr = r & (step - 1), (r >> shift) + pad
        for pc in range(step):
            dst = phase[pr, pc, rr]
            for cc in range(-(-(w - pc) // step)):
                dst[cc + pad] = grid[r, cc * step + pc]
    return phase


@njit(cache=True, nogil=True, inline="always")
def _add_block(g: np.ndarray, r0: int, c0: int, side: int, stride: int, acc: np.ndarray) -> None:
    """``acc[j, k] += g[r0 + j stride, c0 + k stride]`` over the ``side x side`` block, cells
    outside skipped."""
    h, w = g.shape
    span = (side - 1) * stride
    if r0 >= 0 and c0 >= 0 and r0 + span < h and c0 + span < w:  # the usual case
        for j in range(side):
            for k in range(side):
                acc[j, k] += g[r0 + j * stride, c0 + k * stride]
        return
    for j in range(side):
        r = r0 + j * stride
        if 0 <= r < h:
            for k in range(side):
                c = c0 + k * stride
                if 0 <= c < w:
                    acc[j, k] += g[r, c]


@njit(cache=True, nogil=True, inline="always")
def _cell_value(
    grid: np.ndarray, phase: np.ndarray, shift: int, mask: int, pad: int, r: int, c: int
) -> np.float32:
    """``grid[r, c]``, 0 outside; read from ``phase`` (:func:`phase_split` of the grid at ``1 <<
    shift`` with ``pad``, zero past the grid's edge, so bounded by the phases' extent) when it is
    split."""
    if phase.shape[0] == 1:
        h, w = grid.shape
        return grid[r, c] if 0 <= r < h and 0 <= c < w else np.float32(0.0)
    rr, cc = (r >> shift) + pad, (c >> shift) + pad  # floor division: a negative cell falls outside
    if 0 <= rr < phase.shape[2] and 0 <= cc < phase.shape[3]:
        return phase[r & mask, c & mask, rr, cc]
    return np.float32(0.0)


@njit(cache=True, nogil=True)
def _block_sums(
    grid: np.ndarray,
    phase: np.ndarray,
    step: int,
    r0s: np.ndarray,
    c0s: np.ndarray,
    side: int,
    part: np.ndarray,
    out: np.ndarray,
    pad: int = 0,
) -> None:
    """``out[j, k]`` = float32 sum over the points i of ``grid[r0s[i] + j step, c0s[i] + k step]``
    (0 outside; ``phase`` is :func:`phase_split` of ``grid`` at ``step`` with ``pad``, and then
    ``grid`` is not read, or at 1 to read the grid itself ``step`` apart), in numpy's pairwise
    order. Olson's layout: each point adds its whole ``side x side`` block at once (contiguous
    rows of its phase); with <= 128 points point i goes to partial sum ``i % 8`` (``part``,
    (8, side, side)), as numpy's unrolled sum does; more points fall back to gathering each
    offset's values and :func:`pairwise_sum32`."""
    shift = 0  # steps are powers of 2: shift and mask floor-divide, no idiv per point
    while (1 << shift) < step:
        shift += 1
    mask = step - 1
    split = phase.shape[0] > 1
    n = r0s.shape[0]
    zero = np.float32(0.0)
    if n > 128:
        vals = np.empty(n, dtype=np.float32)
        for j in range(side):
            for k in range(side):
                for i in range(n):
                    vals[i] = _cell_value(grid, phase, shift, mask, pad, r0s[i] + j * step, c0s[i] + k * step)
                out[j, k] = pairwise_sum32(vals, 0, n)
        return
    n8 = n - n % 8 if n >= 8 else 0
    part[:] = zero
    for i in range(n8):
        if not split:  # cells ``step`` apart in the grid itself
            _add_block(grid, r0s[i], c0s[i], side, step, part[i % 8])
        else:
            g = phase[r0s[i] & mask, c0s[i] & mask]
            _add_block(g, (r0s[i] >> shift) + pad, (c0s[i] >> shift) + pad, side, 1, part[i % 8])
    for j in range(side):
        for k in range(side):
            if n8 > 0:
                res = ((part[0, j, k] + part[1, j, k]) + (part[2, j, k] + part[3, j, k])) + (
                    (part[4, j, k] + part[5, j, k]) + (part[6, j, k] + part[7, j, k])
                )
            else:
                res = zero
            for i in range(n8, n):  # outside adds 0: exact
                res += _cell_value(grid, phase, shift, mask, pad, r0s[i] + j * step, c0s[i] + k * step)
            out[j, k] = res


@njit(cache=True, nogil=True, inline="always")
def _bilinear_cell(g: np.ndarray, cx: float, cy: float) -> tuple[float, float, float]:
    """Bilinear value of ``g`` at cell coordinates (cx, cy) (cell centres at integers) and its
    gradient per cell; 0 outside."""
    h, w = g.shape
    x0 = math.floor(cx)
    y0 = math.floor(cy)
    if x0 < 0 or x0 >= w - 1 or y0 < 0 or y0 >= h - 1:
        return 0.0, 0.0, 0.0
    fx = cx - x0
    fy = cy - y0
    xi = int(x0)
    yi = int(y0)
    v00 = g[yi, xi]
    v01 = g[yi, xi + 1]
    v10 = g[yi + 1, xi]
    v11 = g[yi + 1, xi + 1]
    top = v00 + fx * (v01 - v00)
    bot = v10 + fx * (v11 - v10)
    return top + fy * (bot - top), (1 - fy) * (v01 - v00) + fy * (v11 - v10), bot - top


@njit(cache=True, nogil=True, inline="always")
def _bilinear(
    g: np.ndarray, ox: float, oy: float, res: float, x: float, y: float
) -> tuple[float, float, float]:
    """Bilinear value and world-frame gradient of ``g`` (cell centres are samples); 0 outside."""
    f, dx, dy = _bilinear_cell(g, (x - ox) / res - 0.5, (y - oy) / res - 0.5)
    return f, dx / res, dy / res


@njit(cache=True, nogil=True)
def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


@njit(cache=True, nogil=True)
def _solve3(h: np.ndarray, b: np.ndarray, pivots: np.ndarray) -> None:
    """``b`` <- the solution of ``h x = b`` for a symmetric 3 x 3 ``h`` (overwritten by its LU
    factors), in place: LAPACK's dgesv, as ``np.linalg.solve`` calls it, so the same bits, without
    its copies and allocations (~0.65 -> ~0.2 us a call: a third of a Gauss-Newton step). ``h``'s
    row-major buffer is its column-major one, as it is symmetric. Like ``np.linalg.solve``, a
    matrix or right-hand side with infs or NaNs, or a singular matrix, raises ``LinAlgError``."""
    for i in range(3):
        if not math.isfinite(b[i]):
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
        for j in range(3):
            if not math.isfinite(h[i, j]):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    info = _DGESV(ord("d"), 3, 1, h.ctypes, 3, pivots.ctypes, b.ctypes, 3)
    if info > 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


@njit(cache=True, nogil=True)
def gauss_newton(
    g: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    pts: np.ndarray,
    x0: np.ndarray,
    prior: np.ndarray,
    occupied_weight: float,
    wt: float,
    wr: float,
    max_iterations: int,
    tolerance: float,
) -> tuple[np.ndarray, float]:
    """Gauss-Newton on ``sum (1 - F(T p_i))^2 occupied_weight / N`` plus translation / rotation
    priors towards ``prior``; the 3 x 3 normal equations are accumulated point by point (same
    cost function, Jacobian and damping as ``matcher.refine_pose_reference``). Returns the pose
    (x, y, theta wrapped) and the mean field value at it.

    Each step is :func:`_bilinear` at every point, split into passes so that its four divisions
    per point run as vector divisions (the cell coordinates, then the gradients): the same IEEE
    operations on the same values as one call per point, so the same bits, ~25 % faster."""
    n = pts.shape[0]
    x = x0.copy()
    wo2 = occupied_weight / n  # wo^2
    h = np.empty((3, 3))
    b = np.empty(3)
    px = np.ascontiguousarray(pts[:, 0])
    py = np.ascontiguousarray(pts[:, 1])
    cx = np.empty(n)
    cy = np.empty(n)
    dfx = np.empty(n)  # the field's gradient, in cells then in metres
    dfy = np.empty(n)
    f = np.empty(n)
    pivots = np.empty(3, dtype=np.int32)
    for _ in range(max_iterations):
        c, s = math.cos(x[2]), math.sin(x[2])
        for i in range(n):  # the points' cell coordinates (vectorized)
            cx[i] = (c * px[i] - s * py[i] + x[0] - ox) / res - 0.5
            cy[i] = (s * px[i] + c * py[i] + x[1] - oy) / res - 0.5
        for i in range(n):  # bilinear lookups
            f[i], dfx[i], dfy[i] = _bilinear_cell(g, cx[i], cy[i])
        for i in range(n):  # per metre (vectorized; 0 / res is 0 outside)
            dfx[i] = dfx[i] / res
            dfy[i] = dfy[i] / res
        # the sums in locals, not in h and b: LLVM cannot tell those arrays from the ones read
        # here, so it stored and reloaded them every point (the same additions in the same order,
        # so the same bits; ~10 % of a call)
        h00 = h01 = h02 = h11 = h12 = h22 = b0 = b1 = b2 = 0.0
        for i in range(n):
            gx, gy = dfx[i], dfy[i]
            jt = gx * (-s * px[i] - c * py[i]) + gy * (c * px[i] - s * py[i])
            # J row = -wo (gx, gy, jt), residual wo (1 - f): J^T J and J^T r scale by wo^2
            h00 += gx * gx
            h01 += gx * gy
            h02 += gx * jt
            h11 += gy * gy
            h12 += gy * jt
            h22 += jt * jt
            e = 1.0 - f[i]
            b0 -= gx * e
            b1 -= gy * e
            b2 -= jt * e
        h[0, 0], h[0, 1], h[0, 2] = h00 * wo2, h01 * wo2, h02 * wo2
        h[1, 1], h[1, 2], h[2, 2] = h11 * wo2, h12 * wo2, h22 * wo2
        b[0], b[1], b[2] = b0 * wo2, b1 * wo2, b2 * wo2
        h[1, 0] = h[0, 1]
        h[2, 0] = h[0, 2]
        h[2, 1] = h[1, 2]
        h[0, 0] += wt * wt + 1e-9
        h[1, 1] += wt * wt + 1e-9
        h[2, 2] += wr * wr + 1e-9
        b[0] += wt * wt * (x[0] - prior[0])
        b[1] += wt * wt * (x[1] - prior[1])
        b[2] += wr * wr * _wrap(x[2] - prior[2])
        _solve3(h, b, pivots)  # b <- h^-1 b (h destroyed)
        for k in range(3):
            x[k] -= b[k]
        if max(abs(b[0]), abs(b[1]), abs(b[2])) < tolerance:
            break
    x[2] = _wrap(x[2])
    c, s = math.cos(x[2]), math.sin(x[2])
    acc = 0.0
    for i in range(n):
        acc += _bilinear(g, ox, oy, res, c * px[i] - s * py[i] + x[0], s * px[i] + c * py[i] + x[1])[0]
    return x, acc / n


@njit(cache=True, nogil=True)
def window_max(grid: np.ndarray, half: int) -> np.ndarray:
    """``out[r + half, c + half]`` = max of ``grid`` over ``[r - half, r + half] x [c - half, c +
    half]`` (cells outside count 0), on a grid ``half`` cells wider on every side: the most any
    point based at cell (r, c) can score over the offsets of a +-``half`` search window, so a sum
    of these over an angle's points bounds every candidate at that angle. A chain of
    :func:`max_pool` steps on the zero-padded grid (windows of 2, 4, ... cells, then the rest),
    whose branch-free passes vectorize."""
    h, w = grid.shape
    span = 2 * half + 1
    q = np.zeros((h + 4 * half, w + 4 * half), dtype=grid.dtype)
    q[2 * half : 2 * half + h, 2 * half : 2 * half + w] = grid
    width = 1  # q[r, c] is the max over the width x width block starting at (r, c)
    while 2 * width <= span:
        q = max_pool(q, width)
        width *= 2
    if width < span:  # two overlapping blocks of `width` cover `span`
        q = max_pool(q, span - width)
    return q[: h + 2 * half, : w + 2 * half].copy()


@njit(cache=True, nogil=True, inline="always")
def _splat_one(field: np.ndarray, r: int, c: int, kernel: np.ndarray) -> None:
    """``field[r + dy, c + dx] = max(field, kernel[dy + R, dx + R])`` for the dense square
    ``kernel`` ((2 R + 1)^2 weights centred on (r, c)), the part outside the grid skipped."""
    h, w = field.shape
    rad = kernel.shape[0] // 2
    r0, c0 = r - rad, c - rad
    if r0 >= 0 and c0 >= 0 and r0 + 2 * rad < h and c0 + 2 * rad < w:  # the usual case
        for j in range(2 * rad + 1):
            for k in range(2 * rad + 1):
                v, kv = field[r0 + j, c0 + k], kernel[j, k]
                field[r0 + j, c0 + k] = kv if kv > v else v
        return
    _splat_clipped(field, r0, c0, kernel, 2 * rad + 1)


@njit(cache=True, nogil=True, inline="always")
def _splat_clipped(field: np.ndarray, r0: int, c0: int, kernel: np.ndarray, size: int) -> None:
    """``field[r0 + j, c0 + k] = max(field, kernel[j, k])`` for j, k < ``size`` (the kernel's
    top-left corner at (r0, c0)), the part outside the grid skipped."""
    h, w = field.shape
    for j in range(max(-r0, 0), min(h - r0, size)):
        for k in range(max(-c0, 0), min(w - c0, size)):
            v, kv = field[r0 + j, c0 + k], kernel[j, k]
            field[r0 + j, c0 + k] = kv if kv > v else v


@njit(cache=True, nogil=True, inline="always")
def _splat_rows8(field: np.ndarray, r: int, c: int, kernel8: np.ndarray, size: int) -> None:
    """:func:`_splat_one` of a ``size`` x ``size`` kernel (``size`` <= 8) given zero-padded to 8
    columns (``kernel8``): away from the grid's right edge every row is one 8-wide max (a max with
    the padding's 0 leaves a field value, >= 0, as it was), instead of ``size`` scalar ones."""
    h, w = field.shape
    rad = size // 2
    r0, c0 = r - rad, c - rad
    if r0 >= 0 and c0 >= 0 and r0 + size <= h and c0 + 8 <= w:
        for j in range(size):
            for k in range(8):
                v, kv = field[r0 + j, c0 + k], kernel8[j, k]
                field[r0 + j, c0 + k] = kv if kv > v else v
        return
    _splat_clipped(field, r0, c0, kernel8, size)


@njit(cache=True, nogil=True)
def _pad8(kernel: np.ndarray) -> np.ndarray:
    """A square kernel of <= 8 columns, zero-padded to 8 (:func:`_splat_rows8`)."""
    out = np.zeros((kernel.shape[0], 8), dtype=kernel.dtype)
    out[:, : kernel.shape[1]] = kernel
    return out


@njit(cache=True, nogil=True)
def splat_dense(field: np.ndarray, rows: np.ndarray, cols: np.ndarray, kernel: np.ndarray) -> None:
    """The maxima of a dense square ``kernel`` ((2 R + 1)^2 weights centred on the cell), row
    by row: ``field[r + dy, c + dx] = max(field, kernel[dy + R, dx + R])``, in place, the part
    outside the grid skipped. Contiguous rows vectorize (~2x faster than a list of offsets); a
    kernel of <= 8 columns (the field's 7 x 7) as 8-wide rows (~30 % less time)."""
    size = kernel.shape[0]
    if size <= 8:
        k8 = _pad8(kernel)
        for i in range(rows.shape[0]):
            _splat_rows8(field, rows[i], cols[i], k8, size)
        return
    for i in range(rows.shape[0]):
        _splat_one(field, rows[i], cols[i], kernel)


@njit(cache=True, nogil=True)
def splat_halved(bound: np.ndarray, rows: np.ndarray, cols: np.ndarray, kernels: np.ndarray) -> None:
    """:func:`splat_dense` on a half-resolution grid: the kernel splatted at full-resolution cell
    (r, c) lands on half-resolution cell (r >> 1, c >> 1) as ``kernels[r & 1, c & 1]`` (each
    parity's 2 x 2 maxima of the full-resolution kernel, ``field._halved_window_kernels``)."""
    size = kernels.shape[2]
    if size <= 8:
        k8 = np.zeros((2, 2, size, 8), dtype=kernels.dtype)
        for pr in range(2):
            for pc in range(2):
                k8[pr, pc] = _pad8(kernels[pr, pc])
        for i in range(rows.shape[0]):
            r, c = rows[i], cols[i]
            _splat_rows8(bound, r >> 1, c >> 1, k8[r & 1, c & 1], size)
        return
    for i in range(rows.shape[0]):
        r, c = rows[i], cols[i]
        _splat_one(bound, r >> 1, c >> 1, kernels[r & 1, c & 1])


@njit(cache=True, nogil=True, inline="always")
def _before(a: int, dy: int, dx: int, ba: int, bdy: int, bdx: int) -> bool:
    """(a, dy, dx) comes before (ba, bdy, bdx) in the search's (angle, dy, dx) order."""
    return a < ba or (a == ba and (dy < bdy or (dy == bdy and dx < bdx)))


@njit(cache=True, nogil=True)
def _angle_bounds(bound: np.ndarray, rows0: np.ndarray, cols0: np.ndarray, wc: int) -> np.ndarray:
    """Each angle's bound: :func:`score_candidates` of ``bound`` at the points' half-resolution
    cells ``((rows0 + wc) >> 1, (cols0 + wc) >> 1)``, offset 0, the same sums, without the four
    (A, N) index arrays (~130 KB written a search)."""
    na, n = rows0.shape
    h, w = bound.shape
    ub = np.empty(na, dtype=np.float32)
    vals = np.empty(n, dtype=np.float32)
    nf = np.float32(n)
    for a in range(na):
        for i in range(n):
            r = (rows0[a, i] + wc) >> 1
            c = (cols0[a, i] + wc) >> 1
            vals[i] = bound[r, c] if 0 <= r < h and 0 <= c < w else np.float32(0.0)
        ub[a] = pairwise_sum32(vals, 0, n) / nf
    return ub


@njit(cache=True, nogil=True)
def exhaustive_search(
    grid: np.ndarray,
    bound: np.ndarray,
    rows0: np.ndarray,
    cols0: np.ndarray,
    wc: int,
    res: float,
    separation: float,
) -> tuple[int, int, int, float, float]:
    """The exhaustive (single-level) correlative search in one pass: every angle ``a``, every cell
    offset (dy, dx) in [-wc, wc]^2 of the points' cells ``rows0`` / ``cols0`` (A, N) at that angle
    (:func:`rotated_cells`). Returns the best (a, dy, dx), its score (float32 mean ``grid`` value,
    0 outside, summed as numpy sums) and the best score of the candidates more than
    ``separation`` (m) from it (0 if none; not searched when ``separation`` is infinite). Ties go
    to the candidate nearest the prior (|dy| + |dx| + |a - centre|), then to the first in
    (a, dy, dx) order, as in ``matcher.correlative_search_reference``.

    Without a runner-up, angles are scored in the order of their bound (``bound`` is
    ``LikelihoodField.window_max(wc)``: :func:`window_max` of ``grid`` at ``wc``, or more, at half
    resolution, cell (r + wc, c + wc) at (r + wc) >> 1, (c + wc) >> 1) and the search stops at the
    first angle whose bound is below the best score found: none of the rest can reach it, so the
    result is the full search's, bit for bit (the tie-break compares (a, dy, dx) explicitly)."""
    na, n = rows0.shape
    side = 2 * wc + 1
    runner = separation < math.inf
    phase = phase_split(grid, 1)
    scores = np.empty((na if runner else 1, side, side), dtype=np.float32)
    part = np.empty((8, side, side), dtype=np.float32)
    sums = np.empty((side, side), dtype=np.float32)
    nf = np.float32(n)
    centre = (na - 1) // 2
    if runner:
        order = np.arange(na)
        ub = np.full(na, np.float32(np.inf))
    else:
        # each angle's points' window maxima (at half resolution: the max over a 2 x 2 block
        # of cells' windows), summed as the scores are: float32 rounding is monotone, so this is
        # at least every score at that angle, bit for bit (an exact bound)
        ub = _angle_bounds(bound, rows0, cols0, wc)
        order = np.argsort(-ub)
    best = np.float32(-1.0)
    best_dist = 0
    ba, bdy, bdx = na, 0, 0
    for a in order:
        if ub[a] < best:
            break  # sorted: no later angle can reach the best either
        _block_sums(grid, phase, 1, rows0[a] - wc, cols0[a] - wc, side, part, sums)
        for j in range(side):
            for k in range(side):
                sc = sums[j, k] / nf
                if runner:
                    scores[a, j, k] = sc
                if sc < best:
                    continue
                dist = abs(j - wc) + abs(k - wc) + abs(a - centre)
                if (
                    sc > best
                    or dist < best_dist
                    or (dist == best_dist and _before(a, j - wc, k - wc, ba, bdy, bdx))
                ):
                    best, best_dist, ba, bdy, bdx = sc, dist, a, j - wc, k - wc
    runner_up = np.float32(0.0)
    if runner:
        for a in range(na):
            for dy in range(-wc, wc + 1):
                for dx in range(-wc, wc + 1):
                    if math.hypot(dy - bdy, dx - bdx) * res > separation:
                        runner_up = max(runner_up, scores[a, dy + wc, dx + wc])
    return ba, bdy, bdx, float(best), float(runner_up)


@njit(cache=True, nogil=True)
def exhaustive_search_of_points(
    grid: np.ndarray,
    bound: np.ndarray,
    pts: np.ndarray,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    px: float,
    py: float,
    ox: float,
    oy: float,
    res: float,
    wc: int,
) -> tuple[int, int, int, float]:
    """:func:`rotated_cells` then :func:`exhaustive_search` (angle-bounded, no runner-up) in one
    call: the SLAM front end's narrow search runs once per scan, and the two calls' Python-side
    dispatch and the (A, N) cell arrays handed back and forth were ~15 % of it."""
    rows0, cols0 = rotated_cells(pts, cos_t, sin_t, px, py, ox, oy, res)
    a, dy, dx, best, _ = exhaustive_search(grid, bound, rows0, cols0, wc, res, math.inf)
    return a, dy, dx, best


@njit(cache=True, nogil=True)
def exhaustive_match(
    grid: np.ndarray,
    bound: np.ndarray,
    search_pts: np.ndarray,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    px: float,
    py: float,
    ox: float,
    oy: float,
    res: float,
    wc: int,
    thetas: np.ndarray,
    refine_pts: np.ndarray,
    occupied_weight: float,
    wt: float,
    wr: float,
    max_iterations: int,
    tolerance: float,
) -> tuple[np.ndarray, float, np.ndarray, float]:
    """:func:`exhaustive_search_of_points` (``search_pts`` at the angles ``thetas``, whose cosines
    and sines are given), then :func:`gauss_newton` of ``refine_pts`` from and towards its pose, in
    one call (the SLAM front end's match of every scan; the Python between the two was ~5 % of a
    scan-to-scan match). Returns the search's pose (x, y, theta wrapped, as ``matcher`` builds it)
    and score, then the refined pose and its mean field value."""
    a, dy, dx, best = exhaustive_search_of_points(
        grid, bound, search_pts, cos_t, sin_t, px, py, ox, oy, res, wc
    )
    coarse = np.empty(3)
    coarse[0] = px + dx * res
    coarse[1] = py + dy * res
    coarse[2] = _wrap(thetas[a])
    x, score = gauss_newton(
        grid, ox, oy, res, refine_pts, coarse, coarse, occupied_weight, wt, wr, max_iterations, tolerance
    )
    return coarse, best, x, score


@njit(cache=True, nogil=True)
def max_pool(prev: np.ndarray, s: int) -> np.ndarray:
    """``out[r, c] = max(prev[r, c], prev[r + s, c], prev[r, c + s], prev[r + s, c + s])`` (zero
    outside): the next max-pooled level, each cell the max over a block twice as wide. Separable
    (a max along rows, then along columns: max is exact, so the order changes nothing) with
    branch-free contiguous inner loops."""
    h, w = prev.shape
    rows = np.empty_like(prev)
    for r in range(h):
        for c in range(w - s):
            rows[r, c] = max(prev[r, c], prev[r, c + s])
        for c in range(max(w - s, 0), w):
            rows[r, c] = max(prev[r, c], np.float32(0.0))
    out = np.empty_like(prev)
    for r in range(h - s):
        for c in range(w):
            out[r, c] = max(rows[r, c], rows[r + s, c])
    for r in range(max(h - s, 0), h):
        for c in range(w):
            out[r, c] = max(rows[r, c], np.float32(0.0))
    return out


@njit(cache=True, nogil=True)
def block_scores(
    phase: np.ndarray, rows0: np.ndarray, cols0: np.ndarray, lo: int, nb: int, step: int, pad: int = 0
) -> np.ndarray:
    """(A, nb, nb) float32 scores of the whole top level of a coarse-to-fine search: at angle
    ``a`` the block offset (lo + j, lo + k) in units of ``step`` cells; the same sums, bit for
    bit, as :func:`score_candidates` over all (a, j, k) on the pooled grid, accumulated point by
    point on its phases (Olson's layout). ``phase`` is :func:`phase_split` of that grid at ``step``
    with ``pad`` (only it is read): always worth it, as reading a large submap in place ``step``
    cells apart (loop closure, step 16) missed the cache on nearly every read (a cold FR079 submap,
    81 angles: ~1.0 -> ~0.7 ms); the caller may keep it (``LikelihoodField.phase``) while the grid
    is unchanged, or build it without the grid (:func:`points_phase`).

    With ``pad >= nb`` and <= 128 points each point's block lies within the padded phases or wholly
    outside the grid (then it reads ``nb x nb`` zeros of the padding instead), so every angle is
    summed by :func:`_lane_sums` (unpadded, only the ~1 in 8 angles of the wide re-search on the
    Intel relation pairs whose 24 points all lay inside were)."""
    if step == 1 and pad != 0:
        raise ValueError("a step-1 top level is the grid itself, unpadded")
    na, n = rows0.shape
    out = np.empty((na, nb, nb), dtype=np.float32)
    part = np.empty((8, nb, nb), dtype=np.float32)
    nf = np.float32(n)
    grid = phase[0, 0]  # the grid itself when ``step`` is 1 (a single phase); else unread
    shift = 0
    while (1 << shift) < step:
        shift += 1
    mask = step - 1
    ph, pw = phase.shape[2], phase.shape[3]
    flat = phase.ravel()
    n8 = n - n % 8 if 8 <= n <= 128 else 0
    offs = np.empty(max(n8, 1), dtype=np.int64)
    r0s = np.empty(n, dtype=np.int64)
    c0s = np.empty(n, dtype=np.int64)
    for a in range(na):
        for i in range(n):
            r0s[i] = rows0[a, i] + lo * step
            c0s[i] = cols0[a, i] + lo * step
        inside = n8 > 0
        for i in range(n8):
            rr, cc = (r0s[i] >> shift) + pad, (c0s[i] >> shift) + pad
            misses = rr + nb <= pad or cc + nb <= pad or rr >= ph - pad or cc >= pw - pad
            if misses and pad >= nb:  # the padding's top-left nb x nb zeros
                offs[i] = 0
                continue
            if rr < 0 or cc < 0 or rr + nb > ph or cc + nb > pw:
                inside = False
                break
            offs[i] = ((r0s[i] & mask) * step + (c0s[i] & mask)) * (ph * pw) + rr * pw + cc
        if inside:  # every block within its phase: 8 partial sums in registers
            _lane_sums(flat, offs, n8 // 8, nb, pw, out[a])
            for j in range(nb):
                for k in range(nb):
                    res = out[a, j, k]
                    for i in range(n8, n):
                        res += _cell_value(
                            grid, phase, shift, mask, pad, r0s[i] + j * step, c0s[i] + k * step
                        )
                    out[a, j, k] = res
        else:
            _block_sums(grid, phase, step, r0s, c0s, nb, part, out[a], pad)
        for j in range(nb):
            for k in range(nb):
                out[a, j, k] /= nf
    return out


@njit(cache=True, nogil=True, inline="always")
def _lane_sums(flat: np.ndarray, offs: np.ndarray, groups: int, side: int, row: int, out: np.ndarray) -> None:
    """``out[j, k]`` = :func:`_block_sums`' float32 sum over ``8 groups`` points of
    ``flat[offs[i] + j row + k]``, every cell inside: point i in partial sum ``i % 8``, the 8
    combined as a tree (numpy's order), one offset at a time so that the 8 partial sums stay in
    registers (~25 % faster than adding each point's block to 8 blocks of partial sums in memory).
    """
    for j in range(side):
        for k in range(side):
            d = j * row + k
            s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = np.float32(0.0)
            for g in range(groups):
                b = 8 * g
                s0 += flat[offs[b] + d]
                s1 += flat[offs[b + 1] + d]
                s2 += flat[offs[b + 2] + d]
                s3 += flat[offs[b + 3] + d]
                s4 += flat[offs[b + 4] + d]
                s5 += flat[offs[b + 5] + d]
                s6 += flat[offs[b + 6] + d]
                s7 += flat[offs[b + 7] + d]
            out[j, k] = ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))


@njit(cache=True, nogil=True)
def rotated_cells(
    pts: np.ndarray,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    px: float,
    py: float,
    ox: float,
    oy: float,
    res: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(A, N) rows and columns of the grid cells of points ``pts`` rotated by each angle (its cos /
    sin given, from numpy so both sides use the same values) and moved to (px, py): the same
    float64 operations in the same order as ``matcher._rotations`` and the numpy floor that
    follows it, so the cells are identical (a tie at a cell border goes the same way)."""
    na, n = cos_t.shape[0], pts.shape[0]
    rows = np.empty((na, n), dtype=np.int64)
    cols = np.empty((na, n), dtype=np.int64)
    xs = np.ascontiguousarray(pts[:, 0])
    ys = np.ascontiguousarray(pts[:, 1])
    qx = np.empty(n)
    qy = np.empty(n)
    for a in range(na):
        c, s = cos_t[a], sin_t[a]
        for i in range(n):  # vectorized divisions (same IEEE operations, same bits)
            qx[i] = (c * xs[i] - s * ys[i] + px - ox) / res
            qy[i] = (s * xs[i] + c * ys[i] + py - oy) / res
        for i in range(n):
            cols[a, i] = math.floor(qx[i])
            rows[a, i] = math.floor(qy[i])
    return rows, cols


@njit(cache=True, nogil=True)
def points_field(
    points: np.ndarray, resolution: float, margin: float, kernel: np.ndarray
) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray]:
    """The likelihood field of the cells hit by (N, 2) ``points`` on a grid covering them plus
    ``margin``, the grid's origin (x, y) and the points' cells (rows, cols), in one call: the same
    float64 operations as ``LikelihoodField.from_points_reference``'s numpy expressions (so the
    same origin and cells), then :func:`splat_dense` of ``kernel`` (dense, square)."""
    lo = np.empty(2)
    hi = np.empty(2)
    for d in range(2):
        mn, mx = points[0, d], points[0, d]
        for i in range(1, points.shape[0]):
            mn = min(mn, points[i, d])
            mx = max(mx, points[i, d])
        lo[d] = math.floor((mn - margin) / resolution) * resolution
        hi[d] = math.floor((mx + margin - lo[d]) / resolution) + 1
    field = np.zeros((int(hi[1]), int(hi[0])), dtype=np.float32)
    rows, cols = points_cells(points, lo[0], lo[1], resolution)
    splat_dense(field, rows, cols, kernel)
    return field, lo[0], lo[1], rows, cols


@njit(cache=True, nogil=True)
def points_cells(
    points: np.ndarray, ox: float, oy: float, resolution: float
) -> tuple[np.ndarray, np.ndarray]:
    """The (rows, cols) of the cells of (N, 2) ``points`` on a grid of origin (``ox``, ``oy``)."""
    n = points.shape[0]
    rows = np.empty(n, dtype=np.int64)
    cols = np.empty(n, dtype=np.int64)
    for i in range(n):
        cols[i] = math.floor((points[i, 0] - ox) / resolution)
        rows[i] = math.floor((points[i, 1] - oy) / resolution)
    return rows, cols


@njit(cache=True, nogil=True)
def pooled_kernel(kernel: np.ndarray, step: int) -> np.ndarray:
    """The splat kernel of a max-pooled level: ``out[d] = max over u, v in [0, step) of
    kernel[d + (u, v)]`` for offsets d from ``-(R + step - 1)`` to ``R`` (``kernel``: (2 R + 1)^2,
    centred). A field that is the maxima of ``kernel`` splatted at some cells, max-pooled over
    ``step x step`` blocks (:func:`max_pool`'s levels: each cell the max over the block starting
    there), is the maxima of this kernel at the same cells, its top-left corner ``R + step - 1``
    cells up and left of the cell (:func:`points_pooled`)."""
    size = kernel.shape[0]
    out = np.zeros((size + step - 1, size + step - 1), dtype=kernel.dtype)
    for i in range(size + step - 1):
        for j in range(size + step - 1):
            m = out[i, j]  # 0, of the kernel's type
            for u in range(step):
                for v in range(step):
                    y, x = i + u - (step - 1), j + v - (step - 1)
                    if 0 <= y < size and 0 <= x < size and kernel[y, x] > m:
                        m = kernel[y, x]
            out[i, j] = m
    return out


@njit(cache=True, nogil=True)
def points_fit(rows: np.ndarray, cols: np.ndarray, radius: int, h: int, w: int) -> bool:
    """Whether a kernel of ``radius`` splatted at every cell lies inside the ``h x w`` grid (then
    :func:`points_pooled` and :func:`points_phase` give exactly the pooled levels of the field and
    their phases: no weight was clipped at the grid's edge)."""
    for i in range(rows.shape[0]):
        if rows[i] < radius or cols[i] < radius or rows[i] + radius >= h or cols[i] + radius >= w:
            return False
    return True


@njit(cache=True, nogil=True)
def points_pooled(
    rows: np.ndarray, cols: np.ndarray, kernel: np.ndarray, step: int, h: int, w: int
) -> np.ndarray:
    """``pooled[level]`` (``step = 2^level``, :func:`max_pool`'s chain) of the ``h x w`` field
    made of ``kernel`` splatted at the cells ``rows`` / ``cols``, without the field: the maxima of
    :func:`pooled_kernel` at those cells, which is exact when :func:`points_fit` (the field's own
    splats were not clipped). A few hundred small splats instead of two passes over the grid a level
    (a scan's field: ~350 x 320 cells for ~180 returns)."""
    k = pooled_kernel(kernel, step)
    off = kernel.shape[0] // 2 + step - 1
    size = k.shape[0]
    out = np.zeros((h, w), dtype=kernel.dtype)
    for i in range(rows.shape[0]):
        _splat_clipped(out, rows[i] - off, cols[i] - off, k, size)
    return out


@njit(cache=True, nogil=True)
def points_phase(
    rows: np.ndarray, cols: np.ndarray, kernel: np.ndarray, step: int, h: int, w: int, pad: int = 0
) -> np.ndarray:
    """:func:`phase_split` at ``step`` with ``pad`` of :func:`points_pooled` (the same
    conditions), splatted straight into the phases: the pooled grid is never built."""
    k = pooled_kernel(kernel, step)
    off = kernel.shape[0] // 2 + step - 1
    size = k.shape[0]
    shift = 0
    while (1 << shift) < step:
        shift += 1
    mask = step - 1
    phase = np.zeros((step, step, -(-h // step) + 2 * pad, -(-w // step) + 2 * pad), dtype=kernel.dtype)
    for i in range(rows.shape[0]):
        r0, c0 = rows[i] - off, cols[i] - off
        for y in range(max(-r0, 0), min(h - r0, size)):
            r = r0 + y
            for x in range(max(-c0, 0), min(w - c0, size)):
                c = c0 + x
                pr, pc, rr, cc = r & mask, c & mask, (r >> shift) + pad, (c >> shift) + pad
                v, kv = phase[pr, pc, rr, cc], k[y, x]
                phase[pr, pc, rr, cc] = kv if kv > v else v
    return phase


@njit(cache=True, nogil=True)
def window_moments(pts: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point of (N, 2) ``pts`` (beam order): the second moments ``cxx, cyy, cxy`` (N,) of the
    ``2 half + 1`` points around it (indices clipped to the ends) about their mean, for
    :func:`nav.slam.matcher.translation_information`. Summed sequentially and divided by the count,
    as numpy's ``mean(axis=1)`` does over so few values, so the moments are bit-identical to
    :func:`nav.slam.matcher.window_moments_reference` (no (N, W, 2) gather, 30x less time)."""
    n = pts.shape[0]
    w = 2 * half + 1
    cxx, cyy, cxy = np.empty(n), np.empty(n), np.empty(n)
    dx, dy = np.empty(w), np.empty(w)
    for i in range(n):
        sx = 0.0
        sy = 0.0
        for k in range(w):
            j = min(max(i - half + k, 0), n - 1)
            sx += pts[j, 0]
            sy += pts[j, 1]
        mx, my = sx / w, sy / w
        for k in range(w):
            j = min(max(i - half + k, 0), n - 1)
            dx[k] = pts[j, 0] - mx
            dy[k] = pts[j, 1] - my
        a = 0.0
        b = 0.0
        c = 0.0
        for k in range(w):
            a += dx[k] * dx[k]
            b += dy[k] * dy[k]
            c += dx[k] * dy[k]
        cxx[i], cyy[i], cxy[i] = a / w, b / w, c / w
    return cxx, cyy, cxy


@njit(cache=True, nogil=True)
def surface_lines(pts: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nav.slam.matcher.surface_lines` from :func:`window_moments` without numpy's
    per-call overhead (a dozen small array operations per scan); the same libm calls in the same
    order, so bit-identical to :func:`nav.slam.matcher.surface_lines_reference`."""
    cxx, cyy, cxy = window_moments(pts, half)
    n = pts.shape[0]
    along = np.empty(n)
    line = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        along[i] = 0.5 * np.arctan2(2 * cxy[i], cxx[i] - cyy[i])
        spread = np.hypot(0.5 * (cxx[i] - cyy[i]), cxy[i])
        hi = 0.5 * (cxx[i] + cyy[i]) + spread
        lo = 0.5 * (cxx[i] + cyy[i]) - spread
        line[i] = lo <= 0.05 * hi and hi > 0 and half <= i < n - half
    return along, line


@njit(cache=True, nogil=True)
def surface_normals(along: np.ndarray, line: np.ndarray, theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals ``(-sin, cos)`` of the lines ``along + theta`` where ``line`` holds."""
    k = 0
    for i in range(along.shape[0]):
        if line[i]:
            k += 1
    nx, ny = np.empty(k), np.empty(k)
    k = 0
    for i in range(along.shape[0]):
        if line[i]:
            a = along[i] + theta
            nx[k] = -np.sin(a)
            ny[k] = np.cos(a)
            k += 1
    return nx, ny


@njit(cache=True, nogil=True)
def accumulate_normal_equations(
    poses: np.ndarray,
    ei: np.ndarray,
    ej: np.ndarray,
    scale: np.ndarray,
    r: np.ndarray,
    pos: np.ndarray,
    data: np.ndarray,
    g: np.ndarray,
) -> None:
    """Pose graph (:mod:`nav.slam.pose_graph`): adds each edge's ``J^T J`` blocks into the CSC
    ``data`` of H at ``pos`` (E, 4, 9: the edge's ii, ij, ji, jj blocks, row-major) and ``-J^T r``
    into ``g``. ``scale`` (E, 3) is ``sqrt_info * w``, ``r`` (E, 3) the scaled errors. Reference:
    ``pose_graph.normal_equations_reference`` (the sparse product ``J^T J``)."""
    ja = np.zeros((3, 3))
    jb = np.zeros((3, 3))
    for e in range(ei.shape[0]):
        i, j = ei[e], ej[e]
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        dx, dy = poses[j, 0] - poses[i, 0], poses[j, 1] - poses[i, 1]
        q0, q1, q2 = scale[e, 0], scale[e, 1], scale[e, 2]
        ja[0, 0], ja[0, 1], ja[0, 2] = -c * q0, -s * q0, (-s * dx + c * dy) * q0
        ja[1, 0], ja[1, 1], ja[1, 2] = s * q1, -c * q1, (-c * dx - s * dy) * q1
        ja[2, 0], ja[2, 1], ja[2, 2] = 0.0, 0.0, -q2
        jb[0, 0], jb[0, 1], jb[0, 2] = c * q0, s * q0, 0.0
        jb[1, 0], jb[1, 1], jb[1, 2] = -s * q1, c * q1, 0.0
        jb[2, 0], jb[2, 1], jb[2, 2] = 0.0, 0.0, q2
        for a in range(3):
            ga = 0.0
            gb = 0.0
            for k in range(3):
                ga += ja[k, a] * r[e, k]
                gb += jb[k, a] * r[e, k]
            g[3 * i + a] -= ga
            g[3 * j + a] -= gb
            for b in range(3):
                hii = 0.0
                hij = 0.0
                hjj = 0.0
                for k in range(3):
                    hii += ja[k, a] * ja[k, b]
                    hij += ja[k, a] * jb[k, b]
                    hjj += jb[k, a] * jb[k, b]
                data[pos[e, 0, 3 * a + b]] += hii
                data[pos[e, 1, 3 * a + b]] += hij
                data[pos[e, 2, 3 * b + a]] += hij
                data[pos[e, 3, 3 * a + b]] += hjj


@njit(cache=True, nogil=True, inline="always")
def _submap_cell(
    px: float, py: float, x: float, y: float, cth: float, sth: float, ox: float, oy: float,
    lo: np.ndarray, sn: np.ndarray, res: float,
) -> tuple[float, bool]:  # fmt: skip
    """Log-odds (0 where not observed) and observed flag of the submap cell under map point (px, py)."""
    dx, dy = px - x, py - y
    sc = math.floor((cth * dx + sth * dy - ox) / res)
    sr = math.floor((-sth * dx + cth * dy - oy) / res)
    if 0 <= sr < lo.shape[0] and 0 <= sc < lo.shape[1] and sn[sr, sc]:
        return float(lo[sr, sc]), True
    return 0.0, False


@njit(cache=True, nogil=True)
def place_submap(
    pose: np.ndarray,
    origin: np.ndarray,
    lo: np.ndarray,
    sn: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    res: float,
    sample: float,
    surface_wins: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Map rendering (:mod:`nav.slam.render`): a submap's log-odds and observed mask at the map cells
    centred at (gx[c], gy[r]) by inverse nearest-neighbour lookup; with ``surface_wins`` the most
    occupied of the cells ``sample`` m from the centre towards each corner replaces it when above 0.
    The same float operations as the numpy references ``render._lookup`` / ``render._surface_wins``
    (equal arrays, tested)."""
    x, y, th = pose[0], pose[1], pose[2]
    cth, sth = math.cos(th), math.sin(th)
    ox, oy = origin[0], origin[1]
    val = np.empty((gy.shape[0], gx.shape[0]))
    ok = np.empty((gy.shape[0], gx.shape[0]), dtype=np.bool_)
    for r in range(gy.shape[0]):
        for c in range(gx.shape[0]):
            v, o = _submap_cell(gx[c], gy[r], x, y, cth, sth, ox, oy, lo, sn, res)
            if surface_wins:
                best = -np.inf
                for k in range(4):
                    sx = sample if k % 2 else -sample
                    sy = sample if k // 2 else -sample
                    v2, o2 = _submap_cell(gx[c] + sx, gy[r] + sy, x, y, cth, sth, ox, oy, lo, sn, res)
                    if o2 and v2 > best:
                        best = v2
                if best > 0.0:
                    v, o = best, True
            val[r, c] = v
            ok[r, c] = o
    return val, ok


@njit(cache=True, nogil=True)
def observed_by_scan(
    ranges: np.ndarray,
    range_min: float,
    range_limit: float,
    angle_min: float,
    angle_increment: float,
    points: np.ndarray,
    pose: np.ndarray,
    margin: float,
) -> np.ndarray:
    """(N,) bool: each of the (N, 2) points, moved by ``pose`` (x, y, cos, sin) into the scan's
    frame, lies within the range its beam or a neighbouring beam returned, plus ``margin``
    (``coverage.observed_by_scan``; the same float64 operations as
    ``coverage.observed_by_scan_reference``). A beam without a valid return (not finite, below
    ``range_min``, beyond ``range_limit``) reaches nothing."""
    n = ranges.shape[0]
    reach = np.empty(n)
    for j in range(n):
        r = ranges[j]
        reach[j] = r if (r >= range_min and r <= range_limit) else 0.0  # False for nan and inf
    full_circle = n * angle_increment >= 2.0 * math.pi - 0.5 * angle_increment
    x0, y0, c, s = pose[0], pose[1], pose[2], pose[3]
    out = np.zeros(points.shape[0], dtype=np.bool_)
    for i in range(points.shape[0]):
        x = c * points[i, 0] - s * points[i, 1] + x0
        y = s * points[i, 0] + c * points[i, 1] + y0
        bearing = math.atan2(y, x) - angle_min
        if bearing < 0.0:  # bearings from angle_min round the circle
            bearing += 2.0 * math.pi
        elif bearing >= 2.0 * math.pi:
            bearing -= 2.0 * math.pi
        k = math.floor(bearing / angle_increment + 0.5)
        if k > n - 1:
            if not full_circle:
                continue  # behind a scan that does not go all round
            k = 0  # the last half-beam of a full circle is the first beam's
        j = int(k)
        far = reach[j]
        if j > 0:
            far = max(far, reach[j - 1])
        if j < n - 1:
            far = max(far, reach[j + 1])
        reach_m = far + margin
        out[i] = x * x + y * y <= reach_m * reach_m
    return out
