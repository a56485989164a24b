"""TEB band optimization internals: the analytic Jacobian against finite differences, the banded
normal equations against dense algebra, the distance field's gradient, and the two solvers."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from bench.teb import corridor, omni_options, skid_options, straight_path
from nav.control.teb import DistanceField, TebController, _nearest_segments
from nav.control.teb_optim import BandProblem, BandStructure, evaluate, pack, unpack
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Pose2D, Twist2D

OBSTACLE = (1.0, 0.0, 0.15)


def band_problem(kind: str, goal_acc: bool, seed: int = 0):
    """A perturbed initial band of the obstacle scene, its problem, structure and options (diff
    with a turning radius so every residual group is active somewhere)."""
    o = skid_options(min_turning_radius=0.3) if kind == "diff" else omni_options()
    ctl = TebController(o)
    ctl.set_path(straight_path())
    cm = corridor(OBSTACLE)
    dfield = DistanceField(cm)
    pose, vel = Pose2D(), Twist2D(0.1, 0.02 if o.holonomic else 0.0, 0.1)
    local = ctl._local_path(pose, cm)
    poses, dts, _ = ctl._initial_band(pose, vel, local, dfield, goal_acc)
    rng = np.random.default_rng(seed)
    poses[1:-1] += rng.normal(0.0, 0.05, poses[1:-1].shape)
    dts = dts * rng.uniform(0.2, 1.5, len(dts))  # violates velocity / acceleration limits
    seg_a, seg_b = local[:-1, :2], local[1:, :2]
    near = _nearest_segments(poses[1:-1, :2], seg_a, seg_b)
    cand = np.clip(near[:, None] + np.arange(-1, 2)[None, :], 0, len(seg_a) - 1)
    ends = np.stack((poses[0], poses[-1]))
    problem = BandProblem(ends, seg_a[cand], seg_b[cand], dfield.sample, vel.as_array(), goal_acc)
    st = BandStructure(len(poses), o, goal_acc)
    return pack(poses, dts), problem, st, o, ctl._radius


def dense_jacobian(st: BandStructure, vals: list[np.ndarray]) -> np.ndarray:
    return st.sparse(vals).toarray()


@pytest.mark.parametrize("kind", ["diff", "omni"])
@pytest.mark.parametrize("goal_acc", [False, True])
def test_analytic_jacobian_matches_central_differences(kind: str, goal_acc: bool) -> None:
    z, problem, st, o, radius = band_problem(kind, goal_acc)
    r, vals = evaluate(z, problem, o, st, radius)
    assert len(r) == st.rows
    jac = dense_jacobian(st, vals)
    h = 1e-7
    fd = np.empty_like(jac)
    for i in range(len(z)):
        dz = np.zeros_like(z)
        dz[i] = h
        fd[:, i] = (
            evaluate(z + dz, problem, o, st, radius)[0] - evaluate(z - dz, problem, o, st, radius)[0]
        ) / (2 * h)
    # hinge kinks and the field's cell edges are not differentiable: allow a handful of entries
    bad = np.abs(jac - fd) > 1e-4 * np.maximum(1.0, np.abs(fd))
    assert bad.sum() <= 3, np.argwhere(bad)[:10]
    for v in vals:  # every residual term was active somewhere, so the comparison covered it
        assert np.all(np.abs(v).max(axis=(0, 2)) > 0)


def test_banded_normal_equations_match_dense_algebra() -> None:
    z, problem, st, o, radius = band_problem("diff", True, seed=3)
    r, vals = evaluate(z, problem, o, st, radius)
    jac = dense_jacobian(st, vals)
    jtj = jac.T @ jac
    ab = st.jtj(vals)
    assert st.u == 10  # residuals span 3 poses and 2 intervals: 10 super-diagonals
    for d in range(st.u + 1):
        np.testing.assert_allclose(ab[st.u - d, d:], np.diag(jtj, d), rtol=1e-9, atol=1e-9)
    assert np.all(np.triu(jtj, st.u + 1) == 0)  # nothing outside the band
    np.testing.assert_allclose(st.jtr(r, vals), jac.T @ r, rtol=1e-9, atol=1e-9)
    h = np.random.default_rng(1).normal(size=len(z))
    np.testing.assert_allclose(st.jvp(vals, h), jac @ h, rtol=1e-9, atol=1e-9)
    poses, dts = unpack(z, problem.ends)
    np.testing.assert_allclose(pack(poses, dts), z)


def test_distance_field_gradient_on_a_rotated_grid() -> None:
    geo = GridGeometry(0.05, 60, 40, Pose2D(0.3, -0.7, 0.6))
    costs = np.zeros((40, 60), np.uint8)
    costs[15:25, 25:32] = LETHAL_OBSTACLE
    f = DistanceField(Costmap(geo, costs))
    rng = np.random.default_rng(2)
    pts = geo.cell_to_world(rng.integers(3, 37, 40), rng.integers(3, 57, 40)) + rng.uniform(
        -0.02, 0.02, (40, 2)
    )
    d, grad = f.sample(pts)
    np.testing.assert_allclose(d, f(pts))
    h = 1e-6
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = h
        fd = (f(pts + step) - f(pts - step)) / (2 * h)
        np.testing.assert_allclose(grad[:, axis], fd, atol=1e-4)
    assert np.abs(grad).max() > 0.5  # a distance field's slope is ~1 away from ridges


@pytest.mark.parametrize("kind", ["diff", "omni"])
def test_both_solvers_bend_around_the_obstacle(kind: str) -> None:
    """The default banded Levenberg-Marquardt and scipy's least_squares reach bands of similar cost
    that clear the obstacle; the default is at least as good."""
    base = skid_options() if kind == "diff" else omni_options()
    inscribed = 0.10 if kind == "diff" else 0.25
    cm = corridor(OBSTACLE)
    costs = {}
    for solver in ("lm_banded", "scipy"):
        ctl = TebController(replace(base, solver=solver))
        ctl.set_path(straight_path())
        _, dbg = ctl.compute(Pose2D(), Twist2D(), cm)
        clear = np.hypot(dbg.band[:, 0] - OBSTACLE[0], dbg.band[:, 1] - OBSTACLE[1]) - OBSTACLE[2]
        assert clear.min() > inscribed, solver
        assert np.all(dbg.dts >= 0.01 - 1e-12)
        assert dbg.nfev <= base.no_inner_iterations * base.no_outer_iterations + 1
        assert math.isfinite(dbg.cost)
        costs[solver] = dbg.cost
    assert costs["lm_banded"] <= 1.25 * costs["scipy"]
