"""Branch-and-bound correlative search (Hess et al. 2016, sec. V.C; Cartographer's
FastCorrelativeScanMatcher2D), compiled.

The window's candidates ``(angle, dy, dx)`` form, at each angle, a quadtree over the offsets: a node
at depth ``l`` is a block of ``2^l x 2^l`` offsets, and its score on ``pooled[l]`` (each cell the
max of the field over the ``2^l`` block starting there) is at least the score of every offset in the
block. The scores are float32 sums in numpy's order (:func:`nav.slam.kernels.pairwise_sum32`), and
float32 rounding is monotone, so that holds bit for bit. The search scores every top-level block,
visits them best first, descends depth first into the best child first, and drops every node whose
bound is below the best full-resolution score found so far. It returns exactly what scoring every
candidate at full resolution returns (the exhaustive search: same score, same tie-break towards the
prior, then the first in ``(angle, dy, dx)`` order), whatever the number of levels; the levels only
change how much is pruned. The numpy reference is the exhaustive search of
``matcher.correlative_search_reference``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from nav.slam.beam_search import top_level_blocks
from nav.slam.kernels import _before, _block_sums, block_scores, phase_split


@njit(cache=True, nogil=True)
def branch_and_bound_search(
    pooled: tuple,
    rows0: np.ndarray,
    cols0: np.ndarray,
    wc: int,
    incumbent: np.ndarray,
    incumbent_score: float,
) -> tuple[int, int, int, float]:
    """The best ``(angle index, dy, dx)`` (cells) of points ``rows0`` / ``cols0`` (A, N: their
    cells at each angle and zero offset, :func:`nav.slam.kernels.rotated_cells`) over the offsets
    ``[-wc, wc]^2``, and its score; ``pooled`` is ``(field, pooled[1], ..., pooled[top])``, all of
    the field's shape. Ties go to the candidate nearest the prior (``|dy| + |dx| + |a - centre|``),
    then to the first in (a, dy, dx) order, as the exhaustive search's.

    ``incumbent`` (a, dy, dx), when not empty, is a candidate of the window already scored
    (``incumbent_score``, bit for bit what this search scores it: a smaller window's search on the
    same angle lattice and points): the search starts from it as its best, so only nodes that can
    beat it are visited; the result is the same."""
    na, n = rows0.shape
    top = len(pooled) - 1
    s = 1 << top
    lo, nb = top_level_blocks(wc, top)
    top_scores = block_scores(phase_split(pooled[top], s, nb), rows0, cols0, lo, nb, s, nb).ravel()
    order = np.argsort(-top_scores, kind="mergesort")
    centre = (na - 1) // 2
    nf = np.float32(n)
    part = np.empty((8, 2, 2), dtype=np.float32)
    sums = np.empty((2, 2), dtype=np.float32)
    # one pass over the points scores a node's 4 children (cells ``step`` apart on the pooled grid
    # below, read in place: a single-phase placeholder tells _block_sums so)
    in_place = np.zeros((1, 1, 1, 1), dtype=np.float32)
    # depth-first stack: (level, angle, by, bx) and the node's bound; at most 4 nodes a level
    cap = 4 * top + 1
    st_l = np.empty(cap, dtype=np.int64)
    st_a = np.empty(cap, dtype=np.int64)
    st_y = np.empty(cap, dtype=np.int64)
    st_x = np.empty(cap, dtype=np.int64)
    st_s = np.empty(cap, dtype=np.float32)
    kid_y = np.empty(4, dtype=np.int64)
    kid_x = np.empty(4, dtype=np.int64)
    kid_s = np.empty(4, dtype=np.float32)
    best = np.float32(-1.0)
    best_dist = 0
    ba, bdy, bdx = na, 0, 0
    if incumbent.shape[0] == 3:
        best = np.float32(incumbent_score)
        ba, bdy, bdx = incumbent[0], incumbent[1], incumbent[2]
        best_dist = abs(bdy) + abs(bdx) + abs(ba - centre)
    for t in order:
        if top_scores[t] < best:
            break  # sorted: no later block can reach the best
        a = t // (nb * nb)
        st_l[0], st_a[0] = top, a
        st_y[0], st_x[0] = lo + (t // nb) % nb, lo + t % nb
        st_s[0] = top_scores[t]
        sp = 1
        while sp > 0:
            sp -= 1
            lvl, a, by, bx, sc = st_l[sp], st_a[sp], st_y[sp], st_x[sp], st_s[sp]
            if sc < best:
                continue  # the bound fell below a best found meanwhile
            if lvl == 0:
                dist = abs(by) + abs(bx) + abs(a - centre)
                if sc > best or dist < best_dist or (dist == best_dist and _before(a, by, bx, ba, bdy, bdx)):
                    best, best_dist, ba, bdy, bdx = sc, dist, a, by, bx
                continue
            step = 1 << (lvl - 1)
            _block_sums(
                pooled[lvl - 1],
                in_place,
                step,
                rows0[a] + 2 * by * step,
                cols0[a] + 2 * bx * step,
                2,
                part,
                sums,
            )
            m = 0
            for q in range(4):
                cy = 2 * by + q // 2
                cx = 2 * bx + q % 2
                y0, x0 = cy * step, cx * step
                if y0 + step - 1 < -wc or y0 > wc or x0 + step - 1 < -wc or x0 > wc:
                    continue  # the child's block misses the window
                ks = sums[q // 2, q % 2] / nf
                if ks < best:
                    continue
                j = m  # insertion sort, ascending: the best child is pushed last, popped first
                while j > 0 and kid_s[j - 1] > ks:
                    kid_s[j], kid_y[j], kid_x[j] = kid_s[j - 1], kid_y[j - 1], kid_x[j - 1]
                    j -= 1
                kid_s[j], kid_y[j], kid_x[j] = ks, cy, cx
                m += 1
            for j in range(m):
                st_l[sp], st_a[sp], st_y[sp], st_x[sp], st_s[sp] = lvl - 1, a, kid_y[j], kid_x[j], kid_s[j]
                sp += 1
    return ba, bdy, bdx, float(best)
