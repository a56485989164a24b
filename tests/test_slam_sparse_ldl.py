"""The compiled sparse LDL^T against dense and SuperLU solves."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from nav.slam.pose_graph import _solve_spd
from nav.slam.sparse_ldl import FactorizationError, SymbolicLDL, block_ordering


def _spd_blocks(
    seed: int, blocks: int = 60, pairs: int = 150
) -> tuple[sp.csc_matrix, np.ndarray, np.ndarray]:
    """A random SPD matrix of 3 x 3 blocks coupled along random block pairs, and those pairs."""
    rng = np.random.default_rng(seed)
    bi = rng.integers(0, blocks, pairs)
    bj = rng.integers(0, blocks, pairs)
    keep = bi != bj
    bi, bj = bi[keep], bj[keep]
    a = np.zeros((3 * blocks, 3 * blocks))
    for i, j in zip(bi, bj, strict=True):
        m = rng.normal(size=(3, 3))
        a[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += m
        a[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] += m.T
    a += np.diag(np.abs(a).sum(axis=1) + 1.0)  # diagonally dominant: SPD
    h = sp.csc_matrix(a)
    h.sort_indices()
    return h, bi, bj


def test_ldl_solves_like_dense_and_superlu() -> None:
    for seed in range(4):
        h, bi, bj = _spd_blocks(seed)
        b = np.random.default_rng(seed).normal(size=h.shape[0])
        sym = SymbolicLDL(h, block_ordering(bi, bj, h.shape[0] // 3, 3))
        x = sym.solve(h, b)
        np.testing.assert_allclose(x, np.linalg.solve(h.toarray(), b), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(x, _solve_spd(h, b), rtol=1e-9, atol=1e-12)
        # the same pattern, new values: the symbolic analysis is reused
        h2 = h.copy()
        h2.data = h2.data * (1.0 + 0.1 * np.random.default_rng(seed + 10).random(h2.nnz))
        h2 = ((h2 + h2.T) / 2).tocsc()
        h2.sort_indices()
        assert sym.matches(h2)
        np.testing.assert_allclose(sym.solve(h2, b), np.linalg.solve(h2.toarray(), b), rtol=1e-9, atol=1e-12)


def test_block_ordering_keeps_each_block_together() -> None:
    h, bi, bj = _spd_blocks(0)
    perm = block_ordering(bi, bj, h.shape[0] // 3, 3)
    assert sorted(perm.tolist()) == list(range(h.shape[0]))
    assert np.all(perm.reshape(-1, 3) == perm.reshape(-1, 3)[:, :1] + np.arange(3))


def test_singular_matrix_is_an_error() -> None:
    a = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]])  # rank 2
    h = sp.csc_matrix(a)
    with pytest.raises(FactorizationError):
        SymbolicLDL(h, np.arange(3)).solve(h, np.ones(3))
