"""Timed Elastic Band local controller (Rösmann, Hoffmann & Bertram, "Integrated online trajectory
planning and optimization in distinctive topologies", Robotics and Autonomous Systems 88, 2017), as
source C writes it and ``teb_local_planner`` implements it.

The band B = (Q, tau) is a sequence of poses s_i = [x_i, y_i, beta_i] and the time intervals dT_i
between them. Each cycle it is initialised from the global path (the first
``max_global_plan_lookahead_dist`` metres) or warm-started from the previous cycle's band (pruned
behind the robot and extended to the new local goal), then optimized:

    B* = argmin_B sum_k gamma_k f_k(B)

with a Levenberg-Marquardt on banded normal equations (``nav.control.teb_optim``; ``solver =
"scipy"`` runs ``scipy.optimize.least_squares`` on the same problem instead). Every term is a
residual whose square is TEB's penalty e(x, x_r, eps, S, n=2) = ((x - (x_r - eps)) / S)^2 when
x > x_r - eps: distance to the global path (via-points), obstacle clearance below
``min_obstacle_dist`` / ``inflation_dist`` (from a signed distance field of the local costmap's
lethal cells, sampled bilinearly), each dT_i (time-optimal), |v|, |w|, |a| limits, and the
differential drive's non-holonomic and forward-drive constraints (TEB's EdgeKinematicsDiffDrive;
omni bases drop them and get a lateral-velocity limit instead, source C's kinematics). Each
residual touches at most three consecutive poses and two intervals, so with the variables in pose
order J^T J is a band matrix: each iteration is one analytic residual + Jacobian evaluation and
one banded Cholesky solve, O(n).

TEB escapes a blocking obstacle by exploring homotopy classes; navdeck seeds a single band on the
side of least detour instead: band poses that start closer to an obstacle than
``min_obstacle_dist`` are pushed sideways along the path's normal before optimizing. The command
sent is the band's first segment, v = body-frame displacement / dT_0 and w = (beta_1 - beta_0) /
dT_0, after footprint-checking the first ``feasibility_check_no_poses`` poses against the costmap
(TEB's ``isTrajectoryFeasible``) with TEB's own obstacle model: each lethal cell is a point obstacle
at its centre (teb_local_planner's costmap conversion), so a pose collides when a lethal cell's
centre lies inside its footprint (:func:`centre_collisions`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from nav.control.errors import ControllerError, InvalidPath, NoValidControl, PatienceExceeded
from nav.control.footprint import swept_poses, swept_turn
from nav.control.teb_optim import (
    BandProblem,
    BandStructure,
    SolveResult,
    evaluate,
    pack,
    solve_lm_banded,
    solve_scipy,
    unpack,
)
from nav.control.teb_options import TebOptions
from nav.costmap.footprint import circle_footprint
from nav.types import LETHAL_OBSTACLE, NO_INFORMATION, Costmap, Path, Pose2D, Twist2D, wrap_angle
from nav.walkers import PERSON_RADIUS

_FAR = 1e3  # distance reported by an obstacle-free field, m


class DistanceField:
    """Signed distance (m) from the nearest lethal cell's edge: positive in free space, negative
    inside obstacles (so a pose that starts inside one still has a gradient out of it). Sampled
    bilinearly between cell centres, so the optimizer sees a continuous function."""

    def __init__(self, costmap: Costmap, unknown_is_lethal: bool = False) -> None:
        g = costmap.geometry
        self.geometry = g
        lethal = costmap.costs == LETHAL_OBSTACLE
        if unknown_is_lethal:
            lethal |= costmap.costs == NO_INFORMATION
        res = g.resolution
        if not lethal.any():
            self.field = np.full(costmap.costs.shape, _FAR)
        else:
            outside = ndimage.distance_transform_edt(~lethal) * res
            inside = ndimage.distance_transform_edt(lethal) * res if (~lethal).any() else None
            if inside is None:
                self.field = np.full(costmap.costs.shape, -_FAR)
            else:
                self.field = np.where(lethal, -(inside - 0.5 * res), outside - 0.5 * res)
        # bilinear patch of every cell [j, i] .. [j+1, i+1] as f = a + b fu + c fv + d fu fv, so a
        # lookup with its gradient is one gather of 4 coefficients
        f = self.field
        if f.shape[0] < 2 or f.shape[1] < 2:
            f = np.pad(f, ((0, max(2 - f.shape[0], 0)), (0, max(2 - f.shape[1], 0))), mode="edge")
        f00, f01, f10, f11 = f[:-1, :-1], f[:-1, 1:], f[1:, :-1], f[1:, 1:]
        self._coef = np.stack((f00, f01 - f00, f10 - f00, f11 - f10 - f01 + f00), axis=-1).reshape(-1, 4)
        self._cells = (f.shape[1] - 1, f.shape[0] - 1)  # patches per row, per column
        self._uv_hi = np.array(self._cells, dtype=float)
        self._cell_hi = np.array(self._cells) - 1
        # world (x, y) -> continuous cell-centre coordinates (u, v) = xy @ to_uv + uv0
        co, si = math.cos(g.origin.theta), math.sin(g.origin.theta)
        self._to_uv = np.array([[co, -si], [si, co]]) / res
        self._uv0 = -np.array([g.origin.x, g.origin.y]) @ self._to_uv - 0.5

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        """Distances at (M, 2) world points; points off the grid read the nearest edge cell."""
        return self.sample(xy, gradient=False)[0]

    def sample(self, xy: np.ndarray, gradient: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(distances (M,), gradients (M, 2) in the world frame) of the bilinear interpolant between
        cell centres at (M, 2) world points: the exact derivative the optimizer's Jacobian needs
        (zero across the grid's edge, where the lookup is clamped; empty without ``gradient``)."""
        uv = np.asarray(xy, dtype=float).reshape(-1, 2) @ self._to_uv + self._uv0
        clamped = np.clip(uv, 0.0, self._uv_hi)
        cell = np.minimum(clamped.astype(np.int64), self._cell_hi)
        fu, fv = (clamped - cell).T
        a, b, c, d = self._coef[cell[:, 1] * self._cells[0] + cell[:, 0]].T
        dist = a + b * fu + (c + d * fu) * fv
        if not gradient:
            return dist, np.zeros((0, 2))
        grad = (np.column_stack((b + d * fv, c + d * fu)) * (uv == clamped)) @ self._to_uv.T
        return dist, grad


@dataclass(frozen=True)
class TebDebug:
    """One cycle's band, for the 3D view and tests."""

    band: np.ndarray  # (N, 3) optimized poses, map frame
    dts: np.ndarray  # (N-1,) time intervals, s
    local_goal: np.ndarray  # (3,) the band's fixed end pose
    warm_started: bool = False
    nfev: int = 0  # residual evaluations by the solver (lm_banded: each with its Jacobian)
    njev: int = 0  # Jacobian evaluations
    cost: float = 0.0  # final 0.5 * sum(residual^2)
    solve_time: float = 0.0  # wall time of the optimization, s
    min_clearance: float = math.inf  # smallest centre-to-obstacle distance along the band, m
    reference: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # local global path
    waiting_for: str = ""  # why the command is a stop this cycle (a walker in the band's way)

    @property
    def velocities(self) -> np.ndarray:
        """(N-1, 3) body-frame (vx, vy, wz) of each band segment."""
        return segment_velocities(self.band, self.dts)

    @property
    def accelerations(self) -> np.ndarray:
        """(N-2, 3) TEB accelerations a_i = 2 (v_{i+1} - v_i) / (dT_i + dT_{i+1})."""
        v = self.velocities
        return 2.0 * np.diff(v, axis=0) / (self.dts[:-1] + self.dts[1:])[:, None]


def centre_collisions(
    costmap: Costmap,
    poses: np.ndarray,
    polygon: np.ndarray,
    radius: float | None = None,
    unknown_is_lethal: bool = False,
) -> np.ndarray:
    """(M,) bool: which of the (M, 3) poses have a lethal cell's centre inside the footprint
    ``polygon`` (base_link), or within ``radius`` of the pose for a round robot (``radius`` given).

    Why cell centres and not whole cells: a lethal cell only says a return fell somewhere in it.
    Taking the whole cell (the footprint's outline touching it) adds a cell to every obstacle on
    the robot's side, so two marks facing each other across a gap one cell wider than the robot
    close it for good (the greenhouse post: 0.6 m for a 0.5 m robot). The centre is TEB's own
    obstacle model and the inflation layer's inscribed test; cells off the map count only with
    ``unknown_is_lethal``, like NO_INFORMATION cells."""
    pz = np.asarray(poses, dtype=float).reshape(-1, 3)
    out = np.zeros(len(pz), dtype=bool)
    if len(pz) == 0:
        return out
    geo = costmap.geometry
    reach = radius if radius is not None else float(np.max(np.hypot(polygon[:, 0], polygon[:, 1])))
    k = math.ceil(reach / geo.resolution) + 1
    rows, cols = geo.world_to_cell(pz[:, :2])
    off = np.arange(-k, k + 1)
    rr, cc = np.broadcast_arrays(
        rows[:, None, None] + off[None, :, None], cols[:, None, None] + off[None, None, :]
    )
    inside_map = geo.in_bounds(rr, cc)
    cost = np.full(rr.shape, NO_INFORMATION, dtype=np.uint8)
    cost[inside_map] = costmap.costs[rr[inside_map], cc[inside_map]]
    bad = cost == LETHAL_OBSTACLE
    if unknown_is_lethal:
        bad |= cost == NO_INFORMATION
    m, i, j = np.nonzero(bad)
    if len(m) == 0:
        return out
    d = geo.cell_to_world(rr[m, i, j], cc[m, i, j]) - pz[m, :2]
    if radius is not None:
        hit = np.hypot(d[:, 0], d[:, 1]) < radius
    else:  # into base_link, then an even-odd point-in-polygon test
        co, si = np.cos(pz[m, 2]), np.sin(pz[m, 2])
        x, y = co * d[:, 0] + si * d[:, 1], -si * d[:, 0] + co * d[:, 1]
        hit = np.zeros(len(m), dtype=bool)
        for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
            crosses = (y0 > y) != (y1 > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
            hit ^= crosses & (x < x_at)
    out[m[hit]] = True
    return out


def segment_velocities(poses: np.ndarray, dts: np.ndarray) -> np.ndarray:
    """Body-frame (vx, vy, wz) of each band segment, expressed in the segment's start pose."""
    d = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    vx = (d[:, 0] * c + d[:, 1] * s) / dts
    vy = (-d[:, 0] * s + d[:, 1] * c) / dts
    w = wrap_angle(np.diff(poses[:, 2])) / dts
    return np.column_stack((vx, vy, w))


def _nearest_segments(pts: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index of the polyline segment (a[k] -> b[k]) nearest to each of (M, 2) points."""
    ab = b - a
    len2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    ap = pts[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("mki,ki->mk", ap, ab) / len2, 0.0, 1.0)
    diff = ap - t[..., None] * ab[None, :, :]
    return np.argmin(np.einsum("mki,mki->mk", diff, diff), axis=1)


def band_fold(poses: np.ndarray, ref: np.ndarray) -> float:
    """How far (m) a band runs backwards along the reference path ``ref`` at worst: each band segment's
    displacement is projected on the direction of the reference segment nearest its midpoint, and
    the result is the largest drop of the accumulated progress below its running maximum (0 for a
    band that only moves forwards or sideways along the path)."""
    if len(poses) < 2 or len(ref) < 2:
        return 0.0
    a, b = ref[:-1, :2], ref[1:, :2]
    d = np.diff(poses[:, :2], axis=0)
    near = _nearest_segments(poses[:-1, :2] + 0.5 * d, a, b)
    tangent = b[near] - a[near]
    tangent /= np.maximum(np.hypot(*tangent.T), 1e-12)[:, None]
    progress = np.concatenate(([0.0], np.cumsum(np.einsum("ij,ij->i", d, tangent))))
    return float(np.max(np.maximum.accumulate(progress) - progress))


def _resample(xy: np.ndarray, theta: np.ndarray, t: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Resample a polyline with headings and cumulative times to ``n`` poses equally spaced in arc
    length; returns ((n, 3) poses, (n,) times)."""
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    keep = np.concatenate(([True], np.diff(s) > 1e-9))
    s, xy, theta, t = s[keep], xy[keep], np.unwrap(theta[keep]), t[keep]
    if len(s) < 2:
        poses = np.repeat(np.array([[xy[0, 0], xy[0, 1], theta[0]]]), n, axis=0)
        return poses, np.full(n, t[0])
    q = np.linspace(0.0, s[-1], n)
    poses = np.column_stack((np.interp(q, s, xy[:, 0]), np.interp(q, s, xy[:, 1]), np.interp(q, s, theta)))
    return poses, np.interp(q, s, t)


def _reachable(clear: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """(P, K) bool: which of the K offsets of each of P poses (clearances ``clear``, sampled
    outwards) are reached without the clearance dropping below the pose's ``floor`` on the way."""
    return np.minimum.accumulate(clear, axis=1) >= floor[:, None]


class TebController:
    """TEB controller with the same interface as :class:`~nav.control.dwa.DwaController`:
    ``set_path`` once per (re)plan, ``compute`` once per control cycle, ``reset`` per goal."""

    def __init__(self, options: TebOptions | None = None) -> None:
        self.options = options or TebOptions()
        o = self.options
        self._polygon = (
            np.asarray(o.footprint, dtype=float) if o.footprint else circle_footprint(o.robot_radius)
        )
        self._radius = o.circumscribed_radius
        self._path: np.ndarray | None = None
        self._s = np.zeros(0)
        self._progress = 0
        self._band: np.ndarray | None = None
        self._dts: np.ndarray | None = None
        self._fail_cycles = 0
        self._structures: dict[tuple[int, bool], BandStructure] = {}
        self.last_debug: TebDebug | None = None
        self._walkers = np.zeros((0, 2))  # walkers' centres now (map frame)
        self._walker_vel = np.zeros((0, 2))  # and their velocities, m/s

    def set_walkers(self, centres: np.ndarray, velocities: np.ndarray) -> None:
        """Walkers (map frame, (W, 2) centres now and velocities) for the next ``compute`` calls:
        constant-velocity dynamic obstacles (teb_local_planner's ``include_dynamic_obstacles``)."""
        c = np.asarray(centres, dtype=float).reshape(-1, 2)
        v = np.asarray(velocities, dtype=float).reshape(-1, 2)
        if c.shape != v.shape or not (np.isfinite(c).all() and np.isfinite(v).all()):
            raise ControllerError("walkers need finite (W, 2) centres and velocities of one shape")
        self._walkers, self._walker_vel = c, v

    def _walkers_at(self, dts: np.ndarray) -> np.ndarray:
        """Walkers' predicted centres (n - 2, W, 2) at the band's interior poses' times."""
        if not self.options.include_dynamic_obstacles:
            return np.zeros((max(len(dts) - 1, 0), 0, 2))
        return self._predict_walkers(np.cumsum(dts)[:-1])

    def _predict_walkers(self, t: np.ndarray) -> np.ndarray:
        """Walkers' centres (len(t), W, 2) at the times ``t`` (s from now), at constant velocity."""
        return self._walkers[None] + self._walker_vel[None] * t[:, None, None]

    # -- path -------------------------------------------------------------------------------------
    def set_path(self, path: Path) -> None:
        """Follow ``path`` (map frame). The band is kept for a warm start unless the goal moved."""
        poses = np.asarray(path.poses, dtype=float)
        if poses.ndim != 2 or poses.shape[0] == 0 or poses.shape[1] != 3 or not np.all(np.isfinite(poses)):
            raise InvalidPath("path must be a non-empty finite (N, 3) array")
        same_goal = self._path is not None and np.allclose(self._path[-1], poses[-1], atol=1e-6)
        if self.options.global_plan_overwrite_orientation and not self.options.holonomic and len(poses) > 1:
            poses = poses.copy()
            heading = np.arctan2(*np.diff(poses[:, 1::-1], axis=0).T)
            poses[:-1, 2] = heading
        self._path = poses
        seg = np.hypot(*np.diff(poses[:, :2], axis=0).T) if len(poses) > 1 else np.zeros(0)
        self._s = np.concatenate(([0.0], np.cumsum(seg)))
        self._progress = 0
        if not same_goal:
            self._band = self._dts = None

    def reset(self) -> None:
        """Forget the path, the band and the failure counter."""
        self._path = None
        self._band = self._dts = None
        self._fail_cycles = 0
        self.last_debug = None

    def prepare_retry(self) -> None:
        """Start the failure count over and keep the band (see ``DwaController.prepare_retry``)."""
        self._fail_cycles = 0

    @property
    def goal(self) -> Pose2D | None:
        return None if self._path is None else Pose2D.from_array(self._path[-1])

    def _local_path(self, pose: Pose2D, costmap: Costmap) -> np.ndarray:
        """The path from its point nearest the robot to ``max_global_plan_lookahead_dist`` ahead,
        cut at the costmap's edge (searching near the previous progress so loops do not confuse)."""
        assert self._path is not None
        o = self.options
        s, p = self._s, self._path
        lo = int(np.searchsorted(s, s[self._progress] - 1.0, side="left"))
        hi = int(np.searchsorted(s, s[self._progress] + o.max_global_plan_lookahead_dist, side="right"))
        cand = p[lo:hi, :2] if hi > lo else p[lo : lo + 1, :2]
        nearest = lo + int(np.argmin(np.hypot(cand[:, 0] - pose.x, cand[:, 1] - pose.y)))
        self._progress = nearest
        end = int(np.searchsorted(s, s[nearest] + o.max_global_plan_lookahead_dist, side="right"))
        seg = p[nearest : max(end, nearest + 1)]
        rows, cols = costmap.geometry.world_to_cell(seg[:, :2])
        inside = costmap.geometry.in_bounds(rows, cols)
        if not inside.all():
            seg = seg[: max(int(np.argmin(inside)), 1)]
        return seg

    # -- band construction --------------------------------------------------------------------------
    def _band_size(self, length: float) -> int:
        o = self.options
        ds = min(o.dt_ref * o.max_vel_x, o.max_pose_separation)
        return int(np.clip(math.ceil(length / ds) + 1, o.min_samples, o.max_samples))

    def _segment_times(self, poses: np.ndarray, v0: float = -1.0, stop: bool = False) -> np.ndarray:
        """Time each segment needs (the band's initial dT): the speed limit, or with ``v0 >= 0`` an
        acceleration-limited profile through speed caps c_j at arc lengths s_j (``v0`` at the start,
        0 at the end when ``stop``, and for omni bases sqrt(a ds / (2 sin(dphi / 2))) where the
        direction of travel turns by dphi: the body-frame acceleration of going round the corner),
        v(s) = min(v_max, min_j sqrt(c_j^2 + 2 a |s - s_j|)); never faster than the turn rate
        allows. Starting the optimizer from a consistent timing saves most of its iterations."""
        o = self.options
        vmax = max(o.max_vel_x, o.max_vel_y) if o.holonomic else o.max_vel_x
        acc = min(o.acc_lim_x, o.acc_lim_y) if o.holonomic else o.acc_lim_x
        d = np.diff(poses[:, :2], axis=0)
        dist = np.hypot(d[:, 0], d[:, 1])
        turn = np.abs(wrap_angle(np.diff(poses[:, 2])))
        if v0 < 0:
            t = dist / vmax
        else:
            s = np.concatenate(([0.0], np.cumsum(dist)))
            caps_s, caps_v = [np.array([0.0])], [np.array([min(v0, vmax)])]
            if stop:
                caps_s.append(s[-1:])
                caps_v.append(np.zeros(1))
            if o.holonomic and len(dist) > 1:
                heading = np.arctan2(d[:, 1], d[:, 0])
                bend = np.abs(wrap_angle(np.diff(heading)))
                moving = (dist[:-1] > 1e-6) & (dist[1:] > 1e-6) & (bend > 1e-3)
                ds = 0.5 * (dist[:-1] + dist[1:])
                caps_s.append(s[1:-1][moving])
                caps_v.append(np.sqrt(0.9 * acc * ds[moving] / (2.0 * np.sin(0.5 * bend[moving]))))
            cs, cv = np.concatenate(caps_s), np.concatenate(caps_v)
            v = np.sqrt(cv[None, :] ** 2 + 2.0 * acc * np.abs(s[:, None] - cs[None, :])).min(axis=1)
            v = np.minimum(v, vmax)
            t = 2.0 * dist / np.maximum(v[:-1] + v[1:], 1e-3)
        return np.maximum(np.maximum(t, turn / o.max_vel_theta), 0.02)

    def _initial_band(
        self, pose: Pose2D, velocity: Twist2D, ref: np.ndarray, dfield: DistanceField, stop: bool
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """(poses, dts, warm): warm start from the previous band when it is still near the robot,
        else a band along the reference path."""
        o = self.options
        start = pose.as_array()
        goal = ref[-1]
        warm = False
        if self._band is not None and self._dts is not None:
            band, dts = self._band, self._dts
            dist = np.hypot(band[:, 0] - pose.x, band[:, 1] - pose.y)
            k = int(np.argmin(dist[: max(len(band) // 2, 1) + 1]))
            # TEB's force_reinit_new_goal_*: a local goal far from the old band's end means the
            # global path now takes another route; extending the old band to it would fold it.
            moved = math.hypot(band[-1, 0] - goal[0], band[-1, 1] - goal[1])
            turned = abs(float(wrap_angle(goal[2] - band[-1, 2])))
            if (
                dist[k] < 0.5
                and moved < o.force_reinit_new_goal_dist
                and turned < o.force_reinit_new_goal_angular
            ):
                warm = True
                t = np.concatenate(([0.0], np.cumsum(dts)))
                kept = band[k + 1 : -1]
                kept_t = t[k + 1 : -1] - t[k]
                # extend along the path from the previous band's end to the new goal
                old_end = band[-1, :2]
                j = int(np.argmin(np.hypot(ref[:, 0] - old_end[0], ref[:, 1] - old_end[1])))
                ext = ref[j:]
                xy = np.vstack((start[:2], kept[:, :2], ext[:, :2]))
                th = np.concatenate(([start[2]], kept[:, 2], ext[:, 2]))
                t_prev = kept_t[-1] if len(kept_t) else 0.0
                ext_t = t_prev + np.cumsum(
                    self._segment_times(np.vstack((kept[-1:] if len(kept) else start[None], ext)))
                )
                times = np.concatenate(([0.0], kept_t, ext_t))
        if warm:
            poses = self._resampled(start, goal, xy, th, times)
            if band_fold(poses, ref) > o.fold_reinit_dist:
                warm = False  # the kept part runs against the path: start again from the path
        if not warm:
            xy = np.vstack((start[:2], ref[:, :2]))
            th = np.concatenate(([start[2]], ref[:, 2]))
            times = np.concatenate(([0.0], np.cumsum(self._segment_times(np.column_stack((xy, th))))))
            poses = self._resampled(start, goal, xy, th, times)
        if not o.holonomic and not warm:
            chord = np.arctan2(*np.diff(poses[:, 1::-1], axis=0).T)
            poses[1:-1, 2] = chord[1:]
        self._push_out(poses, dfield)
        # Timing restarts from the measured speed every cycle: the previous band's first intervals
        # belong to poses now behind the robot, and carrying them over slows the band down.
        dts = self._segment_times(poses, math.hypot(velocity.vx, velocity.vy), stop)
        return poses, dts, warm

    def _resampled(
        self, start: np.ndarray, goal: np.ndarray, xy: np.ndarray, th: np.ndarray, times: np.ndarray
    ) -> np.ndarray:
        """The polyline (xy, th) resampled to the band's size, pinned to ``start`` and ``goal``."""
        length = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
        poses, _ = _resample(xy, th, times, self._band_size(length))
        poses[0] = start
        poses[-1, :2] = goal[:2]
        poses[-1, 2] = poses[-2, 2] + wrap_angle(goal[2] - poses[-2, 2])
        return poses

    def _push_out(self, poses: np.ndarray, dfield: DistanceField) -> None:
        """Homotopy seed: move interior poses within ``min_obstacle_dist`` of an obstacle sideways
        (along the band's normal) to the nearest offset with that clearance, every run of such poses
        to the same side, the side with the smaller detour (left on a tie). In place. Pushing the
        near-miss poses too, not only colliding ones, starts the optimizer out of the obstacle
        penalty's steep part.

        A pose only moves away from what it is near, never through it: an offset counts only if
        the clearance on the way there never drops below the pose's own (:func:`_reachable`).
        Searching past that let a pose beside a table leg land on the leg's far side, so the band
        zigzagged round the leg and every cycle's band collided (apartment 8, world 679961800).
        When neither side reaches the clearance for the whole run (a pose between two legs closer
        than the band's clearance), each pose of it moves to the clearest point it can reach."""
        o = self.options
        need = self._radius + o.min_obstacle_dist
        inner = poses[1:-1, :2]
        if len(inner) == 0:
            return
        here = dfield(inner)
        blocked = here < need
        if not blocked.any():
            return
        tangent = np.gradient(poses[:, :2], axis=0)[1:-1]
        tangent /= np.maximum(np.hypot(*tangent.T), 1e-9)[:, None]
        normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
        offsets = np.arange(1, 51) * 0.02  # up to 1 m
        slack = 0.25 * dfield.geometry.resolution  # the bilinear field's ripple
        idx = np.flatnonzero(blocked)
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        for run in runs:
            best = None
            reach: list[tuple[float, np.ndarray]] = []
            for side in (1.0, -1.0):
                cand = inner[run, None, :] + side * offsets[None, :, None] * normal[run, None, :]
                clear = dfield(cand.reshape(-1, 2)).reshape(len(run), len(offsets))
                clear = np.where(_reachable(clear, here[run] - slack), clear, -np.inf)
                reach.append((side, clear))
                ok = clear >= need
                if not ok.any(axis=1).all():
                    continue
                first = offsets[np.argmax(ok, axis=1)]
                if best is None or first.max() < best[1].max() - 1e-9:
                    best = (side, first)
            if best is not None:
                side, first = best
                shift = side * first
            else:  # no side clears the whole run: each pose to the clearest point it can reach
                clear = np.hstack([here[run, None]] + [c for _, c in reach])
                signed = np.concatenate(([0.0], *(side * offsets for side, _ in reach)))
                shift = signed[np.argmax(clear, axis=1)]
            poses[1:-1][run, :2] = inner[run] + shift[:, None] * normal[run]
        if not self.options.holonomic:
            chord = np.arctan2(*np.diff(poses[:, 1::-1], axis=0).T)
            poses[1:-1, 2] = poses[1:-1, 2] + wrap_angle(chord[1:] - poses[1:-1, 2])

    # -- optimization ---------------------------------------------------------------------------------
    def optimize(
        self,
        poses: np.ndarray,
        dts: np.ndarray,
        ref: np.ndarray,
        dfield: DistanceField,
        v0: np.ndarray,
        goal_acc: bool,
    ) -> tuple[np.ndarray, np.ndarray, SolveResult]:
        """Optimize a band with fixed end poses with ``options.solver``; returns (poses, dts, result)."""
        o = self.options
        n = len(poses)
        ends = np.stack((poses[0], poses[-1]))
        ref_xy = ref[:, :2] if len(ref) > 1 else np.vstack((ref[:1, :2], ref[:1, :2]))
        seg_a, seg_b = ref_xy[:-1], ref_xy[1:]
        near = _nearest_segments(poses[1:-1, :2], seg_a, seg_b)
        cand = np.clip(near[:, None] + np.arange(-1, 2)[None, :], 0, len(seg_a) - 1)  # (m, 3)
        problem = BandProblem(
            ends, seg_a[cand], seg_b[cand], dfield.sample, v0, goal_acc, self._walkers_at(dts), PERSON_RADIUS
        )
        key = (n, goal_acc)
        if key not in self._structures:
            self._structures[key] = BandStructure(n, o, goal_acc)
        st = self._structures[key]

        def fn(z: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
            return evaluate(z, problem, o, st, self._radius)

        budget = o.no_inner_iterations * o.no_outer_iterations
        z0 = pack(poses, dts)
        if o.solver == "scipy":
            res = solve_scipy(z0, fn, st, budget, o.solver_ftol)
        else:
            res = solve_lm_banded(z0, fn, st, budget, o.solver_ftol)
        out, out_dts = unpack(res.z, ends)
        out[:, 2] = wrap_angle(out[:, 2])
        return out, out_dts, res

    # -- control ----------------------------------------------------------------------------------------
    def _choose_goal(self, local: np.ndarray, dfield: DistanceField) -> np.ndarray:
        """The local path cut at its last point the footprint fits at (a goal inside an obstacle
        cannot be reached; the next cycles move it past the obstacle)."""
        if len(local) <= 1:
            return local
        ok = dfield(local[:, :2]) >= self._radius
        if ok[-1] or not ok.any():
            return local
        last_ok = len(ok) - 1 - int(np.argmax(ok[::-1]))
        return local[: last_ok + 1]

    def compute(self, pose: Pose2D, velocity: Twist2D, costmap: Costmap) -> tuple[Twist2D, TebDebug]:
        """One control cycle: optimize the band and return its first command.

        Raises ``NoValidControl`` when the optimized band's first poses collide (the caller should
        stop the robot), ``PatienceExceeded`` once that has lasted longer than ``failure_tolerance``.
        """
        if self._path is None:
            raise ControllerError("compute called before set_path")
        if not (pose.is_finite() and velocity.is_finite()):
            raise ControllerError("pose and velocity must be finite")
        o = self.options
        dfield = DistanceField(costmap, o.unknown_is_lethal)
        goal = self._path[-1]
        if pose.distance_to(Pose2D.from_array(goal)) <= o.xy_goal_tolerance:
            return self._rotate_to_goal(pose, goal, costmap)
        local = self._choose_goal(self._local_path(pose, costmap), dfield)
        at_final = bool(np.allclose(local[-1], goal))
        stop = at_final and not o.free_goal_vel
        poses, dts, warm = self._initial_band(pose, velocity, local, dfield, stop)
        v0 = velocity.as_array()
        t0 = time.perf_counter()
        try:
            poses, dts, res = self.optimize(poses, dts, local, dfield, v0, stop)
            if warm and band_fold(poses, local) > o.fold_reinit_dist:
                # The warm start led the optimizer into a band that doubles back (its first
                # command would turn the robot round): optimize once more from the path.
                self._band = self._dts = None
                poses, dts, warm = self._initial_band(pose, velocity, local, dfield, stop)
                poses, dts, res = self.optimize(poses, dts, local, dfield, v0, stop)
        except ValueError as exc:  # non-finite residuals: a degenerate band
            self._band = self._dts = None
            return self._fail(f"band optimization failed: {exc}", poses, dts, local, warm)
        elapsed = time.perf_counter() - t0
        self._band, self._dts = poses, dts
        clearance = float(np.min(dfield(poses[:, :2])))
        debug = TebDebug(
            band=poses,
            dts=dts,
            local_goal=local[-1].copy(),
            warm_started=warm,
            nfev=int(res.nfev),
            njev=int(res.njev or 0),
            cost=float(res.cost),
            solve_time=elapsed,
            min_clearance=clearance,
            reference=local,
        )
        self.last_debug = debug
        k = min(o.feasibility_check_no_poses, len(poses) - 1)
        if k > 0:
            # the footprint swept between the poses, not only at them: a turn's corners
            hit = self._swept_collisions(costmap, poses[: k + 1])
            if hit >= 0:
                self._band = self._dts = None  # re-seed next cycle
                return self._fail(f"band pose {hit} collides", poses, dts, local, warm, debug)
            meet = self._walker_conflict(poses[: k + 1], dts[:k])
            if meet >= 0:
                # The band would meet a walker: stand and let it pass (re-seeded next cycle). A
                # wait is a command, not a failure: counted as one, a walker crossing for 0.3 s
                # spent the controller's patience and started a recovery (apartment 16, world
                # 361274677: six of them, then the goal failed). A wait that lasts is the
                # navigator's to end (its stall and progress checks).
                self._band = self._dts = None
                self._fail_cycles = 0
                debug = replace(debug, waiting_for=f"band pose {meet} meets a walker")
                self.last_debug = debug
                return Twist2D(), debug
        self._fail_cycles = 0
        vx, vy, wz = (float(v) for v in debug.velocities[0])
        if not o.holonomic:
            vy = 0.0
        # The first segment's mean velocity lies up to dT_0 ahead; reaching it within one control
        # period may exceed the acceleration limit, so it is limited like Nav2's velocity_smoother.
        dv = o.control_period * np.array([o.acc_lim_x, o.acc_lim_y if o.holonomic else 0.0, o.acc_lim_theta])
        lo = np.maximum(v0 - dv, [-o.max_vel_x_backwards, -o.max_vel_y, -o.max_vel_theta])
        hi = np.minimum(v0 + dv, [o.max_vel_x, o.max_vel_y, o.max_vel_theta])
        out = np.clip([vx, vy, wz], np.minimum(lo, hi), np.maximum(lo, hi))
        cmd = Twist2D(float(out[0]), float(out[1]) if o.holonomic else 0.0, float(out[2]))
        return cmd, debug

    def _fail(
        self,
        why: str,
        poses: np.ndarray,
        dts: np.ndarray,
        local: np.ndarray,
        warm: bool,
        debug: TebDebug | None = None,
    ) -> tuple[Twist2D, TebDebug]:
        self.last_debug = debug or TebDebug(
            band=poses, dts=dts, local_goal=local[-1].copy(), warm_started=warm
        )
        self._fail_cycles += 1
        if self._fail_cycles * self.options.control_period > self.options.failure_tolerance:
            raise PatienceExceeded(f"no feasible band for {self._fail_cycles} cycles ({why})", {"teb": 1})
        raise NoValidControl(why, {"teb": 1})

    def _walker_conflict(self, poses: np.ndarray, dts: np.ndarray) -> int:
        """Index (1-based, into ``poses``) of the first pose whose circumscribed circle takes in a
        walker's predicted body at that pose's time nearer than standing at ``poses[0]`` would, or
        -1. Only moving towards a walker counts: a walker already beside the robot (the
        simulator's and many people's way is to wait for it) does not pin a robot that drives
        away from it, as DWA's escape rule lets a footprint on a wall turn or back away."""
        if not (self.options.include_dynamic_obstacles and len(self._walkers) and len(dts)):
            return -1
        at = self._predict_walkers(np.cumsum(dts))  # (k, W, 2)
        gap = np.hypot(*(at - poses[1:, None, :2]).transpose(2, 0, 1))  # (k, W)
        stand = np.hypot(*(at - poses[0, None, None, :2]).transpose(2, 0, 1))
        closer = (gap < self._radius + PERSON_RADIUS) & (gap < stand - 1e-3)
        bad = np.flatnonzero(closer.any(axis=1))
        return int(bad[0]) + 1 if bad.size else -1

    def _swept_collisions(self, costmap: Costmap, poses: np.ndarray) -> int:
        """Index (1-based, into ``poses``) of the first segment end whose swept footprint (from the
        previous pose) hits a lethal cell centre, or -1 when the whole sweep is free."""
        step = self._sweep_step(costmap)
        sweeps = [swept_poses(poses[i - 1 : i + 1], self._radius, step)[1:] for i in range(1, len(poses))]
        if not sweeps:
            return -1
        hit = np.flatnonzero(self._collisions(costmap, np.vstack(sweeps)))
        if hit.size == 0:
            return -1
        # the segment holding the first colliding sample (one check for all of them)
        return int(np.searchsorted(np.cumsum([len(sw) for sw in sweeps]), hit[0], side="right")) + 1

    @staticmethod
    def _sweep_step(costmap: Costmap) -> float:
        """Largest motion (m) of a footprint point between two checked poses of a sweep."""
        return 0.5 * costmap.geometry.resolution

    def _collisions(self, costmap: Costmap, poses: np.ndarray) -> np.ndarray:
        """:func:`centre_collisions` of ``poses`` with this controller's footprint."""
        o = self.options
        round_radius = None if o.footprint else o.robot_radius
        return centre_collisions(costmap, poses, self._polygon, round_radius, o.unknown_is_lethal)

    def _rotate_to_goal(self, pose: Pose2D, goal: np.ndarray, costmap: Costmap) -> tuple[Twist2D, TebDebug]:
        """Inside ``xy_goal_tolerance``: stop translating and turn to the goal's heading, the short
        way round if its swept footprint is free, else the long way; raises ``NoValidControl`` when
        both would sweep a corner through an obstacle (a rectangular base beside a post)."""
        o = self.options
        err = float(wrap_angle(goal[2] - pose.theta))
        wz = 0.0
        if abs(err) > o.yaw_goal_tolerance:
            start = pose.as_array()
            step = self._sweep_step(costmap)
            for turn in (err, err - math.copysign(2.0 * math.pi, err)):
                if not self._collisions(costmap, swept_turn(start, turn, self._radius, step)[1:]).any():
                    wz = float(np.clip(1.5 * turn, -o.max_vel_theta, o.max_vel_theta))
                    break
            else:
                why = "turning to the goal heading would sweep the footprint into an obstacle"
                return self._fail(why, np.vstack((start, goal)), np.array([0.1]), goal[None, :], False)
        band = np.vstack((pose.as_array(), goal))
        debug = TebDebug(
            band=band, dts=np.array([max(abs(err) / o.max_vel_theta, 0.01)]), local_goal=goal.copy()
        )
        self.last_debug = debug
        self._fail_cycles = 0
        return Twist2D(0.0, 0.0, wz), debug


__all__ = [
    "DistanceField",
    "TebController",
    "TebDebug",
    "band_fold",
    "centre_collisions",
    "segment_velocities",
]
