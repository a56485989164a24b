"""The coarse-to-fine beam search, compiled (the wide re-search, loop closure and the global
search: :func:`nav.slam.matcher.correlative_search` with ``levels > 0``), in one call
(:func:`beam_search`).

The top level's blocks are all scored (:func:`nav.slam.kernels.block_scores`); then a level at a
time the ``beam`` best candidates are kept (:func:`keep_best`: ties to the earlier candidate, kept in
candidate order), each is split into its 4 children and they are scored; the last level picks the
best (:func:`best_candidate`). Scoring a parent's 4 children is one pass over the points
(:func:`nav.slam.kernels._block_sums` reads each point's 2 x 2 cells in place): the same float32
sums, bit for bit, as scoring each child on its own (:func:`nav.slam.kernels.score_candidates`).

The beam was numpy's ``argpartition`` until stop 39, called from Python between the kernels: which
of several equal scores at the beam's edge it keeps, and in which order, is its algorithm's (and
numpy picks a SIMD one by CPU), so it could not move into a kernel. Keeping the earlier candidate
is a rule both sides follow. The Python between the levels was ~100 us of a ~520 us wide re-search
on the Intel relation pairs of ``navdeck bench peers``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nav.slam.kernels import _block_sums, block_scores

_NO_BOUNDS = np.zeros(0, dtype=np.float32)  # score_children: every parent's children


@njit(cache=True, nogil=True)
def keep_best(score: np.ndarray, beam: int) -> np.ndarray:
    """Indices of the ``beam`` highest ``score`` (all when there are no more), ties to the lower
    index, in ascending order: :func:`keep_best_reference`'s."""
    n = score.shape[0]
    if n <= beam:
        return np.arange(n)
    t = _kth_highest(score, beam)
    ties = beam
    for i in range(n):
        if score[i] > t:
            ties -= 1
    out = np.empty(beam, dtype=np.int64)
    m = 0
    for i in range(n):
        v = score[i]
        if v > t or (v == t and ties > 0):
            if v == t:
                ties -= 1
            out[m] = i
            m += 1
    return out


@njit(cache=True, nogil=True)
def _kth_highest(score: np.ndarray, k: int) -> np.float32:
    """The ``k``-th highest of ``score`` (counting equal values), 1 <= k <= its length: a min-heap
    of the ``k`` highest so far, one comparison per value once it is full (numba's ``np.partition``
    took ~10x as long on a top level's 4356 scores)."""
    heap = score[:k].copy()
    for i in range(k // 2 - 1, -1, -1):
        _sift_down(heap, i)
    for i in range(k, score.shape[0]):
        if score[i] > heap[0]:
            heap[0] = score[i]
            _sift_down(heap, 0)
    return heap[0]


@njit(cache=True, nogil=True, inline="always")
def _sift_down(heap: np.ndarray, i: int) -> None:
    """Restore the min-heap order below ``heap[i]``."""
    n = heap.shape[0]
    v = heap[i]
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and heap[c + 1] < heap[c]:
            c += 1
        if heap[c] >= v:
            break
        heap[i] = heap[c]
        i = c
    heap[i] = v


def keep_best_reference(score: np.ndarray, beam: int) -> np.ndarray:
    """numpy reference of :func:`keep_best` (a stable sort: equal scores keep their order)."""
    return np.sort(np.argsort(-score, kind="stable")[:beam])


@njit(cache=True, nogil=True)
def score_children(
    grid: np.ndarray,
    rows0: np.ndarray,
    cols0: np.ndarray,
    parents: np.ndarray,
    step: int,
    wc: int,
    bounds: np.ndarray = _NO_BOUNDS,
) -> tuple[np.ndarray, np.ndarray]:
    """The children ``(angle, by, bx)`` of ``parents`` one level down, ``(2 by + (0, 0, 1, 1), 2 bx +
    (0, 1, 0, 1))`` in that order (blocks of ``step`` cells on ``grid``, the pooled level they are
    scored on), those whose block meets the +-``wc`` cell window, and their float32 mean scores,
    bit for bit :func:`nav.slam.kernels.score_candidates`' (``rows0`` / ``cols0`` (A, N): the
    points' cells at each angle and zero offset). Reference: the numpy split and scores of
    ``matcher._correlative`` (``compiled=False``).

    With ``bounds`` (the parents' own scores, one level up: at least each child's) the children of
    a parent whose bound is below the best child scored so far are left out, the parent with the
    highest bound first: what is left holds every child scoring the best, in the same order, so the
    pick (:func:`best_candidate` without a runner-up) is the same (branch-and-bound's rule, on the
    beam's last level)."""
    n = rows0.shape[1]
    nf = np.float32(n)
    kids = np.empty((4 * parents.shape[0], 3), dtype=np.int64)
    scores = np.empty(4 * parents.shape[0], dtype=np.float32)
    in_place = np.zeros((1, 1, 1, 1), dtype=np.float32)  # read the grid itself, ``step`` apart
    part = np.empty((8, 2, 2), dtype=np.float32)
    part4 = np.empty(32, dtype=np.float32)
    sums = np.empty((2, 2), dtype=np.float32)
    r0s = np.empty(n, dtype=np.int64)
    c0s = np.empty(n, dtype=np.int64)
    prune = bounds.shape[0] > 0
    first = np.argmax(bounds) if prune else -1
    best = -np.inf
    first_sums = np.zeros((2, 2), dtype=np.float32)
    m = 0
    for t in range(parents.shape[0] + 1):
        k = first if t == 0 else t - 1  # the highest bound first (to set the best), then all in order
        if k < 0 or (prune and bounds[k] < best):
            continue
        a, by, bx = parents[k, 0], parents[k, 1], parents[k, 2]
        if t > 0 and k == first:  # scored first: its sums are kept
            sums[:] = first_sums
        else:
            dy, dx = 2 * by * step, 2 * bx * step
            if n <= 128:
                _children_sums(grid, rows0[a], cols0[a], dy, dx, step, part4, sums)
            else:
                for i in range(n):
                    r0s[i] = rows0[a, i] + dy
                    c0s[i] = cols0[a, i] + dx
                _block_sums(grid, in_place, step, r0s, c0s, 2, part, sums)
        for q in range(4):
            cy, cx = 2 * by + q // 2, 2 * bx + q % 2
            if _meets(cy * step, cx * step, step, wc):
                sc = sums[q // 2, q % 2] / nf
                best = max(best, sc)
                if t > 0:
                    kids[m, 0], kids[m, 1], kids[m, 2] = a, cy, cx
                    scores[m] = sc
                    m += 1
        if t == 0:
            first_sums[:] = sums
    return kids[:m], scores[:m]


@njit(cache=True, nogil=True, inline="always")
def _meets(lo_y: int, lo_x: int, step: int, wc: int) -> bool:
    """Whether the block of ``step`` cells from offset (lo_y, lo_x) meets the +-``wc`` window."""
    return lo_y + step - 1 >= -wc and lo_y <= wc and lo_x + step - 1 >= -wc and lo_x <= wc


@njit(cache=True, nogil=True, inline="always")
def _children_sums(
    grid: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    dy: int,
    dx: int,
    step: int,
    part: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`nav.slam.kernels._block_sums` of a 2 x 2 block of cells ``step`` apart at each
    point's cell moved by (``dy``, ``dx``), for <= 128 points (in place on the grid), written out:
    the four cells of a point go to its partial sums (``part``, 8 x 4) in four adds (the general
    loop over a block's rows and columns cost ~2x as much at this size). The same additions in the
    same order, so the same bits."""
    h, w = grid.shape
    n = rows.shape[0]
    n8 = n - n % 8 if n >= 8 else 0
    zero = np.float32(0.0)
    part[:] = zero
    for i in range(n8):
        r, c = rows[i] + dy, cols[i] + dx
        b = (i & 7) * 4
        if r >= 0 and c >= 0 and r + step < h and c + step < w:
            part[b] += grid[r, c]
            part[b + 1] += grid[r, c + step]
            part[b + 2] += grid[r + step, c]
            part[b + 3] += grid[r + step, c + step]
        else:
            for q in range(4):
                rr, cc = r + (q >> 1) * step, c + (q & 1) * step
                if 0 <= rr < h and 0 <= cc < w:
                    part[b + q] += grid[rr, cc]
    for q in range(4):
        if n8 > 0:
            res = ((part[q] + part[4 + q]) + (part[8 + q] + part[12 + q])) + (
                (part[16 + q] + part[20 + q]) + (part[24 + q] + part[28 + q])
            )
        else:
            res = zero
        for i in range(n8, n):
            rr, cc = rows[i] + dy + (q >> 1) * step, cols[i] + dx + (q & 1) * step
            if 0 <= rr < h and 0 <= cc < w:
                res += grid[rr, cc]
        out[q >> 1, q & 1] = res


@njit(cache=True, nogil=True)
def best_candidate(
    cand: np.ndarray, scores: np.ndarray, centre: int, separation: float, resolution: float
) -> tuple[int, int, int, float, float]:
    """The full-resolution candidate ``(angle, dy, dx)`` with the best score, ties to the one
    nearest the prior (``|dy| + |dx| + |a - centre|``), then to the first in ``cand`` (the numpy
    reference's ``lexsort``), its score, and the best score of the candidates more than
    ``separation`` m from it (0 when there is none)."""
    best = 0
    best_dist = abs(cand[0, 1]) + abs(cand[0, 2]) + abs(cand[0, 0] - centre)
    for k in range(1, cand.shape[0]):
        dist = abs(cand[k, 1]) + abs(cand[k, 2]) + abs(cand[k, 0] - centre)
        if scores[k] > scores[best] or (scores[k] == scores[best] and dist < best_dist):
            best, best_dist = k, dist
    by, bx = cand[best, 1], cand[best, 2]
    runner_up = np.float32(0.0)
    found = False
    for k in range(cand.shape[0]):
        if math.hypot(cand[k, 1] - by, cand[k, 2] - bx) * resolution > separation:
            if not found or scores[k] > runner_up:
                runner_up = scores[k]
            found = True
    return cand[best, 0], by, bx, float(scores[best]), float(runner_up)


@njit(cache=True, nogil=True)
def top_level_blocks(wc: int, top: int) -> tuple[int, int]:
    """The first block offset and the number of blocks a side of a +-``wc`` cell window's level
    ``top`` (blocks of ``2^top`` cells)."""
    s = 1 << top
    lo = -((wc + s - 1) // s)  # floor(-wc / s)
    return lo, wc // s - lo + 1


@njit(cache=True, nogil=True)
def top_candidates(angles: int, lo: int, nb: int) -> np.ndarray:
    """Every ``(angle index, by, bx)`` of a coarse-to-fine search's top level, blocks ``lo`` ..
    ``lo + nb - 1``, in :func:`nav.slam.kernels.block_scores`' order."""
    cand = np.empty((angles * nb * nb, 3), dtype=np.int64)
    m = 0
    for a in range(angles):
        for j in range(nb):
            for k in range(nb):
                cand[m, 0], cand[m, 1], cand[m, 2] = a, lo + j, lo + k
                m += 1
    return cand


@njit(cache=True, nogil=True)
def beam_search(
    levels: tuple | list,  # the pooled grids below the top: a tuple, or a numba typed List
    top_phase: np.ndarray,
    pad: int,
    rows0: np.ndarray,
    cols0: np.ndarray,
    top_rows: np.ndarray,
    top_cols: np.ndarray,
    wc: int,
    beam: int,
    centre: int,
    separation: float,
    resolution: float,
) -> tuple[int, int, int, float, float]:
    """The whole beam search of the +-``wc`` cell window: ``levels[l]`` is ``pooled[l]`` for the
    levels below the top (``levels[0]`` the field), ``top_phase`` the top level's
    :func:`nav.slam.kernels.phase_split`; ``rows0`` / ``cols0`` (A, N) the points' cells at each
    angle and zero offset, ``top_rows`` / ``top_cols`` those of the points the top level ranks its
    blocks by. Returns :func:`best_candidate` of the last level (``centre``: the prior's angle
    index)."""
    top = len(levels)
    s = 1 << top
    lo, nb = top_level_blocks(wc, top)
    score = block_scores(top_phase, top_rows, top_cols, lo, nb, s, pad).ravel()
    cand = top_candidates(top_rows.shape[0], lo, nb)
    for level in range(top - 1, -1, -1):
        keep = keep_best(score, beam)
        # the last level without a runner-up asks only for the best child, and the parents' scores
        # bound their children's when they summed the same points (not the top level's few)
        same_points = level + 1 < top or top_rows.shape[1] == rows0.shape[1]
        bounds = score[keep] if level == 0 and separation == math.inf and same_points else _NO_BOUNDS
        cand, score = score_children(levels[level], rows0, cols0, cand[keep], 1 << level, wc, bounds)
    return best_candidate(cand, score, centre, separation, resolution)
