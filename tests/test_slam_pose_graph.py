"""Sparse pose-graph optimization: consistent graphs, loop corrections and false-closure robustness."""

from __future__ import annotations

import numpy as np

from nav.slam.pose_graph import (
    EdgeSet,
    PoseGraphOptions,
    _HessianPattern,
    edge_errors,
    normal_equations_reference,
    optimize_pose_graph,
)


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack(
        (c * dx + s * dy, -s * dx + c * dy, (b[:, 2] - a[:, 2] + np.pi) % (2 * np.pi) - np.pi)
    )


def _circle(n: int = 200) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    th = (t + np.pi / 2 + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack((5 * np.cos(t), 5 * np.sin(t), th))


def _chain(x0: np.ndarray, z: np.ndarray) -> np.ndarray:
    x = [x0]
    for d in z:
        p = x[-1]
        c, s = np.cos(p[2]), np.sin(p[2])
        x.append(np.array([p[0] + c * d[0] - s * d[1], p[1] + s * d[0] + c * d[1], p[2] + d[2]]))
    return np.array(x)


def _edges(i: np.ndarray, j: np.ndarray, z: np.ndarray, robust: bool) -> EdgeSet:
    return EdgeSet(i, j, z, np.tile([50.0, 50.0, 100.0], (len(i), 1)), np.full(len(i), robust))


def test_loop_closure_removes_drift() -> None:
    truth = _circle()
    n = len(truth)
    i = np.arange(n - 1)
    z = _rel(truth[i], truth[i + 1])
    z_drift = z + np.array([0.0, 0.0, 0.004])  # heading bias: the chain does not close
    init = _chain(truth[0], z_drift)
    loop_i, loop_j = np.array([0, 10, 20]), np.array([n - 1, n - 1, n - 1])
    edges = EdgeSet(
        np.concatenate((i, loop_i)),
        np.concatenate((i + 1, loop_j)),
        np.vstack((z_drift, _rel(truth[loop_i], truth[loop_j]))),
        np.tile([50.0, 50.0, 100.0], (n - 1 + 3, 1)),
        np.concatenate((np.zeros(n - 1, bool), np.ones(3, bool))),
    )
    x, w = optimize_pose_graph(init, edges)
    before = np.hypot(*(init[:, :2] - truth[:, :2]).T).max()
    after = np.hypot(*(x[:, :2] - truth[:, :2]).T).max()
    assert before > 1.0
    assert after < 0.2 * before
    assert np.allclose(x[0], truth[0])  # node 0 is the fixed gauge
    assert np.all(w > 0)


def test_consistent_graph_is_a_fixed_point() -> None:
    truth = _circle(50)
    i = np.arange(49)
    edges = _edges(i, i + 1, _rel(truth[i], truth[i + 1]), robust=False)
    x, _ = optimize_pose_graph(truth, edges)
    assert np.abs(x - truth).max() < 1e-9
    assert np.abs(edge_errors(x, edges)).max() < 1e-9


def test_huber_kernel_limits_a_false_closure() -> None:
    truth = _circle(100)
    i = np.arange(99)
    z = _rel(truth[i], truth[i + 1])
    good_i, good_j = np.array([0, 5]), np.array([99, 99])
    bad = np.array([[3.0, -2.0, 1.0]])  # a wildly wrong closure between nodes 30 and 70
    edges_i = np.concatenate((i, good_i, [30]))
    edges_j = np.concatenate((i + 1, good_j, [70]))
    zz = np.vstack((z, _rel(truth[good_i], truth[good_j]), bad))
    info = np.tile([50.0, 50.0, 100.0], (len(edges_i), 1))
    robust = np.concatenate((np.zeros(99, bool), np.ones(3, bool)))
    x_rob, w = optimize_pose_graph(truth, EdgeSet(edges_i, edges_j, zz, info, robust))
    x_l2, _ = optimize_pose_graph(truth, EdgeSet(edges_i, edges_j, zz, info, np.zeros_like(robust)))
    err_rob = np.hypot(*(x_rob[:, :2] - truth[:, :2]).T).max()
    err_l2 = np.hypot(*(x_l2[:, :2] - truth[:, :2]).T).max()
    assert err_rob < 0.5 * err_l2
    assert w[-1] < 0.2  # the false closure is strongly down-weighted


def test_dcs_kernel_switches_a_false_closure_off() -> None:
    """Huber keeps pulling a wrong closure with a bounded force; DCS (Agarwal et al. 2013) scales its
    information by s^2 -> 0, so the graph returns to what the other edges say."""
    truth = _circle(100)
    i = np.arange(99)
    z = _rel(truth[i], truth[i + 1])
    good_i, good_j = np.array([0, 5]), np.array([99, 99])
    bad = np.array([[3.0, -2.0, 1.0]])
    edges = EdgeSet(
        np.concatenate((i, good_i, [30])),
        np.concatenate((i + 1, good_j, [70])),
        np.vstack((z, _rel(truth[good_i], truth[good_j]), bad)),
        np.tile([50.0, 50.0, 100.0], (102, 1)),
        np.concatenate((np.zeros(99, bool), np.ones(3, bool))),
    )
    x_huber, _ = optimize_pose_graph(truth, edges, options=PoseGraphOptions(huber_delta=3.0))
    x_dcs, w = optimize_pose_graph(truth, edges, options=PoseGraphOptions(kernel="dcs", dcs_phi=9.0))
    err_huber = np.hypot(*(x_huber[:, :2] - truth[:, :2]).T).max()
    err_dcs = np.hypot(*(x_dcs[:, :2] - truth[:, :2]).T).max()
    assert err_dcs < 0.01 < err_huber
    assert w[-1] < 1e-3 and np.all(w[-3:-1] == 1.0)  # the good closures keep their full weight


def _loop_graph(seed: int, n: int = 120, loops: int = 30) -> tuple[np.ndarray, EdgeSet]:
    """A noisy circle with a chain and random loop edges (some robust), poses perturbed off it."""
    rng = np.random.default_rng(seed)
    truth = _circle(n)
    i = np.arange(n - 1)
    li = rng.integers(0, n - 10, loops)
    lj = li + rng.integers(5, 10, loops)
    ii, jj = np.concatenate((i, li)), np.concatenate((i + 1, lj))
    z = _rel(truth[ii], truth[jj]) + rng.normal(0, [0.02, 0.02, 0.01], (len(ii), 3))
    info = rng.uniform(10, 100, (len(ii), 3))
    robust = np.concatenate((np.zeros(n - 1, bool), rng.random(loops) < 0.5))
    return truth + rng.normal(0, [0.2, 0.2, 0.05], truth.shape), EdgeSet(ii, jj, z, info, robust)


def test_assembled_normal_equations_equal_the_sparse_product() -> None:
    for seed in range(3):
        x, edges = _loop_graph(seed)
        n = len(x)
        w = np.where(edges.robust, np.random.default_rng(seed).uniform(0.2, 1.0, len(edges)), 1.0)
        h_ref, g_ref = normal_equations_reference(x, edges, w, n, 3, 1e-6)
        h, g = _HessianPattern(edges, n, 3).assemble(x, edges, w, 1e-6)
        np.testing.assert_allclose(h.toarray(), h_ref.toarray(), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=1e-12)


def test_ldl_solver_agrees_with_superlu() -> None:
    for seed in range(3):
        x0, edges = _loop_graph(seed)
        ldl, _ = optimize_pose_graph(x0, edges, options=PoseGraphOptions(solver="ldl"))
        ref, _ = optimize_pose_graph(x0, edges, options=PoseGraphOptions(solver="superlu"))
        assert np.abs(x0 - ref).max() > 0.1  # the optimization moved the poses
        np.testing.assert_allclose(ldl, ref, atol=1e-9)
