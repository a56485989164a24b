"""Dynamic Window Approach local controller, organised like Nav2's DWB.

Fox, Burgard & Thrun, "The Dynamic Window Approach to Collision Avoidance", IEEE Robotics &
Automation Magazine 4(1), 1997 — as source A uses it through Nav2's ``dwb_core``: each control
cycle samples the velocities reachable within one period (``trajectory.generate``), simulates them
as arcs for ``sim_time``, lets every critic score all of them (``critics``), drops the illegal ones
and sends the cheapest. Why DWB's shape: critics are small, separately weighted and testable, and
the same loop runs Fox's original objective (``FOX_CRITICS``) or DWB's path-following one.

Per cycle the controller also prunes the global path to the part ahead of the robot (its end is the
local goal) and latches "inside the goal window" so RotateToGoal can turn in place at the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from nav.control.critics import Critic, CriticContext, make_critics, polyline_length
from nav.control.errors import ControllerError, InvalidPath, NoValidControl, PatienceExceeded
from nav.control.footprint import CostWindow, FootprintModel
from nav.control.options import DwaOptions
from nav.control.trajectory import TrajectorySet, generate
from nav.types import ZERO_TWIST, Costmap, Path, Pose2D, Twist2D


@njit(cache=True, nogil=True)
def _prune(
    path: np.ndarray,
    s: np.ndarray,
    progress: int,
    x: float,
    y: float,
    back: float,
    ahead: float,
    ox: float,
    oy: float,
    res: float,
    width: int,
    height: int,
) -> tuple[int, int]:
    """``DwaController._local_path`` in one compiled pass: the path index nearest (x, y) among
    those from ``back`` m behind to ``ahead`` m past ``progress`` (``back`` < 0: all of them), and
    the end (exclusive) of the segment ``ahead`` m from it, cut before the first vertex off the
    costmap (``res`` > 0: an axis-aligned costmap with origin (ox, oy)). Same rules (searchsorted
    sides, first-minimum ties) as the numpy code it replaces."""
    n = path.shape[0]
    if back >= 0.0:
        lo = np.searchsorted(s, s[progress] - back, side="left")
        hi = np.searchsorted(s, s[progress] + ahead, side="right")
    else:
        lo, hi = 0, n
    if hi <= lo:
        hi = lo + 1
    nearest, best = lo, np.inf
    for i in range(lo, hi):
        d = math.hypot(path[i, 0] - x, path[i, 1] - y)
        if d < best:
            nearest, best = i, d
    stop = max(np.searchsorted(s, s[nearest] + ahead, side="right"), nearest + 1)
    if res > 0.0:
        for i in range(nearest, stop):
            c = math.floor((path[i, 0] - ox) / res)
            r = math.floor((path[i, 1] - oy) / res)
            if not (0 <= r < height and 0 <= c < width):
                return nearest, max(i, nearest + 1)
    return nearest, stop


@dataclass(frozen=True)
class DwaDebug:
    """What one cycle considered, for the 3D view and for tests."""

    trajectories: np.ndarray  # (K, T, 2) float32 sampled trajectories (map frame)
    twists: np.ndarray  # (K, 3) sampled (vx, vy, wz)
    costs: np.ndarray  # (K,) total weighted cost, +inf where illegal
    chosen: int  # index of the command sent, -1 when none was legal
    critic_costs: dict[str, np.ndarray] = field(default_factory=dict)  # weighted, per critic
    rejections: dict[str, int] = field(default_factory=dict)  # illegal trajectories per critic
    local_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    in_goal_window: bool = False

    @property
    def legal(self) -> np.ndarray:
        return np.isfinite(self.costs)

    @property
    def chosen_trajectory(self) -> np.ndarray | None:
        return None if self.chosen < 0 else self.trajectories[self.chosen]


class DwaController:
    """DWA/DWB controller: ``set_path`` once per (re)plan, ``compute`` once per control cycle.

    Stateful on purpose (like DWB): the path progress index, the goal-window latch, the
    Oscillation/RotateToGoal critics' memory and the failure counter behind ``PatienceExceeded``.
    """

    def __init__(self, options: DwaOptions | None = None) -> None:
        self.options = options or DwaOptions()
        self.critics: list[Critic] = make_critics(self.options)
        self._polygon = self._footprint_polygon()
        self._footprints: dict[float, FootprintModel] = {}
        self._path: np.ndarray | None = None
        self._s: np.ndarray = np.zeros(0)  # cumulative arc length along the path
        self._progress = 0
        self._in_window = False
        self._fail_cycles = 0
        self.last_debug: DwaDebug | None = None
        self._local_span = (0, 0)  # path slice of the last local path
        self._length_key: tuple[int, ...] | None = None  # (slice, size) of _length; None after set_path
        self._length = 0.0

    # -- path -------------------------------------------------------------------------------------
    def set_path(self, path: Path) -> None:
        """Follow ``path`` (map frame). Critic memories are kept when the goal is unchanged (a
        periodic replan), reset when it moved."""
        poses = np.asarray(path.poses, dtype=float)
        if poses.ndim != 2 or poses.shape[0] == 0 or poses.shape[1] != 3 or not np.all(np.isfinite(poses)):
            raise InvalidPath("path must be a non-empty finite (N, 3) array")
        same_goal = self._path is not None and np.allclose(self._path[-1], poses[-1], atol=1e-6)
        self._path = poses
        self._length_key = None
        seg = np.hypot(*np.diff(poses[:, :2], axis=0).T) if len(poses) > 1 else np.zeros(0)
        self._s = np.concatenate(([0.0], np.cumsum(seg)))
        self._progress = 0
        if not same_goal:
            self._in_window = False
            for c in self.critics:
                c.reset()

    def reset(self) -> None:
        """Forget the path and all per-goal state."""
        self._path = None
        self._length_key = None
        self._in_window = False
        self._fail_cycles = 0
        self.last_debug = None
        for c in self.critics:
            c.reset()

    def prepare_retry(self) -> None:
        """After a recovery the navigator retries the same goal (Nav2 sends a fresh FollowPath):
        start the failure count over (``failure_tolerance`` afresh: a count left at its limit raised
        ``PatienceExceeded`` again on the very next cycle) and re-arm the goal window (a back-up
        recovery may have taken the robot out of it: latched, the critics only turned the robot to
        the goal's heading 0.5 m away). The critics' memories (oscillation, ...) stay: clearing
        them let the robot dither between chair legs."""
        self._fail_cycles = 0
        self._in_window = False

    @property
    def goal(self) -> Pose2D | None:
        return None if self._path is None else Pose2D.from_array(self._path[-1])

    def _footprint_polygon(self) -> np.ndarray:
        o = self.options
        if o.footprint:
            return np.asarray(o.footprint, dtype=float)
        a = np.linspace(0.0, 2 * math.pi, 32, endpoint=False)
        return np.column_stack((np.cos(a), np.sin(a))) * o.robot_radius

    def _footprint_model(self, resolution: float) -> FootprintModel:
        model = self._footprints.get(resolution)
        if model is None:
            o = self.options
            model = FootprintModel.build(
                self._polygon, resolution, o.footprint_orientation_bins, not o.footprint
            )
            self._footprints[resolution] = model
        return model

    def _local_path(self, pose: Pose2D, costmap: Costmap) -> np.ndarray:
        """The path from its point closest to the robot to ``forward_prune_distance`` ahead (cut at
        the costmap's edge), searching only near the previous progress so loops do not confuse it."""
        assert self._path is not None
        o, g = self.options, costmap.geometry
        back = o.prune_distance if o.prune_plan else -1.0  # < 0: search the whole path
        if g.origin.theta == 0.0:  # the usual axis-aligned costmap: bounds tested in the kernel
            box = (g.origin.x, g.origin.y, g.resolution, g.width, g.height)
        else:
            box = (0.0, 0.0, 0.0, 0, 0)  # resolution 0: no bounds test; done below
        nearest, stop = _prune(
            self._path, self._s, self._progress, pose.x, pose.y, back, o.forward_prune_distance, *box
        )
        self._progress = nearest
        self._local_span = (nearest, stop)
        seg = self._path[nearest:stop]
        if box[2] == 0.0:
            rows, cols = g.world_to_cell(seg[:, :2])
            inside = g.in_bounds(rows, cols)
            if not inside.all():
                seg = seg[: max(int(np.argmin(inside)), 1)]
        return seg

    # -- control ----------------------------------------------------------------------------------
    def compute(self, pose: Pose2D, velocity: Twist2D, costmap: Costmap) -> tuple[Twist2D, DwaDebug]:
        """One control cycle: the best legal twist and what was considered.

        Raises ``NoValidControl`` when every trajectory is illegal (the caller should stop the
        robot), ``PatienceExceeded`` once that has lasted longer than ``failure_tolerance``.
        """
        if self._path is None:
            raise ControllerError("compute called before set_path")
        if not (pose.is_finite() and velocity.is_finite()):
            raise ControllerError("pose and velocity must be finite")
        o = self.options
        goal = Pose2D.from_array(self._path[-1])
        self._in_window = self._in_window or pose.distance_to(goal) <= o.xy_goal_tolerance
        local_path = self._local_path(pose, costmap)
        # the local path moves on only every few cycles (one path point per ~4 at cruise speed):
        # its length is kept while the same slice of the same path is used
        span = (*self._local_span, len(local_path))
        if self._length_key != span:
            self._length_key, self._length = span, polyline_length(local_path)
        trajs: TrajectorySet = generate(o, pose, velocity)
        window = CostWindow.around(costmap, trajs.poses, o.circumscribed_radius, o.unknown_is_lethal)
        ctx = CriticContext(
            options=o,
            pose=pose,
            velocity=velocity,
            trajectories=trajs,
            window=window,
            footprint=self._footprint_model(costmap.geometry.resolution),
            local_path=local_path,
            goal=goal,
            in_goal_window=self._in_window,
            local_path_length=self._length,
        )
        k = len(trajs)
        total = np.zeros(k)
        illegal = np.zeros(k, dtype=bool)
        per_critic: dict[str, np.ndarray] = {}
        rejections: dict[str, int] = {}
        for critic in self.critics:
            cost, bad = critic.score(ctx)
            w = critic.weight(ctx)
            weighted = w * cost if w != 0.0 else np.zeros(k)
            per_critic[critic.name] = weighted
            total += weighted
            if bad.any():  # most critics reject nothing: skip the count
                n_bad = int(np.count_nonzero(bad & ~illegal))
                if n_bad:
                    rejections[critic.name] = n_bad
                illegal |= bad
        costs = np.where(illegal, np.inf, total)
        chosen = -1 if illegal.all() else int(np.argmin(costs))
        xy32 = trajs.xy32 if trajs.xy32 is not None else trajs.poses[..., :2].astype(np.float32)
        debug = DwaDebug(
            trajectories=xy32,
            twists=trajs.twists,
            costs=costs,
            chosen=chosen,
            critic_costs=per_critic,
            rejections=rejections,
            local_path=local_path,
            in_goal_window=self._in_window,
        )
        self.last_debug = debug
        if chosen < 0:
            for critic in self.critics:  # the robot is stopped this cycle: stateful critics see it
                critic.debrief(ZERO_TWIST, pose)
            self._fail_cycles += 1
            why = ", ".join(f"{n}: {c}" for n, c in rejections.items()) or "no samples"
            if self._fail_cycles * o.sim_period > o.failure_tolerance:
                raise PatienceExceeded(
                    f"no valid trajectory for {self._fail_cycles} cycles ({why})", rejections
                )
            raise NoValidControl(f"all {k} trajectories rejected ({why})", rejections)
        self._fail_cycles = 0
        vx, vy, wz = (float(v) for v in trajs.twists[chosen])
        cmd = Twist2D(vx, vy, wz)
        for critic in self.critics:
            critic.debrief(cmd, pose)
        return cmd, debug
