"""Sparse 2D pose-graph optimization (Gauss-Newton / Levenberg-Marquardt with a robust kernel).

Nodes are SE(2) poses ``x_i = (x, y, theta)``; an edge ``(i, j, z, Omega)`` says "``x_j`` seen from
``x_i`` is ``z``" with information matrix ``Omega`` (Lu & Milios 1997; Grisetti et al. 2010,
"A tutorial on graph-based SLAM"). The error is

    e_ij = [ R_i^T (t_j - t_i) - z_t ;  wrap(theta_j - theta_i - z_theta) ]

and the normal equations ``(J^T W J + lambda D) dx = -J^T W e`` are assembled block by block
from vectorized per-edge Jacobian blocks (no per-edge Python loop) into a sparsity pattern built
once per optimization (:class:`_HessianPattern`; the ``J^T J`` product of
:func:`normal_equations_reference` is the reference) and solved by a compiled sparse LDL^T whose
ordering and symbolic analysis are also done once per optimization
(:class:`nav.slam.sparse_ldl.SymbolicLDL`; SuperLU, :func:`_solve_spd`, is the reference and
``solver="superlu"``). Edges flagged ``robust`` get a robust kernel via iteratively re-weighted
least squares, so a false loop closure cannot pull the whole graph: Huber (Cartographer's) or
Dynamic Covariance Scaling (Agarwal et al. 2013, "Robust map optimization using dynamic covariance
scaling"), whose weight falls towards zero as the error grows, so a closure that fights the rest of
the graph is in effect switched off instead of pulling with a constant force.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from nav.slam.kernels import accumulate_normal_equations
from nav.slam.sparse_ldl import FactorizationError, SymbolicLDL, block_ordering
from nav.types import wrap_angle

_ANCHOR = 1e6
"""Weight of the prior that holds the fixed node in place (its square on H's diagonal)."""


class PoseGraphError(RuntimeError):
    """The optimization failed (singular system or non-finite values)."""


@dataclass(frozen=True)
class PoseGraphOptions:
    """Options of :func:`optimize_pose_graph`."""

    max_iterations: int = 20
    """Gauss-Newton iterations at most."""
    kernel: Literal["huber", "dcs"] = "huber"
    """Robust kernel of robust edges: ``huber`` (linear beyond ``huber_delta``: a wrong edge keeps
    pulling with a bounded force) or ``dcs`` (Dynamic Covariance Scaling: its information is
    scaled by ``s^2``, ``s = min(1, 2 Phi / (Phi + chi2))``, so it fades out)."""
    huber_delta: float = 1.0
    """Huber kernel threshold on the Mahalanobis error sqrt(e^T Omega e) of robust edges."""
    dcs_phi: float = 1.0
    """DCS's ``Phi``: the squared Mahalanobis error (chi2) up to which an edge keeps its full weight."""
    tolerance: float = 1e-6
    """Stop when the largest update component is below this."""
    relative_tolerance: float = 1e-4
    """Stop when the robust cost decreased by less than this fraction in one iteration."""
    damping: float = 1e-6
    """Levenberg-Marquardt damping added to the diagonal (relative)."""
    solver: Literal["ldl", "superlu"] = "ldl"
    """Linear solver of the normal equations: ``ldl`` (compiled LDL^T, ordering and symbolic
    analysis once per optimization: about 5x faster per iteration on MIT Killian's graphs) or
    ``superlu`` (SciPy's SuperLU at every iteration, the reference)."""


@dataclass
class EdgeSet:
    """Edges as arrays: ``i, j`` (E,), ``z`` (E, 3), ``sqrt_info`` (E, 3) diagonal sqrt of Omega,
    ``robust`` (E,) bool."""

    i: np.ndarray
    j: np.ndarray
    z: np.ndarray
    sqrt_info: np.ndarray
    robust: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])


def edge_errors(poses: np.ndarray, edges: EdgeSet) -> np.ndarray:
    """(E, 3) errors ``e_ij`` (unweighted)."""
    pi, pj = poses[edges.i], poses[edges.j]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    return np.column_stack(
        (
            c * dx + s * dy - edges.z[:, 0],
            -s * dx + c * dy - edges.z[:, 1],
            wrap_angle(pj[:, 2] - pi[:, 2] - edges.z[:, 2]),
        )
    )


def _jacobian_blocks(poses: np.ndarray, edges: EdgeSet, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per edge the weighted ``d e / d x_i`` and ``d e / d x_j`` (E, 3, 3), rows scaled by
    ``sqrt_info * w``."""
    e = len(edges)
    pi, pj = poses[edges.i], poses[edges.j]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    zero, one = np.zeros(e), np.ones(e)
    # d e / d x_i (3x3) and d e / d x_j (3x3), each row-major per edge
    ji = np.stack(
        (
            np.stack((-c, -s, -s * dx + c * dy), 1),
            np.stack((s, -c, -c * dx - s * dy), 1),
            np.stack((zero, zero, -one), 1),
        ),
        1,
    )
    jj = np.stack((np.stack((c, s, zero), 1), np.stack((-s, c, zero), 1), np.stack((zero, zero, one), 1)), 1)
    scale = (edges.sqrt_info * w[:, None])[:, :, None]
    return ji * scale, jj * scale


def _jacobian(poses: np.ndarray, edges: EdgeSet, w: np.ndarray, n: int) -> sp.csr_matrix:
    """Weighted sparse Jacobian (3E, 3n)."""
    e = len(edges)
    ji, jj = _jacobian_blocks(poses, edges, w)
    rows = (3 * np.arange(e))[:, None, None] + np.arange(3)[None, :, None]
    rows = np.broadcast_to(rows, (e, 3, 3))
    ci = (3 * edges.i)[:, None, None] + np.arange(3)[None, None, :]
    cj = (3 * edges.j)[:, None, None] + np.arange(3)[None, None, :]
    data = np.concatenate((ji.ravel(), jj.ravel()))
    r = np.concatenate((rows.ravel(), rows.ravel()))
    cc = np.concatenate((np.broadcast_to(ci, (e, 3, 3)).ravel(), np.broadcast_to(cj, (e, 3, 3)).ravel()))
    return sp.csr_matrix((data, (r, cc)), shape=(3 * e, 3 * n))


def _damped(h: sp.csc_matrix, damping: float) -> sp.csc_matrix:
    """``h`` with ``damping * (diag + 1)`` added to its diagonal."""
    return (h + sp.diags(damping * (h.diagonal() + 1.0))).tocsc()


def normal_equations_reference(
    poses: np.ndarray, edges: EdgeSet, w: np.ndarray, n: int, fixed: int, damping: float
) -> tuple[sp.csc_matrix, np.ndarray]:
    """Damped ``H = J^T J`` and ``g = -J^T r`` from the sparse Jacobian (the fixed node's prior as
    three more rows): what :class:`_HessianPattern` assembles block by block."""
    anchor = sp.csr_matrix((np.full(3, _ANCHOR), (np.arange(3), 3 * fixed + np.arange(3))), shape=(3, 3 * n))
    j = sp.vstack((_jacobian(poses, edges, w, n), anchor)).tocsr()
    r = np.concatenate(((edge_errors(poses, edges) * edges.sqrt_info * w[:, None]).ravel(), np.zeros(3)))
    return _damped((j.T @ j).tocsc(), damping), -(j.T @ r)


class _HessianPattern:
    """The sparsity pattern of H for one edge set (3 x 3 blocks: each pose's diagonal block and
    one block each way per connected pair), built once per optimization; :meth:`assemble` then
    adds every edge's blocks in place (:func:`nav.slam.kernels.accumulate_normal_equations`; no
    sparse product, no re-sorting)."""

    def __init__(self, edges: EdgeSet, n: int, fixed: int) -> None:
        self.n, self.fixed = n, fixed
        i, j = edges.i.astype(np.int64), edges.j.astype(np.int64)
        diag = np.arange(n, dtype=np.int64)
        # blocks (row pose, column pose): per edge ii, ij, ji, jj; then every diagonal block
        br = np.concatenate((i, i, j, j, diag))
        bc = np.concatenate((i, j, i, j, diag))
        keys, self._slot = np.unique(bc * n + br, return_inverse=True)  # column-major order
        ucol, urow = keys // n, keys % n
        count = np.bincount(ucol, minlength=n)  # blocks per block column
        first = np.concatenate(([0], np.cumsum(count)[:-1]))
        rank = np.arange(len(keys)) - first[ucol]  # block's position in its block column
        # CSC: column 3c + b holds 3 entries per block of block column c, in block-row order
        col_nnz = np.repeat(3 * count, 3)
        self.indptr = np.concatenate(([0], np.cumsum(col_nnz))).astype(np.int32)
        a = np.arange(3)
        # entry (a, b) of unique block u sits at indptr[3 col + b] + 3 rank + a
        column = self.indptr[3 * ucol[:, None, None] + a[None, None, :]]
        self._pos = column + 3 * rank[:, None, None] + a[None, :, None]
        self.indices = np.empty(int(self.indptr[-1]), np.int32)
        self.indices[self._pos] = np.broadcast_to(3 * urow[:, None, None] + a[None, :, None], self._pos.shape)
        self._diag = self._pos[np.flatnonzero(ucol == urow)][:, a, a].ravel()  # (3n,) in variable order
        e = len(i)
        # per edge, where its ii, ij, ji, jj blocks' entries go in the data array
        self._edge_pos = np.ascontiguousarray(
            self._pos.reshape(-1, 9)[self._slot[: 4 * e]].reshape(4, e, 9).transpose(1, 0, 2)
        )
        self._i, self._j = i, j
        self._symbolic: SymbolicLDL | None = None

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        size = 3 * self.n
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(size, size))

    def assemble(
        self, poses: np.ndarray, edges: EdgeSet, w: np.ndarray, damping: float, err: np.ndarray | None = None
    ) -> tuple[sp.csc_matrix, np.ndarray]:
        """Damped ``H`` and ``g = -J^T r`` at ``poses`` with robust weights ``w`` (``err``: the
        poses' :func:`edge_errors`, when already computed)."""
        scale = np.ascontiguousarray(edges.sqrt_info * w[:, None])
        r = (edge_errors(poses, edges) if err is None else err) * scale
        data = np.zeros(len(self.indices))
        g = np.zeros(3 * self.n)
        accumulate_normal_equations(poses, self._i, self._j, scale, r, self._edge_pos, data, g)
        anchor = self._diag[3 * self.fixed : 3 * self.fixed + 3]
        data[anchor] += _ANCHOR * _ANCHOR
        data[self._diag] += damping * (data[self._diag] + 1.0)
        return self.matrix(data), g

    def solve(self, h: sp.csc_matrix, g: np.ndarray) -> np.ndarray:
        """``h^-1 g`` by the compiled LDL^T, ordered and analysed on the first call."""
        if self._symbolic is None:
            perm = block_ordering(self._i, self._j, self.n, 3)
            self._symbolic = SymbolicLDL(h, perm)
        try:
            return self._symbolic.solve(h, g)
        except FactorizationError as exc:
            raise PoseGraphError(f"pose graph normal equations are singular ({exc})") from exc


def _solve_spd(h: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """Solve the (symmetric positive definite) normal equations. SuperLU in symmetric mode with a
    minimum-degree ordering of H and no pivoting is in effect a sparse LDL^T: on Intel's graph
    (5330 poses, 2309 loop edges) 0.08 s against 1.2 s for ``spsolve``'s default column ordering,
    which ignores the symmetry and fills in 8x more."""
    try:
        lu = splu(h, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError as exc:  # exactly singular
        raise PoseGraphError(f"pose graph normal equations are singular ({exc})") from exc
    return lu.solve(b)


def _cost(m: np.ndarray, robust: np.ndarray, options: PoseGraphOptions) -> np.ndarray:
    """Per-edge cost of Mahalanobis errors ``m``, watched for convergence."""
    if options.kernel == "dcs":
        phi, chi2 = options.dcs_phi, m * m
        # the M-estimator whose IRLS weight is DCS's s^2: Phi (3 chi2 - Phi) / (Phi + chi2) beyond Phi
        return np.where(robust & (chi2 > phi), phi * (3 * chi2 - phi) / (phi + chi2), chi2)
    d = options.huber_delta
    # (Huber on every edge: the stopping rule the Freiburg figures were measured with)
    return np.where(m > d, 2 * d * m - d * d, m * m)


def _robust_weight(m: np.ndarray, options: PoseGraphOptions) -> np.ndarray:
    """IRLS factor on ``sqrt(Omega)`` (the information is scaled by its square)."""
    if options.kernel == "dcs":
        return np.minimum(1.0, 2 * options.dcs_phi / (options.dcs_phi + m * m))
    d = options.huber_delta
    return np.where(m > d, np.sqrt(d / np.maximum(m, 1e-12)), 1.0)


def optimize_pose_graph(
    poses: np.ndarray,
    edges: EdgeSet,
    fixed: int = 0,
    options: PoseGraphOptions = PoseGraphOptions(),
) -> tuple[np.ndarray, np.ndarray]:
    """Optimize (n, 3) ``poses`` with node ``fixed`` held in place.

    Returns the optimized poses and the final per-edge robust weights (1 = fully trusted).
    """
    x = np.array(poses, dtype=float)
    n = x.shape[0]
    w = np.ones(len(edges))
    if len(edges) == 0 or n < 2:
        return x, w
    pattern = _HessianPattern(edges, n, fixed) if options.solver == "ldl" else None
    prev_cost = np.inf
    for _ in range(options.max_iterations):
        err = edge_errors(x, edges)
        m = np.sqrt(np.sum((err * edges.sqrt_info) ** 2, axis=1))
        cost = float(np.sum(_cost(m, edges.robust, options)))
        if prev_cost - cost < options.relative_tolerance * prev_cost:
            break
        prev_cost = cost
        w = np.where(edges.robust, _robust_weight(m, options), 1.0)
        if pattern is not None:
            h, g = pattern.assemble(x, edges, w, options.damping, err)
            dx = pattern.solve(h, g)
        else:
            h, g = normal_equations_reference(x, edges, w, n, fixed, options.damping)
            dx = _solve_spd(h, g)
        if not np.all(np.isfinite(dx)):
            raise PoseGraphError("pose graph normal equations are singular")
        x += dx.reshape(n, 3)
        x[:, 2] = wrap_angle(x[:, 2])
        if np.abs(dx).max() < options.tolerance:
            break
    return x, w
