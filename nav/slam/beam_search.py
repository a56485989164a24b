"""The coarse-to-fine beam search's levels below the top, compiled (the wide re-search, loop
closure and the global search: :func:`nav.slam.matcher.correlative_search` with ``levels > 0``).

A level keeps its ``beam`` best candidates (numpy's ``argpartition``, called between these kernels
so the kept candidates and their order are what the numpy reference keeps, ties included), splits
each into its 4 children and scores them; the last level picks the best. Scoring a parent's 4
children is one pass over the points (:func:`nav.slam.kernels._block_sums` reads each point's 2 x 2
cells in place): the same float32 sums, bit for bit, as scoring each child on its own
(:func:`nav.slam.kernels.score_candidates`), without gathering each child's values first. On the
7 Intel relation pairs of ``navdeck bench peers`` that fall back to the wide re-search, a whole
match took ~0.88 of its time with these levels and their split, scores and pick in numpy (same
poses, same-process A/B).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nav.slam.kernels import _block_sums


@njit(cache=True, nogil=True)
def score_children(
    grid: np.ndarray, rows0: np.ndarray, cols0: np.ndarray, parents: np.ndarray, step: int, wc: int
) -> tuple[np.ndarray, np.ndarray]:
    """The children ``(angle, by, bx)`` of ``parents`` one level down, ``(2 by + (0, 0, 1, 1), 2 bx +
    (0, 1, 0, 1))`` in that order (blocks of ``step`` cells on ``grid``, the pooled level they are
    scored on), those whose block meets the +-``wc`` cell window, and their float32 mean scores,
    bit for bit :func:`nav.slam.kernels.score_candidates`' (``rows0`` / ``cols0`` (A, N): the
    points' cells at each angle and zero offset). Reference: the numpy split and scores of
    ``matcher._correlative`` (``compiled=False``)."""
    n = rows0.shape[1]
    nf = np.float32(n)
    kids = np.empty((4 * parents.shape[0], 3), dtype=np.int64)
    scores = np.empty(4 * parents.shape[0], dtype=np.float32)
    in_place = np.zeros((1, 1, 1, 1), dtype=np.float32)  # read the grid itself, ``step`` apart
    part = np.empty((8, 2, 2), dtype=np.float32)
    sums = np.empty((2, 2), dtype=np.float32)
    r0s = np.empty(n, dtype=np.int64)
    c0s = np.empty(n, dtype=np.int64)
    m = 0
    for k in range(parents.shape[0]):
        a, by, bx = parents[k, 0], parents[k, 1], parents[k, 2]
        dy, dx = 2 * by * step, 2 * bx * step
        for i in range(n):
            r0s[i] = rows0[a, i] + dy
            c0s[i] = cols0[a, i] + dx
        _block_sums(grid, in_place, step, r0s, c0s, 2, part, sums)
        for q in range(4):
            cy, cx = 2 * by + q // 2, 2 * bx + q % 2
            lo_y, lo_x = cy * step, cx * step
            if lo_y + step - 1 >= -wc and lo_y <= wc and lo_x + step - 1 >= -wc and lo_x <= wc:
                kids[m, 0], kids[m, 1], kids[m, 2] = a, cy, cx
                scores[m] = sums[q // 2, q % 2] / nf
                m += 1
    return kids[:m], scores[:m]


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
