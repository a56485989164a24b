"""Trajectory critics, each scoring all K trajectories of a cycle in a few numpy expressions.

Organised like Nav2 DWB's ``dwb_critics`` (Marder-Eppstein's ``base_local_planner`` lineage): a
critic returns a cost per trajectory (lower is better) and a mask of trajectories it declares
illegal (DWB's ``IllegalTrajectoryException``); the controller minimises sum(scale * cost) over the
legal ones. Distances are in costmap cells, as in DWB, so its default scales keep their balance.

Differences from DWB, and why:
- PathDist measures exact Euclidean distance to the path's segments and GoalDist / GoalAlign the
  distance to the local goal *along the path* (nearest path point + remaining length; a compiled
  point-to-polyline loop), instead of DWB's breadth-first Manhattan wavefront through the grid: no
  per-cell queue, and like the wavefront it goes round the wall ends the path bends round (a
  straight line to a local goal behind a wall parks the robot at the wall).
- The alignment and distance critics are silenced once the robot is inside ``xy_goal_tolerance``
  (DWB silences PathAlign/GoalAlign only within ``forward_point_distance``); otherwise they fight
  RotateToGoal over the heading, the usual cause of DWB's oscillation at the goal.

Fox et al. 1997's objective terms are critics too (FoxHeading, FoxClearance, FoxVelocity), as costs
in [0, 1]: maximising alpha*heading + beta*dist + gamma*vel equals minimising these weighted costs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import numpy as np
from scipy.spatial import cKDTree

from nav.control.footprint import CostWindow, FootprintModel
from nav.control.footprint import _inside_polygon as _inside
from nav.control.geometry import project_poses
from nav.control.options import DwaOptions
from nav.control.trajectory import TrajectorySet
from nav.types import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, Pose2D, Twist2D, wrap_angle


@dataclass
class CriticContext:
    """Everything the critics of one cycle read. Costs and clearances are computed on first use."""

    options: DwaOptions
    pose: Pose2D
    velocity: Twist2D
    trajectories: TrajectorySet
    window: CostWindow
    footprint: FootprintModel
    local_path: np.ndarray  # (M, 3) path ahead of the robot; its last pose is the local goal
    goal: Pose2D  # last pose of the whole path
    in_goal_window: bool  # latched: the robot has come within xy_goal_tolerance of the goal
    local_path_length: float | None = None  # polyline_length(local_path) if the caller has it
    resolution: float = field(init=False)
    _projections: dict[float, tuple[np.ndarray, ...]] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.resolution = self.window.geometry.resolution

    @property
    def future(self) -> np.ndarray:
        """(K, T-1, 3) simulated poses after the start pose (the start is where the robot is
        already; excluding it lets a robot whose centre sits in the inscribed zone drive out)."""
        return self.trajectories.poses[:, 1:, :]

    @property
    def last(self) -> np.ndarray:
        return self.trajectories.poses[:, -1, :]

    @property
    def local_goal(self) -> np.ndarray:
        return self.local_path[-1]

    @cached_property
    def centre_costs(self) -> np.ndarray:
        return self.window.centre_costs(self.future)

    def _projection(self, forward: float) -> tuple[np.ndarray, ...]:
        """``project_onto_polyline`` of the trajectories' last poses moved ``forward`` m along
        their heading (0: the last poses), once per cycle for all critics asking for it."""
        key = round(forward, 9)
        hit = self._projections.get(key)
        if hit is None:
            hit = self._projections[key] = project_poses(self.last, forward, self.local_path)
        return hit

    def path_distance(self, forward: float = 0.0) -> np.ndarray:
        """Exact distance (m) from the (forward points of the) trajectory ends to the local path."""
        return self._projection(forward)[0]

    @cached_property
    def path_length(self) -> float:
        if self.local_path_length is not None:
            return self.local_path_length
        return polyline_length(self.local_path)

    def distance_to_go(self, forward: float = 0.0) -> np.ndarray:
        """Distance (m) from the (forward points of the) trajectory ends to the local goal *along
        the path*: to the nearest path point, then the path's remaining length. DWB gets the same
        effect from a wavefront through the grid (it goes round walls); a straight line to a local
        goal behind a wall end would pull the robot into the corner the path bends round."""
        _, d, s = self._projection(forward)
        return d + (self.path_length - s)

    @cached_property
    def footprint_lethal(self) -> np.ndarray:
        """(K, T-1) whether the footprint touches a lethal cell at each future pose."""
        return self.window.footprint_lethal(self.future, self.footprint)

    @cached_property
    def last_footprint_costs(self) -> np.ndarray:
        """(K,) max cost under the footprint at each trajectory's last pose."""
        return self.window.footprint_costs(self.last, self.footprint)

    @cached_property
    def clearance(self) -> np.ndarray:
        return self.window.clearance(self.trajectories.poses)

    def forward_points(self, poses: np.ndarray, distance: float) -> np.ndarray:
        return poses[:, :2] + distance * np.column_stack((np.cos(poses[:, 2]), np.sin(poses[:, 2])))

    def robot_to_goal(self) -> float:
        return math.hypot(self.pose.x - self.goal.x, self.pose.y - self.goal.y)


def polyline_length(path: np.ndarray) -> float:
    """Length (m) of the polyline through the (M, 2+) path's points."""
    seg = np.diff(path[:, :2], axis=0)
    return float(np.hypot(seg[:, 0], seg[:, 1]).sum())


class Critic(Protocol):
    """One DWB critic. ``score`` returns (cost (K,), illegal (K,) bool)."""

    name: str

    def weight(self, ctx: CriticContext) -> float: ...
    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]: ...
    def debrief(self, cmd: Twist2D, pose: Pose2D) -> None: ...
    def reset(self) -> None: ...


class _Stateless:
    name = ""
    scale = 1.0

    def __init__(self, options: DwaOptions) -> None:
        self.options = options

    def weight(self, ctx: CriticContext) -> float:
        return self.scale

    def debrief(self, cmd: Twist2D, pose: Pose2D) -> None:
        return None

    def reset(self) -> None:
        return None

    @staticmethod
    def _legal(k: int) -> np.ndarray:
        return np.zeros(k, dtype=bool)


class BaseObstacle(_Stateless):
    """Cost of the cell under the robot's centre (last pose, or summed); a centre in a lethal,
    inscribed (or unknown-as-lethal) cell makes the trajectory illegal. DWB ``BaseObstacleCritic``."""

    name = "BaseObstacle"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.base_obstacle_scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        c = ctx.centre_costs.astype(np.float64)
        illegal = np.any(c >= INSCRIBED_INFLATED_OBSTACLE, axis=1)
        cost = c.sum(axis=1) if self.options.base_obstacle_sum_scores else c[:, -1]
        return cost, illegal


class ObstacleFootprint(_Stateless):
    """Max cost under the footprint (last pose); a footprint touching a lethal cell anywhere along
    the trajectory makes it illegal. DWB ``ObstacleFootprintCritic``.

    Escape (navdeck): when the footprint already overlaps a lethal cell where the robot stands
    (a 4 cm chair leg marked a cell too close, localisation jitter against a wall), DWB rejects
    every trajectory and the robot is stuck for good. Then a trajectory is legal if it never
    reaches deeper into an obstacle than now: the signed depth of the nearby lethal cells' centres
    (how far the deepest one lies inside the polygon, in m; negative: minus the nearest one's
    distance outside it) never exceeds the start's. Turning in place or backing out of the
    contact is allowed, pushing on is not. This includes a footprint that touches only by the
    raster's margin (a lethal cell its outline crosses, the cell's centre outside): it used to keep
    DWB's strict rule, which rejects every trajectory there too, since each one's first pose still
    touches (apartment goal 11: a wall end's mark 0.16 m from the centre of the skid robot, stuck
    until the navigator gave up)."""

    name = "ObstacleFootprint"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.obstacle_footprint_scale
        self.escaping = False  # whether the last score used the escape rule

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        cost = ctx.last_footprint_costs.astype(np.float64)
        hit = ctx.footprint_lethal
        start = ctx.trajectories.poses[:1, :1]  # every trajectory starts at the robot's pose
        touching = bool(hit.any()) and bool(ctx.window.footprint_lethal(start, ctx.footprint)[0, 0])
        self.escaping = touching
        if not touching:
            return cost, np.any(hit, axis=1)
        depth = self._depth(ctx)  # (K, T) signed
        deeper = depth[:, 1:] > depth[:, :1] + 1e-9
        return cost, np.any(deeper, axis=1)

    def _depth(self, ctx: CriticContext) -> np.ndarray:
        """(K, T) signed depth (m) of the lethal cells near the robot in the footprint polygon at
        each pose: the largest distance from a covered cell's centre to the outline, or when no
        centre is covered minus the smallest distance from a centre to the outline (-inf: none).

        Only pose-cell pairs closer than the circumscribed radius + one cell are evaluated (a KD-tree
        pairs them): a cell farther off lies over a cell outside the outline, so its value is below
        the start's (which touches) and cannot make a pose deeper. Evaluating every pose against
        every cell in reach was (K * T * L, 16, 2): 6.5 GB for an omni robot in a greenhouse."""
        w, poses = ctx.window, ctx.trajectories.poses
        reach = ctx.footprint.circumscribed + float(np.abs(poses[..., :2] - poses[:1, :1, :2]).max())
        rr, cc = np.nonzero(w.costs >= LETHAL_OBSTACLE)
        cells = w.geometry.cell_to_world(rr, cc)
        near = np.hypot(cells[:, 0] - ctx.pose.x, cells[:, 1] - ctx.pose.y) <= reach + w.geometry.resolution
        cells = cells[near]
        depth = np.full(poses.shape[0] * poses.shape[1], -np.inf)
        if cells.shape[0] == 0:
            return depth.reshape(poses.shape[:2])
        flat = poses.reshape(-1, 3)
        pairs = cKDTree(flat[:, :2]).sparse_distance_matrix(
            cKDTree(cells),
            ctx.footprint.circumscribed + w.geometry.resolution,
            output_type="ndarray",
        )
        i, j = pairs["i"], pairs["j"]
        if i.size == 0:
            return depth.reshape(poses.shape[:2])
        # cell centres in their pose's frame: (P, 2)
        dx, dy = cells[j, 0] - flat[i, 0], cells[j, 1] - flat[i, 1]
        c, s = np.cos(flat[i, 2]), np.sin(flat[i, 2])
        pts = np.column_stack((c * dx + s * dy, -s * dx + c * dy))
        poly = self._polygon()
        a, b = poly, np.roll(poly, -1, axis=0)
        ab = b - a
        t = np.clip(((pts[:, None, :] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
        edge = np.hypot(*(a + t[..., None] * ab - pts[:, None, :]).transpose(2, 0, 1)).min(axis=1)
        np.maximum.at(depth, i, np.where(_inside(pts, poly), edge, -edge))
        return depth.reshape(poses.shape[:2])

    def _polygon(self) -> np.ndarray:
        o = self.options
        if o.footprint:
            return np.asarray(o.footprint, dtype=float)
        a = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
        return o.robot_radius * np.column_stack((np.cos(a), np.sin(a)))


class PathDist(_Stateless):
    """Distance (cells) from the trajectory's end to the path. DWB ``PathDistCritic``."""

    name = "PathDist"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.path_dist_scale

    def weight(self, ctx: CriticContext) -> float:
        return 0.0 if ctx.in_goal_window else self.scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        d = ctx.path_distance() / ctx.resolution
        return d, self._legal(d.shape[0])


class PathAlign(_Stateless):
    """Distance (cells) from a point ``forward_point_distance`` ahead of the trajectory's end to
    the path: rewards facing along the path. DWB ``PathAlignCritic``; off near the goal."""

    name = "PathAlign"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.path_align_scale
        self.forward = options.path_align_forward_point_distance

    def weight(self, ctx: CriticContext) -> float:
        if ctx.in_goal_window or ctx.robot_to_goal() <= self.forward:
            return 0.0
        return self.scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        d = ctx.path_distance(self.forward) / ctx.resolution
        return d, self._legal(d.shape[0])


class GoalDist(_Stateless):
    """Distance (cells) from the trajectory's end to the local goal (the end of the path segment
    the controller sees), measured along the path (``CriticContext.distance_to_go``). DWB
    ``GoalDistCritic``."""

    name = "GoalDist"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.goal_dist_scale

    def weight(self, ctx: CriticContext) -> float:
        return 0.0 if ctx.in_goal_window else self.scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        d = ctx.distance_to_go() / ctx.resolution
        return d, self._legal(d.shape[0])


class GoalAlign(_Stateless):
    """Distance (cells) from the forward point of the trajectory's end to the local goal, along
    the path like GoalDist: rewards facing the way the path goes. DWB ``GoalAlignCritic``; off near
    the goal."""

    name = "GoalAlign"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.goal_align_scale
        self.forward = options.goal_align_forward_point_distance

    def weight(self, ctx: CriticContext) -> float:
        if ctx.in_goal_window or ctx.robot_to_goal() <= self.forward:
            return 0.0
        return self.scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        d = ctx.distance_to_go(self.forward) / ctx.resolution
        return d, self._legal(d.shape[0])


class RotateToGoal(_Stateless):
    """Inside ``xy_goal_tolerance``: first slow down (speeding up is illegal, cost =
    slowing_factor * speed^2 + heading error), then, once stopped, only pure rotations (or, while the
    window cannot reach zero speed, the slowest samples) are legal and the cost is |yaw error| at the
    trajectory's end. DWB ``RotateToGoalCritic``."""

    name = "RotateToGoal"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.rotate_to_goal_scale
        self.rotating = False

    def reset(self) -> None:
        self.rotating = False

    def _yaw_error(self, ctx: CriticContext) -> np.ndarray:
        la = self.options.rotate_to_goal_lookahead_time
        tw = ctx.trajectories.twists
        end_yaw = ctx.pose.theta + tw[:, 2] * la if la >= 0 else ctx.last[:, 2]
        return np.abs(wrap_angle(ctx.goal.theta - end_yaw))

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        tw = ctx.trajectories.twists
        k = tw.shape[0]
        if not ctx.in_goal_window:
            return np.zeros(k), self._legal(k)
        cur_sq = ctx.velocity.vx**2 + ctx.velocity.vy**2
        self.rotating = self.rotating or cur_sq <= self.options.trans_stopped_velocity**2
        speed_sq = tw[:, 0] ** 2 + tw[:, 1] ** 2
        if not self.rotating:
            illegal = speed_sq >= cur_sq
            return speed_sq * self.options.rotate_to_goal_slowing_factor + self._yaw_error(ctx), illegal
        # DWB: any translation is illegal. When the dynamic window does not reach zero yet (a
        # fast robot entering the window), allow only the slowest reachable translation instead of
        # rejecting everything, so the robot brakes to a stop, then turns.
        illegal = speed_sq > speed_sq.min() + 1e-12
        return self._yaw_error(ctx), illegal


class PreferForward(_Stateless):
    """Backing up costs ``penalty``, and so does a forward sample slower than ``strafe_x`` that
    turns slower than ``strafe_theta`` (a base whose sensors look forwards); every other sample
    costs ``theta_scale * |w|`` (turning is not progress). DWB ``PreferForwardCritic``.

    navdeck's default penalty is automatic (``prefer_forward_penalty`` < 0): the most a reversing
    sample can gain over one horizon on the path and goal critics (GoalDist, GoalAlign, PathDist,
    PathAlign), so a goal behind the robot makes it turn round rather than reverse the whole way,
    while a robot whose forward and turning samples are illegal (nose in a dead end too narrow to
    turn in) still backs out. Off inside the goal window, where RotateToGoal alone decides. The
    strafe rule and the turn-round term are navdeck rules, explained where they are computed."""

    name = "PreferForward"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.prefer_forward_scale

    def weight(self, ctx: CriticContext) -> float:
        return 0.0 if ctx.in_goal_window else self.scale

    def penalty(self, resolution: float) -> float:
        o = self.options
        if o.prefer_forward_penalty >= 0.0:
            return o.prefer_forward_penalty
        reach_cells = abs(min(o.min_vel_x, 0.0)) * o.sim_time / resolution
        progress = o.goal_dist_scale + o.goal_align_scale + o.path_dist_scale + o.path_align_scale
        return progress * reach_cells / max(self.scale, 1e-9)

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        o = self.options
        tw = ctx.trajectories.twists
        vx, w = tw[:, 0], tw[:, 2]
        penalised = vx < 0.0
        v0 = ctx.velocity
        if v0.vx < o.prefer_forward_strafe_x and abs(v0.wz) < o.prefer_forward_strafe_theta:
            # DWB's strafe rule, only while the robot itself crawls or stands (a robot turning or
            # driving may slow through the band, or it could never brake a turn it no longer
            # wants); the fastest turn reachable each way this cycle counts as turning, since from
            # rest the window does not reach strafe_theta yet
            slow = (vx < o.prefer_forward_strafe_x) & (np.abs(w) < o.prefer_forward_strafe_theta)
            fastest = ((w == w.max()) & (w > 0.0)) | ((w == w.min()) & (w < 0.0))
            penalised |= slow & ~fastest
        cost = np.where(penalised, self.penalty(ctx.resolution), np.abs(w) * o.prefer_forward_theta_scale)
        return cost + self._turn_round(ctx), self._legal(cost.shape[0])

    def _turn_round(self, ctx: CriticContext) -> np.ndarray:
        """With the path behind the robot (its point ``sampling_distance`` ahead more than
        ``angle_threshold`` off the heading), the angle from each trajectory's end heading to that
        point, weighted to outweigh the most PathAlign + GoalAlign can charge for the turn (their
        forward points move at most twice their distance): facing away from its path is a local
        minimum of DWB's critics, which backing up used to escape (Nav2 answers it with the
        RotationShimController, MPPI with its PathAngle critic)."""
        o, k = self.options, len(ctx.trajectories)
        path = ctx.local_path
        seg = np.hypot(*np.diff(path[:, :2], axis=0).T)
        along = np.concatenate(([0.0], np.cumsum(seg)))
        target = path[min(int(np.searchsorted(along, o.prefer_forward_sampling_distance)), len(path) - 1)]
        bearing = math.atan2(target[1] - ctx.pose.y, target[0] - ctx.pose.x)
        if abs(float(wrap_angle(bearing - ctx.pose.theta))) <= o.prefer_forward_angle_threshold:
            return np.zeros(k)
        last = ctx.last
        err = np.abs(wrap_angle(np.arctan2(target[1] - last[:, 1], target[0] - last[:, 0]) - last[:, 2]))
        fpd = o.path_align_scale * o.path_align_forward_point_distance
        fpd += o.goal_align_scale * o.goal_align_forward_point_distance
        per_rad = 2.0 * (2.0 * fpd / ctx.resolution) / math.pi  # twice the alignment barrier, per radian
        return per_rad * err / max(self.scale, 1e-9)


class _Trend:
    """Sign history of one command axis (DWB ``OscillationCritic::CommandTrend``)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.sign = 0
        self.positive_only = False
        self.negative_only = False

    def update(self, v: float, deadband: float = 0.0) -> bool:
        flipped = False
        if abs(v) <= deadband:
            return False
        if v < 0.0:
            if self.sign > 0:
                self.negative_only = flipped = True
            self.sign = -1
        elif v > 0.0:
            if self.sign < 0:
                self.positive_only = flipped = True
            self.sign = 1
        return flipped

    def oscillating(self, v: np.ndarray) -> np.ndarray:
        return (self.positive_only & (v < 0.0)) | (self.negative_only & (v > 0.0))

    @property
    def flipped(self) -> bool:
        return self.positive_only or self.negative_only


class Oscillation:
    """After a command axis changes sign, commands of the old sign are illegal until the robot has
    moved ``oscillation_reset_dist`` or turned ``oscillation_reset_angle`` (or
    ``oscillation_reset_time`` passed). y and theta trends only update while |vx| is below
    ``x_only_threshold``. DWB ``OscillationCritic``, plus two navdeck rules against its deadlock
    (a robot that flipped to a -0.001 m/s sample may never drive forward again, so it stops, never
    moves ``reset_dist`` and stays vetoed): commands inside ``oscillation_deadband`` do not count
    as a direction, and ``oscillation_stall_reset_time`` of commands too slow to clear the flags by
    motion in that time, chosen under a veto, resets them."""

    name = "Oscillation"

    def __init__(self, options: DwaOptions) -> None:
        self.options = options
        self.scale = options.oscillation_scale
        self.x, self.y, self.theta = _Trend(), _Trend(), _Trend()
        self.anchor: Pose2D | None = None
        self.anchor_cycles = 0
        self.vetoed = False  # whether the last score made any trajectory illegal
        self.stall_cycles = 0  # consecutive chosen stops while vetoing

    def weight(self, ctx: CriticContext) -> float:
        return self.scale

    def reset(self) -> None:
        for t in (self.x, self.y, self.theta):
            t.reset()
        self.anchor = None
        self.anchor_cycles = 0
        self.vetoed = False
        self.stall_cycles = 0

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        tw = ctx.trajectories.twists
        k = tw.shape[0]
        illegal = np.zeros(k, dtype=bool)
        for axis, trend in enumerate((self.x, self.y, self.theta)):
            if trend.flipped:  # most cycles no axis has flipped: nothing to test
                illegal |= trend.oscillating(tw[:, axis])
        self.vetoed = bool(illegal.any())
        return np.zeros(k), illegal

    def debrief(self, cmd: Twist2D, pose: Pose2D) -> None:
        o = self.options
        band = o.oscillation_deadband
        # stalled: too slow to clear the flags by motion (reset_dist / reset_angle) within the
        # stall time, while the veto is in force
        t = o.oscillation_stall_reset_time
        slow = math.hypot(cmd.vx, cmd.vy) * t < o.oscillation_reset_dist
        slow = slow and abs(cmd.wz) * t < o.oscillation_reset_angle
        self.stall_cycles = self.stall_cycles + 1 if slow and self.vetoed else 0
        if 0 < t <= self.stall_cycles * o.sim_period:
            self.reset()
            return
        flagged = self.x.update(cmd.vx, band)
        if abs(cmd.vx) <= o.oscillation_x_only_threshold:
            flagged |= self.y.update(cmd.vy, band)
            flagged |= self.theta.update(cmd.wz, band)
        if flagged:
            self.anchor, self.anchor_cycles = pose, 0
            return
        self.anchor_cycles += 1
        if self.anchor is None or not (self.x.flipped or self.y.flipped or self.theta.flipped):
            return
        moved = pose.distance_to(self.anchor) > o.oscillation_reset_dist
        turned = abs(float(wrap_angle(pose.theta - self.anchor.theta))) > o.oscillation_reset_angle
        timed = o.oscillation_reset_time >= 0 and self.anchor_cycles * o.sim_period > o.oscillation_reset_time
        if moved or turned or timed:
            self.reset()


class FoxHeading(_Stateless):
    """Fox's heading term as a cost: |angle between the end pose's heading and the direction to a
    carrot ``fox_heading_lookahead`` m along the path| / pi (Fox: heading = 180 deg - that angle,
    maximised). A short carrot (source C's 0.5 m local look-ahead) keeps the robot on a path that
    bends round obstacles instead of aiming at a goal behind them, Fox's local minimum."""

    name = "FoxHeading"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.fox_heading_scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        path = ctx.local_path
        seg = np.hypot(*np.diff(path[:, :2], axis=0).T)
        along = np.concatenate(([0.0], np.cumsum(seg)))
        i = min(int(np.searchsorted(along, self.options.fox_heading_lookahead)), len(path) - 1)
        g, last = path[i], ctx.last
        bearing = np.arctan2(g[1] - last[:, 1], g[0] - last[:, 0])
        err = np.abs(wrap_angle(bearing - last[:, 2])) / math.pi
        return err, self._legal(err.shape[0])


class FoxClearance(_Stateless):
    """Fox's dist term as a cost, 1 - min(clearance, cap)/cap (clearance: smallest distance from
    the arc to a lethal cell minus the inscribed radius), and Fox's admissible velocities
    V_a = {v <= sqrt(2 dist(v,w) |decel_x|), w <= sqrt(2 turn(v,w) |decel_theta|)}, with dist / turn
    the distance / angle travelled along the arc before the footprint would touch an obstacle.

    Unlike ObstacleFootprint this does not reject an arc that hits something late in the horizon if
    the robot could still brake before it: Fox's semantics, where only the next period is executed.
    """

    name = "FoxClearance"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.fox_clearance_scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        o = self.options
        cap = o.fox_clearance_max
        clear = ctx.clearance - o.inscribed_radius  # (K, T)
        cost = 1.0 - np.clip(clear.min(axis=1), 0.0, cap) / cap
        tw = ctx.trajectories.twists
        hit = ctx.footprint_lethal  # (K, T-1), aligned with times[1:]
        any_hit = hit.any(axis=1)
        # time of the last collision-free pose before the first hit (conservative: the contact lies
        # somewhere between it and the next sample); meaningful where any_hit
        t_hit = ctx.trajectories.times[:-1][np.argmax(hit, axis=1)]
        speed = np.hypot(tw[:, 0], tw[:, 1])
        dist = speed * t_hit
        turn = np.abs(tw[:, 2]) * t_hit
        bad_v = any_hit & (speed > np.sqrt(2.0 * dist * abs(o.decel_lim_x)))
        bad_w = any_hit & (np.abs(tw[:, 2]) > np.sqrt(2.0 * turn * abs(o.decel_lim_theta)))
        return cost, bad_v | bad_w


class FoxVelocity(_Stateless):
    """Fox's vel term as a cost: 1 - speed / max speed (progress is rewarded)."""

    name = "FoxVelocity"

    def __init__(self, options: DwaOptions) -> None:
        super().__init__(options)
        self.scale = options.fox_velocity_scale

    def score(self, ctx: CriticContext) -> tuple[np.ndarray, np.ndarray]:
        tw = ctx.trajectories.twists
        vmax = max(self.options.max_speed_xy, self.options.max_vel_x, 1e-9)
        cost = 1.0 - np.clip(np.hypot(tw[:, 0], tw[:, 1]) / vmax, 0.0, 1.0)
        return cost, self._legal(cost.shape[0])


CRITIC_TYPES: dict[str, type] = {
    c.name: c
    for c in (
        BaseObstacle,
        ObstacleFootprint,
        PathDist,
        PathAlign,
        GoalDist,
        GoalAlign,
        RotateToGoal,
        Oscillation,
        PreferForward,
        FoxHeading,
        FoxClearance,
        FoxVelocity,
    )
}


def make_critics(options: DwaOptions) -> list[Critic]:
    """Instantiate ``options.critics`` in order."""
    return [CRITIC_TYPES[name](options) for name in options.critics]
