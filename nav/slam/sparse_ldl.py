"""Sparse LDL^T of the pose graph's normal equations, compiled (numba), with the symbolic work done
once per optimization.

The pose graph's Hessian keeps one sparsity pattern through all Gauss-Newton iterations of an
optimization (only its values change), yet SuperLU (:func:`nav.slam.pose_graph._solve_spd`, kept as
the reference) re-orders and re-analyses it at every iteration and computes both L and U. Here the
fill-reducing ordering is a minimum-degree ordering of the *pose* graph (one vertex per pose, 3x
smaller than H; SuperLU's ``MMD_AT_PLUS_A`` on it) expanded to each pose's three variables, the
elimination tree and column counts are computed once per pattern, and each iteration runs only the
numeric factorization: the up-looking LDL^T of QDLDL (Stellato et al., OSQP's solver; Davis,
"Direct Methods for Sparse Linear Systems", ch. 4), no pivoting, which the symmetric positive
definite (damped) H does not need.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.linalg import splu


class FactorizationError(RuntimeError):
    """A zero pivot: the matrix is singular (or not positive definite)."""


@njit(cache=True, nogil=True)
def elimination_tree(n: int, ap: np.ndarray, ai: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Elimination tree (parent per column, -1 at roots) and the number of entries of each column
    of L below the diagonal, from the upper triangle (CSC, rows <= column) of a symmetric matrix."""
    work = np.full(n, -1, np.int64)
    parent = np.full(n, -1, np.int64)
    lnz = np.zeros(n, np.int64)
    for j in range(n):
        work[j] = j
        for p in range(ap[j], ap[j + 1]):
            i = ai[p]
            while work[i] != j:
                if parent[i] == -1:
                    parent[i] = j
                lnz[i] += 1
                work[i] = j
                i = parent[i]
    return parent, lnz


@njit(cache=True, nogil=True)
def ldl_numeric(
    n: int,
    ap: np.ndarray,
    ai: np.ndarray,
    ax: np.ndarray,
    parent: np.ndarray,
    lp: np.ndarray,
    li: np.ndarray,
    lx: np.ndarray,
    d: np.ndarray,
) -> bool:
    """Up-looking LDL^T of the upper triangle ``(ap, ai, ax)``: fills unit-lower L's strict lower
    part (CSC ``lp, li, lx``, preallocated from :func:`elimination_tree`'s counts) and the diagonal
    ``d``. False on a zero pivot."""
    y = np.zeros(n)
    mark = np.zeros(n, np.bool_)
    stack = np.empty(n, np.int64)
    pattern = np.empty(n, np.int64)
    nxt = lp[:-1].copy()
    for k in range(n):
        d[k] = 0.0
        top = 0
        for p in range(ap[k], ap[k + 1]):
            i = ai[p]
            if i == k:
                d[k] = ax[p]
                continue
            y[i] = ax[p]
            if mark[i]:
                continue
            # the path from i up the elimination tree to the first marked node is row k's pattern
            depth = 0
            while i != -1 and i < k and not mark[i]:
                mark[i] = True
                stack[depth] = i
                depth += 1
                i = parent[i]
            while depth > 0:
                depth -= 1
                pattern[top] = stack[depth]
                top += 1
        for t in range(top - 1, -1, -1):
            c = pattern[t]
            yc = y[c]
            for q in range(lp[c], nxt[c]):
                y[li[q]] -= lx[q] * yc
            lkc = yc / d[c]
            li[nxt[c]] = k
            lx[nxt[c]] = lkc
            nxt[c] += 1
            d[k] -= yc * lkc
            y[c] = 0.0
            mark[c] = False
        if d[k] == 0.0 or not np.isfinite(d[k]):
            return False
    return True


@njit(cache=True, nogil=True)
def ldl_solve(lp: np.ndarray, li: np.ndarray, lx: np.ndarray, d: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with L D L^T x = b."""
    n = d.shape[0]
    x = b.copy()
    for j in range(n):
        for q in range(lp[j], lp[j + 1]):
            x[li[q]] -= lx[q] * x[j]
    for j in range(n):
        x[j] /= d[j]
    for j in range(n - 1, -1, -1):
        for q in range(lp[j], lp[j + 1]):
            x[j] -= lx[q] * x[li[q]]
    return x


def block_ordering(rows: np.ndarray, cols: np.ndarray, blocks: int, size: int) -> np.ndarray:
    """Fill-reducing permutation of a matrix of ``blocks`` x ``blocks`` dense ``size`` x ``size``
    blocks whose off-diagonal blocks sit at (``rows``, ``cols``): SuperLU's minimum-degree ordering
    of the block graph (a diagonally dominant matrix of that pattern), each block's variables kept
    together and in order."""
    ones = np.ones(len(rows))
    adj = sp.coo_matrix((ones, (rows, cols)), shape=(blocks, blocks))
    adj = (adj + adj.T).tocsr()
    degree = np.asarray(abs(adj).sum(axis=1)).ravel()
    g = (sp.diags(degree + 1.0) - adj).tocsc()
    order = splu(g, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).perm_c
    # perm_c[k] is the position of block k; the elimination order is its inverse
    perm = np.argsort(order)
    return (size * perm[:, None] + np.arange(size)[None, :]).ravel()


class SymbolicLDL:
    """The ordering and symbolic analysis of one sparsity pattern, for repeated numeric LDL^T.

    ``pattern``: a symmetric CSC matrix whose structure (full, both triangles, diagonal present)
    is the one every later matrix has; ``perm``: the elimination order of its variables."""

    def __init__(self, pattern: sp.csc_matrix, perm: np.ndarray) -> None:
        n = pattern.shape[0]
        self.n = n
        self.perm = np.asarray(perm, dtype=np.int64)
        # where each entry of the permuted upper triangle comes from in the original's data array
        probe = sp.csc_matrix(
            (np.arange(1, pattern.nnz + 1, dtype=np.float64), pattern.indices, pattern.indptr), shape=(n, n)
        )
        upper = sp.triu(probe[self.perm][:, self.perm], format="csc")
        upper.sort_indices()
        self._ap = upper.indptr.astype(np.int64)
        self._ai = upper.indices.astype(np.int64)
        self._source = upper.data.astype(np.int64) - 1
        self._structure = (pattern.indptr.copy(), pattern.indices.copy())
        parent, lnz = elimination_tree(n, self._ap, self._ai)
        self._parent = parent
        self._lp = np.concatenate(([0], np.cumsum(lnz))).astype(np.int64)

    def matches(self, h: sp.csc_matrix) -> bool:
        """Whether ``h`` has the analysed structure."""
        indptr, indices = self._structure
        return np.array_equal(h.indptr, indptr) and np.array_equal(h.indices, indices)

    def solve(self, h: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
        """Factorize ``h`` (the analysed structure) and solve ``h x = b``."""
        nnz = int(self._lp[-1])
        li = np.empty(nnz, np.int64)
        lx = np.empty(nnz)
        d = np.empty(self.n)
        ax = np.ascontiguousarray(h.data[self._source], dtype=np.float64)
        if not ldl_numeric(self.n, self._ap, self._ai, ax, self._parent, self._lp, li, lx, d):
            raise FactorizationError("zero pivot in the LDL^T factorization (singular matrix)")
        xp = ldl_solve(self._lp, li, lx, d, np.ascontiguousarray(b[self.perm], dtype=np.float64))
        x = np.empty_like(xp)
        x[self.perm] = xp
        return x
