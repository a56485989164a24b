"""The TEB band's least-squares problem: residuals with their analytic Jacobian, and two solvers.

Variables are packed in pose order, ``z = [dT_0, x_1, y_1, th_1, dT_1, ..., x_{n-2}, y_{n-2},
th_{n-2}, dT_{n-2}]`` (the end poses are fixed), so every residual (it touches at most three
consecutive poses and two intervals) depends on variables at most 10 apart: J^T J is a band matrix
with 10 super-diagonals. ``solve_lm_banded`` is a Levenberg-Marquardt on those banded normal
equations (banded Cholesky, LAPACK ``dpbsv``: O(n) per step, where g2o's sparse Cholesky does the
same for teb_local_planner); ``solve_scipy`` hands the same residuals and sparse Jacobian to
``scipy.optimize.least_squares`` (trust-region reflective with LSMR), kept as the reference.

Each residual group stores its Jacobian as (rows, terms, K) values over K variable columns fixed
per row (``BandStructure.cols``), so J^T J, J^T r and J h are a batched matmul and one
``np.bincount`` per group, with no per-residual Python loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dpbsv
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from nav.control.teb_options import TebOptions
from nav.types import wrap_angle

DT_MIN = 0.01  # lower bound of every time interval, s
SampleFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # (M, 2) -> distances, (M, 2) grads


@dataclass(frozen=True)
class BandProblem:
    """The fixed data of one band optimization."""

    ends: np.ndarray  # (2, 3) first and last pose (not optimized)
    ref_a: np.ndarray  # (m, C, 2) candidate path segments' starts for each interior pose
    ref_b: np.ndarray  # (m, C, 2) ... and ends
    sample: SampleFn  # signed distance field with gradient
    v0: np.ndarray  # (3,) measured body velocity
    goal_acc: bool  # decelerate to rest at the band's end
    ref_ab: tuple[np.ndarray, np.ndarray] = field(init=False)  # segments' (dx, dy), (m, C) each
    ref_inv_len2: np.ndarray = field(init=False)  # 1 / squared segment lengths, (m, C)
    # walkers' predicted centres at each interior pose's time (m, W, 2), with the body radius they
    # are taken to have: TEB's dynamic obstacles (EdgeDynamicObstacle, time fixed per pose)
    walkers: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))
    walker_radius: float = 0.0

    def __post_init__(self) -> None:
        ab = self.ref_b - self.ref_a
        object.__setattr__(self, "ref_ab", (ab[..., 0], ab[..., 1]))
        object.__setattr__(self, "ref_inv_len2", 1.0 / np.maximum(np.sum(ab * ab, axis=-1), 1e-12))


@dataclass(frozen=True)
class SolveResult:
    z: np.ndarray
    cost: float  # 0.5 * sum(residual^2) at z
    nfev: int  # residual evaluations
    njev: int  # Jacobian evaluations


def pack(poses: np.ndarray, dts: np.ndarray) -> np.ndarray:
    """(n, 3) poses and (n-1,) intervals -> the variable vector (pose order)."""
    m = len(poses) - 2
    z = np.empty(4 * m + 1)
    z[0] = dts[0]
    blk = z[1:].reshape(m, 4)
    blk[:, :3] = poses[1:-1]
    blk[:, 3] = dts[1:]
    return z


def unpack(z: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    m = (len(z) - 1) // 4
    blk = z[1:].reshape(m, 4)
    poses = np.empty((m + 2, 3))
    poses[0], poses[-1] = ends
    poses[1:-1] = blk[:, :3]
    return poses, np.concatenate((z[:1], blk[:, 3]))


def _bound(
    x: np.ndarray, lo: np.ndarray, hi: np.ndarray, eps: np.ndarray, inv: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """TEB's ``penaltyBoundToInterval`` with source C's scale S = eps: how far ``x`` lies outside
    [lo + eps, hi - eps], in units of the margin eps (``inv`` = 1 / eps), so the limits stay tight
    whatever their magnitude (0.26 m/s or 1.5 m/s) against the time term; returns (value, d/dx)."""
    over = x - (hi - eps)
    under = (lo + eps) - x
    val = (np.maximum(over, 0.0) + np.maximum(under, 0.0)) * inv
    return val, ((over > 0).astype(float) - (under > 0)) * inv


def _eps(o: TebOptions, limit: float) -> float:
    return min(o.penalty_epsilon, 0.1 * limit)


class BandStructure:
    """Residual groups of a band of ``n`` poses (computed once per size and options) with their
    variable columns, and the index maps that turn Jacobian values into J^T J (upper band storage),
    J^T r and J h.

    Three groups; in each, a row's T residual terms share the row's K variable columns, so a group's
    residuals are (R, T) and its Jacobian values (R, T, K):
      poses    (n-2, 3) x [x_k, y_k]: via-point, obstacle, inflation
      segments (n-1, T) x [pose k, pose k+1, dT_k]: time, velocity limits per axis, then for diff
               drives non-holonomic, forward drive and (optionally) turning radius
      accels   (n-1 or n, A) x [pose j, pose j+1, pose j+2, dT_j, dT_j+1]: acceleration limits per
               axis, from the measured velocity and (at the final goal) to rest; a column may
               appear twice in a row (dT_0 in the first, the last dT in the goal row), which
               every product below handles (the two slots' values add up)
    """

    def __init__(self, n: int, o: TebOptions, goal_acc: bool) -> None:
        self.n = n
        m = n - 2
        self.nvar = 4 * m + 1
        dummy = self.nvar  # fixed end poses point here: a zero column dropped from every product

        def pose(k: np.ndarray) -> list[np.ndarray]:
            inner = (k >= 1) & (k <= n - 2)
            return [np.where(inner, 4 * k - 3 + c, dummy) for c in range(3)]

        def dt(k: np.ndarray) -> np.ndarray:
            return np.where(k == 0, 0, 4 * k)

        # acceleration rows j = -1 .. n-3 (n-2 at the final goal): rows -1 and n-2 use virtual
        # segments before and after the band (the measured velocity, rest) with the same dT as
        # their neighbour, which makes them TEB's EdgeAccelerationStart / EdgeAccelerationGoal
        k_in, seg, j = np.arange(1, n - 1), np.arange(n - 1), np.arange(-1, n - 2 + goal_acc)
        jd = np.clip(j, 0, n - 2), np.clip(j + 1, 0, n - 2)
        self.cols = [
            np.column_stack(pose(k_in)[:2]),
            np.column_stack((*pose(seg), *pose(seg + 1), dt(seg))),
            np.column_stack((*pose(j), *pose(j + 1), *pose(j + 2), dt(jd[0]), dt(jd[1]))),
        ]
        self.axes = np.array([0, 1, 2] if o.holonomic else [0, 2])
        na = len(self.axes)
        self.seg_terms = 1 + na + (0 if o.holonomic else 2 + (o.min_turning_radius > 0))
        self.terms = [3, self.seg_terms, na]
        self.sizes = [len(c) * t for c, t in zip(self.cols, self.terms, strict=True)]
        self.rows = sum(self.sizes)
        self._split = np.cumsum(self.sizes)[:-1]
        # per-axis limits: lower, upper, margin eps, 1/eps and sqrt(weight)
        vmax = np.array([o.max_vel_x, o.max_vel_y, o.max_vel_theta])[self.axes]
        vlo = np.array([-o.max_vel_x_backwards, -o.max_vel_y, -o.max_vel_theta])[self.axes]
        vw = np.array([o.weight_max_vel_x, o.weight_max_vel_y, o.weight_max_vel_theta])[self.axes]
        veps = np.array([_eps(o, v) for v in vmax])
        self.vel = (vlo, vmax, veps, 1.0 / np.maximum(veps, 1e-6), np.sqrt(vw))
        amax = np.array([o.acc_lim_x, o.acc_lim_y, o.acc_lim_theta])[self.axes]
        aw = np.array([o.weight_acc_lim_x, o.weight_acc_lim_y, o.weight_acc_lim_theta])[self.axes]
        aeps = np.array([_eps(o, a) for a in amax])
        self.acc = (-amax, amax, aeps, 1.0 / np.maximum(aeps, 1e-6), np.sqrt(aw))
        # upper bandwidth of J^T J
        self.u = max(int((np.where(c == dummy, -1, c).max(axis=1) - c.min(axis=1)).max()) for c in self.cols)
        # J^T J: a row's K x K block entry (a, b) with col_a <= col_b lands at ab[u + col_a - col_b, col_b]
        sels, dests = [], []
        for c in self.cols:
            ca, cb = c[:, :, None], c[:, None, :]
            keep = (ca <= cb) & (ca != dummy) & (cb != dummy)
            sels.append(np.flatnonzero(keep))
            dests.append(((self.u + ca - cb) * self.nvar + cb)[keep])
        self._pair_sel = sels
        self._pair_dest = np.concatenate(dests)
        self._col_flat = np.concatenate([c.ravel() for c in self.cols])
        # CSR pattern of J for scipy: row-major over (R, T, K), dummy columns dropped
        rows, cols, off = [], [], 0
        for c, t in zip(self.cols, self.terms, strict=True):
            r = off + np.arange(len(c) * t).reshape(len(c), t)
            rows.append(np.broadcast_to(r[:, :, None], (len(c), t, c.shape[1])).ravel())
            cols.append(np.broadcast_to(c[:, None, :], (len(c), t, c.shape[1])).ravel())
            off += len(c) * t
        all_cols = np.concatenate(cols)
        self._csr_keep = all_cols != dummy
        self._csr_rows, self._csr_cols = np.concatenate(rows)[self._csr_keep], all_cols[self._csr_keep]

    def jtj(self, vals: list[np.ndarray]) -> np.ndarray:
        """J^T J in LAPACK's upper band storage, shape (u + 1, nvar)."""
        blocks = [
            np.matmul(v.transpose(0, 2, 1), v).ravel()[s] for v, s in zip(vals, self._pair_sel, strict=True)
        ]
        flat = np.bincount(self._pair_dest, np.concatenate(blocks), minlength=(self.u + 1) * self.nvar)
        return flat.reshape(self.u + 1, self.nvar)

    def jtr(self, r: np.ndarray, vals: list[np.ndarray]) -> np.ndarray:
        parts = np.split(r, self._split)
        w = [
            np.matmul(p.reshape(v.shape[:2])[:, None, :], v).ravel() for v, p in zip(vals, parts, strict=True)
        ]
        return np.bincount(self._col_flat, np.concatenate(w), minlength=self.nvar + 1)[: self.nvar]

    def jvp(self, vals: list[np.ndarray], h: np.ndarray) -> np.ndarray:
        """J h."""
        hx = np.append(h, 0.0)
        return np.concatenate(
            [np.matmul(v, hx[c][:, :, None]).ravel() for v, c in zip(vals, self.cols, strict=True)]
        )

    def sparse(self, vals: list[np.ndarray]) -> csr_matrix:
        data = np.concatenate([v.ravel() for v in vals])[self._csr_keep]
        return csr_matrix((data, (self._csr_rows, self._csr_cols)), shape=(self.rows, self.nvar))


def _segment_distance(pts: np.ndarray, p: BandProblem) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each of (K, 2) points to the nearest of its own candidate path segments, and
    its gradient (the unit vector from the nearest point; zero on the path)."""
    apx = pts[:, :1] - p.ref_a[..., 0]
    apy = pts[:, 1:] - p.ref_a[..., 1]
    abx, aby = p.ref_ab
    t = np.clip((apx * abx + apy * aby) * p.ref_inv_len2, 0.0, 1.0)
    dx, dy = apx - t * abx, apy - t * aby
    d2 = dx * dx + dy * dy
    best = (np.arange(len(pts)), np.argmin(d2, axis=1))
    dist = np.sqrt(d2[best])
    inv = 1.0 / np.maximum(dist, 1e-12)
    return dist, np.column_stack((dx[best] * inv, dy[best] * inv))


def _with_walkers(
    xy: np.ndarray, d: np.ndarray, grad: np.ndarray, p: BandProblem
) -> tuple[np.ndarray, np.ndarray]:
    """The static field's distance and gradient per pose, replaced by the nearest walker's (its
    predicted centre at the pose's time, less its radius) where that is nearer."""
    off = xy[:, None, :] - p.walkers  # (m, W, 2)
    dist = np.hypot(off[..., 0], off[..., 1])
    w = dist.argmin(axis=1)
    rows = np.arange(len(xy))
    dw = dist[rows, w]
    closer = dw - p.walker_radius < d
    unit = off[rows, w] / np.maximum(dw, 1e-9)[:, None]
    return np.where(closer, dw - p.walker_radius, d), np.where(closer[:, None], unit, grad)


def evaluate(
    z: np.ndarray, p: BandProblem, o: TebOptions, st: BandStructure, radius: float
) -> tuple[np.ndarray, list[np.ndarray]]:
    """All weighted residuals (TEB's edges, in ``st``'s group order) and each group's (R, K)
    Jacobian slot values. Hinge terms contribute zero rows while inactive."""
    poses, dts = unpack(z, p.ends)
    m, ns, na = len(poses) - 2, len(dts), len(st.axes)
    # poses: via-point (distance to the global path's nearby segments), obstacle and inflation
    # (clearance of the footprint circle, scaled by S = min_obstacle_dist like the limits)
    r1, j1 = np.empty((m, 3)), np.empty((m, 3, 2))
    sw = math.sqrt(o.weight_viapoint)
    dist, grad = _segment_distance(poses[1:-1, :2], p)
    r1[:, 0], j1[:, 0] = sw * dist, sw * grad
    d, dgrad = p.sample(poses[1:-1, :2])
    if p.walkers.shape[1]:
        d, dgrad = _with_walkers(poses[1:-1, :2], d, dgrad, p)
    scale = max(o.min_obstacle_dist, 0.05)
    k = np.array([math.sqrt(o.weight_obstacle), math.sqrt(o.weight_inflation)]) / scale
    gap = np.array([o.min_obstacle_dist + 0.01, o.inflation_dist]) - (d - radius)[:, None]
    on = gap > 0
    r1[:, 1:] = k * np.where(on, gap, 0.0)
    j1[:, 1:] = np.where(on[..., None], -k[:, None] * dgrad[:, None, :], 0.0)
    # segments: body velocities (fwd, lat, ang) / dT_k, derivatives over slots [pose k, pose k+1, dT_k]
    dxy = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    c0, s0 = c[:-1], s[:-1]
    fwd = dxy[:, 0] * c0 + dxy[:, 1] * s0
    lat = dxy[:, 1] * c0 - dxy[:, 0] * s0
    ang = wrap_angle(np.diff(poses[:, 2]))
    dq = np.zeros((ns, 3, 7))
    dq[:, 0, :5] = np.column_stack((-c0, -s0, lat, c0, s0))
    dq[:, 1, :5] = np.column_stack((s0, -c0, -fwd, -s0, c0))
    dq[:, 2, 2], dq[:, 2, 5] = -1.0, 1.0
    inv_dt = 1.0 / dts
    vel = np.column_stack((fwd, lat, ang))[:, st.axes] * inv_dt[:, None]
    dvel = dq[:, st.axes] * inv_dt[:, None, None]
    dvel[..., 6] = -vel * inv_dt[:, None]
    r2, j2 = np.empty((ns, st.seg_terms)), np.zeros((ns, st.seg_terms, 7))
    sw = math.sqrt(o.weight_optimaltime)  # TEB EdgeTimeOptimal: one residual per interval
    r2[:, 0], j2[:, 0, 6] = sw * dts, sw
    lo, hi, eps, inv, sw_a = st.vel
    b, db = _bound(vel, lo, hi, eps, inv)
    r2[:, 1 : 1 + na] = sw_a * b
    j2[:, 1 : 1 + na] = (sw_a * db)[..., None] * dvel
    if not o.holonomic:
        # TEB EdgeKinematicsDiffDrive: both headings make equal angles with the chord; forward drive
        sw = math.sqrt(o.weight_kinematics_nh)
        cs, ss = c0 + c[1:], s0 + s[1:]
        r2[:, 1 + na] = sw * (cs * dxy[:, 1] - ss * dxy[:, 0])
        th0 = -s0 * dxy[:, 1] - c0 * dxy[:, 0]
        th1 = -s[1:] * dxy[:, 1] - c[1:] * dxy[:, 0]
        j2[:, 1 + na, :6] = sw * np.column_stack((ss, -cs, th0, -ss, cs, th1))
        sw = math.sqrt(o.weight_kinematics_forward_drive)
        back = fwd < 0
        r2[:, 2 + na] = sw * np.where(back, -fwd, 0.0)
        j2[:, 2 + na] = np.where(back[:, None], -sw * dq[:, 0], 0.0)
        if o.min_turning_radius > 0:
            sw = math.sqrt(o.weight_kinematics_turning_radius)
            length = np.hypot(dxy[:, 0], dxy[:, 1])
            unit = dxy / np.maximum(length, 1e-12)[:, None]
            gap_r = o.min_turning_radius * np.abs(ang) - length
            dgap = o.min_turning_radius * np.sign(ang)[:, None] * dq[:, 2]
            dgap[:, :2] += unit
            dgap[:, 3:5] -= unit
            on_r = gap_r > 0
            r2[:, 3 + na] = sw * np.where(on_r, gap_r, 0.0)
            j2[:, 3 + na] = np.where(on_r[:, None], sw * dgap, 0.0)
    # accelerations a_j = 2 (v_j+1 - v_j) / (dT_j + dT_j+1) over [pose j, j+1, j+2, dT_j, dT_j+1],
    # between the measured velocity, the band's segments and (at the final goal) rest
    lo, hi, eps, inv, sw_a = st.acc
    tail = 1 if p.goal_acc else 0
    v_ext = np.concatenate((p.v0[st.axes][None], vel, np.zeros((tail, na))))
    dv_ext = np.concatenate((np.zeros((1, na, 7)), dvel, np.zeros((tail, na, 7))))
    dt_ext = np.concatenate((dts[:1], dts, dts[ns - tail :]))
    mid = dt_ext[:-1] + dt_ext[1:]
    g = (2.0 / mid)[:, None]
    acc = np.diff(v_ext, axis=0) * g
    da = np.zeros((len(acc), na, 11))
    da[..., 0:6] = -g[..., None] * dv_ext[:-1, :, :6]
    da[..., 3:9] += g[..., None] * dv_ext[1:, :, :6]
    corr = acc / mid[:, None]
    da[..., 9] = -g * dv_ext[:-1, :, 6] - corr
    da[..., 10] = g * dv_ext[1:, :, 6] - corr
    b, db = _bound(acc, lo, hi, eps, inv)
    r3, j3 = sw_a * b, (sw_a * db)[..., None] * da
    return np.concatenate((r1.ravel(), r2.ravel(), r3.ravel())), [j1, j2, j3]


def lower_bounds(nvar: int) -> np.ndarray:
    lb = np.full(nvar, -np.inf)
    lb[0] = DT_MIN
    lb[4::4] = DT_MIN
    return lb


def solve_lm_banded(
    z0: np.ndarray,
    fn: Callable[[np.ndarray], tuple[np.ndarray, list[np.ndarray]]],
    st: BandStructure,
    max_iter: int,
    ftol: float = 1e-6,
    tau: float = 1e-2,
) -> SolveResult:
    """Projected Levenberg-Marquardt: each iteration solves (J^T J + mu I) h = -J^T r by banded
    Cholesky (LAPACK dpbsv, O(n u^2)), clips dT >= DT_MIN, and accepts the step when the residuals
    fall (Nielsen's damping update, mu_0 = tau max diag(J^T J)). Plain mu I damping, as a trust
    region in the variables' own units, converges here where Marquardt's mu diag(J^T J) does not:
    the hinge penalties give near-zero curvature to variables whose limits are not yet active, and
    Marquardt lets those take huge steps. One residual + Jacobian evaluation per iteration."""
    lb = lower_bounds(st.nvar)
    z = np.maximum(z0, lb)
    r, vals = fn(z)
    if not np.all(np.isfinite(r)):
        raise ValueError("residuals are not finite at the initial band")
    cost = 0.5 * float(r @ r)
    nfev, mu, nu = 1, -1.0, 2.0
    for _ in range(max_iter):
        g = st.jtr(r, vals)
        ab = st.jtj(vals)
        if mu < 0:
            mu = tau * max(float(ab[st.u].max()), 1e-12)
        ab[st.u] += mu
        _, h, info = dpbsv(ab, -g, lower=0, overwrite_ab=1)
        if info != 0:  # not positive definite: only with non-finite entries
            raise ValueError("banded Cholesky failed (non-finite Jacobian)")
        z_new = z + h
        clipped = z_new < lb
        if clipped.any():
            z_new = np.maximum(z_new, lb)
            h = z_new - z
            lin = r + st.jvp(vals, h)
            predicted = cost - 0.5 * float(lin @ lin)
        else:  # model decrease of the exact LM step: (h . (mu h - g)) / 2
            predicted = 0.5 * float(h @ (mu * h - g))
        r_new, vals_new = fn(z_new)
        nfev += 1
        cost_new = 0.5 * float(r_new @ r_new)
        gain = (cost - cost_new) / predicted if predicted > 0 and math.isfinite(cost_new) else -1.0
        if gain > 0:
            done = cost - cost_new <= ftol * cost
            z, r, vals, cost = z_new, r_new, vals_new, cost_new
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            nu = 2.0
            if done:
                break
        else:
            mu, nu = mu * nu, nu * 2.0
    return SolveResult(z, cost, nfev, nfev)


def solve_scipy(
    z0: np.ndarray,
    fn: Callable[[np.ndarray], tuple[np.ndarray, list[np.ndarray]]],
    st: BandStructure,
    max_iter: int,
    ftol: float = 1e-6,
) -> SolveResult:
    """``scipy.optimize.least_squares`` (trust-region reflective, LSMR steps) on the same residuals
    with the analytic sparse Jacobian."""
    cache: dict[str, tuple[np.ndarray, tuple[np.ndarray, list[np.ndarray]]]] = {}

    def both(z: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        hit = cache.get("last")
        if hit is None or not np.array_equal(hit[0], z):
            cache["last"] = (z.copy(), fn(z))
        return cache["last"][1]

    lb = lower_bounds(st.nvar)
    res = least_squares(
        lambda z: both(z)[0],
        np.maximum(z0, lb + 1e-3 * np.isfinite(lb)),
        jac=lambda z: st.sparse(both(z)[1]),
        bounds=(lb, np.full(st.nvar, np.inf)),
        method="trf",
        tr_solver="lsmr",
        x_scale=1.0,
        tr_options={"maxiter": 15},
        max_nfev=max_iter,
        xtol=1e-6,
        ftol=ftol,
    )
    return SolveResult(res.x, float(res.cost), int(res.nfev), int(res.njev or 0))


__all__ = [
    "BandProblem",
    "BandStructure",
    "SolveResult",
    "evaluate",
    "pack",
    "solve_lm_banded",
    "solve_scipy",
    "unpack",
]
