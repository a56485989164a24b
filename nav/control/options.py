"""Options of the DWA controller, with Nav2 DWB's parameter names, units and defaults.

Defaults follow ``nav2_bringup/params/nav2_params.yaml`` (the configuration Nav2 ships for a
TurtleBot-class base, whose limits are also the ``skid4`` profile's). Critic parameters use DWB's
``<Critic>.<param>`` names with the dot replaced by an underscore and the critic name in snake case
(``PathAlign.forward_point_distance`` -> ``path_align_forward_point_distance``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import cached_property
from typing import Any

#: DWB's critic list in ``nav2_params.yaml``, with ``ObstacleFootprint`` instead of ``BaseObstacle``
#: so a polygon footprint (not only its centre cell) is checked against the costmap.
DWB_CRITICS: tuple[str, ...] = (
    "RotateToGoal",
    "Oscillation",
    "ObstacleFootprint",
    "GoalAlign",
    "PathAlign",
    "PathDist",
    "GoalDist",
)

#: The objective of Fox, Burgard & Thrun 1997, G = alpha*heading + beta*dist + gamma*vel, as critics;
#: FoxClearance also applies Fox's admissible-velocity test instead of DWB's collision rejection.
FOX_CRITICS: tuple[str, ...] = ("FoxHeading", "FoxClearance", "FoxVelocity")

#: Added to ``DWB_CRITICS`` by :meth:`DwaOptions.for_robot` for differential/skid bases: a robot
#: whose lidar and IR sensors look forwards should back up only when that is the only way.
PREFER_FORWARD = "PreferForward"

KNOWN_CRITICS: frozenset[str] = frozenset(
    (*DWB_CRITICS, "BaseObstacle", PREFER_FORWARD, "FoxHeading", "FoxClearance", "FoxVelocity")
)


@dataclass(frozen=True)
class DwaOptions:
    """Every knob of :class:`nav.control.dwa.DwaController` (SI units, radians)."""

    # --- Kinematic parameters (dwb_plugins::KinematicParameters) ---------------------------------
    holonomic: bool = False
    """True for omni bases: ``vy`` is sampled (``vy_samples``); otherwise ``vy`` is always 0."""
    min_vel_x: float = 0.0
    """Smallest (most negative) forward velocity sampled, m/s. Nav2 0.0 (no reversing)."""
    max_vel_x: float = 0.26
    """Largest forward velocity, m/s. Nav2 0.26."""
    min_vel_y: float = 0.0
    """Smallest lateral velocity, m/s (holonomic only). Nav2 0.0."""
    max_vel_y: float = 0.0
    """Largest lateral velocity, m/s (holonomic only). Nav2 0.0."""
    max_vel_theta: float = 1.0
    """Largest |angular velocity|, rad/s. Nav2 1.0."""
    min_speed_xy: float = 0.0
    """Translations slower than this are invalid unless |wz| >= ``min_speed_theta``, m/s. Nav2 0.0."""
    max_speed_xy: float = 0.26
    """Largest hypot(vx, vy), m/s. Nav2 0.26."""
    min_speed_theta: float = 0.0
    """See ``min_speed_xy``, rad/s. Nav2 0.0."""
    acc_lim_x: float = 2.5
    """Forward acceleration limit, m/s^2. Nav2 2.5."""
    acc_lim_y: float = 0.0
    """Lateral acceleration limit, m/s^2. Nav2 0.0."""
    acc_lim_theta: float = 3.2
    """Angular acceleration limit, rad/s^2. Nav2 3.2."""
    decel_lim_x: float = -2.5
    """Forward deceleration limit (negative), m/s^2. Nav2 -2.5."""
    decel_lim_y: float = 0.0
    """Lateral deceleration limit (negative), m/s^2. Nav2 0.0."""
    decel_lim_theta: float = -3.2
    """Angular deceleration limit (negative), rad/s^2. Nav2 -3.2."""

    # --- Trajectory generator (dwb_plugins::StandardTrajectoryGenerator + XYThetaIterator) -------
    vx_samples: int = 20
    """Forward velocities sampled across the dynamic window. Nav2 20."""
    vy_samples: int = 5
    """Lateral velocities sampled (holonomic only; 1 otherwise). Nav2 5."""
    vtheta_samples: int = 20
    """Angular velocities sampled. Nav2 20."""
    sim_time: float = 1.7
    """Horizon each sampled velocity is simulated over, s. Nav2 1.7."""
    discretize_by_time: bool = False
    """Step trajectories every ``time_granularity`` s instead of by distance/angle. Nav2 False."""
    time_granularity: float = 0.5
    """Time step when ``discretize_by_time``, s. Nav2 0.5."""
    linear_granularity: float = 0.05
    """Largest distance between simulated poses, m. Nav2 0.05."""
    angular_granularity: float = 0.025
    """Largest rotation between simulated poses, rad. Nav2 0.025."""
    footprint_step: bool = True
    """Space poses by the footprint's sweep (travel + circumscribed radius x turn) against
    ``linear_granularity`` instead of by ``angular_granularity`` (navdeck; see ``time_steps``)."""
    max_steps: int = 60
    """Cap on simulated steps per trajectory (navdeck; keeps one cycle's cost bounded)."""
    controller_frequency: float = 20.0
    """Control rate, Hz; its period ``sim_period`` is the dynamic window's acceleration time
    (Fox's dt). Nav2 controller_server 20.0."""
    failure_tolerance: float = 0.3
    """How long (s) the controller may fail before ``PatienceExceeded``. Nav2 controller_server 0.3."""

    # --- Plan handling (dwb_core::DWBLocalPlanner) ------------------------------------------------
    prune_plan: bool = True
    """Drop the part of the path behind the robot each cycle. Nav2 True."""
    prune_distance: float = 2.0
    """How far back along the path (m) the closest-point search may look. Nav2 2.0."""
    forward_prune_distance: float = 2.0
    """Length of path ahead of the robot the critics see, m; its end is the local goal. Nav2 2.0."""

    # --- Footprint and costmap ---------------------------------------------------------------------
    footprint: tuple[tuple[float, float], ...] = ()
    """Footprint polygon in base_link, m (Nav2 ``footprint``); empty: a circle of ``robot_radius``."""
    robot_radius: float = 0.1
    """Radius of a round robot, m. Nav2 0.1 (used when ``footprint`` is empty)."""
    footprint_orientation_bins: int = 16
    """Headings the rasterised footprint is pre-rotated to (navdeck; 1 for round robots)."""
    unknown_is_lethal: bool = False
    """Treat NO_INFORMATION (255) cells as lethal. False like a Nav2 local costmap with
    ``track_unknown_space: false``; cells off the costmap are always lethal (DWB "Goes Off Grid")."""

    # --- Goal handling -----------------------------------------------------------------------------
    xy_goal_tolerance: float = 0.25
    """Distance to the goal (m) inside which RotateToGoal takes over. Nav2 0.25."""
    trans_stopped_velocity: float = 0.25
    """Speed (m/s) under which the robot counts as stopped for RotateToGoal. Nav2 0.25."""

    # --- Critics -------------------------------------------------------------------------------------
    critics: tuple[str, ...] = DWB_CRITICS
    """Critic names, as DWB's ``critics`` list."""
    base_obstacle_scale: float = 0.02
    """BaseObstacle.scale. Nav2 0.02."""
    base_obstacle_sum_scores: bool = False
    """BaseObstacle.sum_scores: sum costs along the trajectory instead of the last pose's. Nav2 False."""
    obstacle_footprint_scale: float = 0.02
    """ObstacleFootprint.scale (same weight as BaseObstacle)."""
    path_align_scale: float = 32.0
    """PathAlign.scale. Nav2 32.0."""
    path_align_forward_point_distance: float = 0.1
    """PathAlign.forward_point_distance, m. Nav2 0.1."""
    goal_align_scale: float = 24.0
    """GoalAlign.scale. Nav2 24.0."""
    goal_align_forward_point_distance: float = 0.1
    """GoalAlign.forward_point_distance, m. Nav2 0.1."""
    path_dist_scale: float = 32.0
    """PathDist.scale. Nav2 32.0."""
    goal_dist_scale: float = 24.0
    """GoalDist.scale. Nav2 24.0."""
    rotate_to_goal_scale: float = 32.0
    """RotateToGoal.scale. Nav2 32.0."""
    rotate_to_goal_slowing_factor: float = 5.0
    """RotateToGoal.slowing_factor. Nav2 5.0."""
    rotate_to_goal_lookahead_time: float = -1.0
    """RotateToGoal.lookahead_time, s; negative: use the trajectory's last pose. Nav2 -1.0."""
    oscillation_scale: float = 1.0
    """Oscillation.scale (it only rejects, so the scale does not matter). Nav2 1.0."""
    oscillation_reset_dist: float = 0.05
    """Oscillation.oscillation_reset_dist, m. Nav2 0.05."""
    oscillation_reset_angle: float = 0.2
    """Oscillation.oscillation_reset_angle, rad. Nav2 0.2."""
    oscillation_reset_time: float = -1.0
    """Oscillation.oscillation_reset_time, s; negative: never. Nav2 -1.0."""
    oscillation_x_only_threshold: float = 0.05
    """Oscillation.x_only_threshold, m/s: y and theta trends only count below this |vx|. Nav2 0.05."""
    oscillation_deadband: float = 0.01
    """Commands slower than this (m/s, rad/s per axis) neither set nor flip a trend: a near-stop
    has no direction (navdeck; DWB counts any sign, so a -0.001 m/s sample can forbid forward)."""
    oscillation_stall_reset_time: float = 1.0
    """Seconds of choosing only commands too slow to move ``oscillation_reset_dist`` or turn
    ``oscillation_reset_angle`` in that time, while the Oscillation critic vetoes trajectories,
    after which its flags reset: the veto then holds a stalled robot in place rather than
    preventing a dither (navdeck; DWB's flags only reset by motion, which a stalled robot never
    makes). <= 0: never."""
    prefer_forward_scale: float = 1.0
    """PreferForward.scale. DWB 1.0."""
    prefer_forward_penalty: float = -1.0
    """PreferForward.penalty: cost of a reversing sample, and of one slower than ``strafe_x`` that
    hardly turns. Negative (navdeck default): automatic, the most a reversing sample can gain on
    the path and goal critics over one horizon (the sum of the GoalDist, GoalAlign, PathDist and
    PathAlign scales x ``|min_vel_x| * sim_time`` in cells, divided by ``prefer_forward_scale``),
    so progress alone never makes backing win; it still wins where the forward and turning
    samples are illegal or much worse on the other critics. DWB's 1.0 is a rounding error against
    its own GoalDist scale of 24 per cell."""
    prefer_forward_strafe_x: float = 0.1
    """PreferForward.strafe_x, m/s: slower forward samples that also turn slower than
    ``strafe_theta`` get the penalty too (a base whose sensors look forwards). DWB 0.1."""
    prefer_forward_strafe_theta: float = 0.2
    """PreferForward.strafe_theta, rad/s. DWB 0.2."""
    prefer_forward_theta_scale: float = 10.0
    """PreferForward.theta_scale: cost per rad/s of turning (turning is not progress). DWB 10.0."""
    prefer_forward_sampling_distance: float = 0.5
    """Distance along the path (m) of the point whose direction tells whether the path lies behind
    the robot (navdeck; Nav2 RotationShimController ``forward_sampling_distance`` 0.5)."""
    prefer_forward_angle_threshold: float = math.pi / 2
    """Above this angle (rad) between the heading and that point, PreferForward also charges each
    trajectory its end heading's angle to the point, so the robot turns round to face its path
    instead of backing along it (navdeck)."""
    fox_heading_scale: float = 2.0
    """Fox's alpha (heading term weight). Fox et al. 1997 use 2.0."""
    fox_clearance_scale: float = 0.2
    """Fox's beta (clearance term weight). Fox et al. 1997 use 0.2."""
    fox_velocity_scale: float = 0.2
    """Fox's gamma (velocity term weight). Fox et al. 1997 use 0.2."""
    fox_heading_lookahead: float = 0.5
    """Distance along the path (m) of the point Fox's heading term aims at (source C's local plan
    look-ahead, 0.5 m)."""
    fox_clearance_max: float = 1.0
    """Clearance (m) above which the dist term saturates (navdeck; Fox bound it the same way)."""

    def __post_init__(self) -> None:
        unknown = set(self.critics) - KNOWN_CRITICS
        if unknown:
            raise ValueError(f"unknown critic(s) {sorted(unknown)}; known: {sorted(KNOWN_CRITICS)}")
        for name in ("max_vel_x", "max_vel_theta", "sim_time", "controller_frequency"):
            if not getattr(self, name) > 0:
                raise ValueError(f"DwaOptions.{name} must be positive")
        for name in ("vx_samples", "vy_samples", "vtheta_samples", "max_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"DwaOptions.{name} must be at least 1")
        if self.min_vel_x > self.max_vel_x or self.min_vel_y > self.max_vel_y:
            raise ValueError("DwaOptions: min_vel_* must not exceed max_vel_*")
        if not self.footprint and self.robot_radius <= 0:
            raise ValueError("DwaOptions needs a footprint polygon or a positive robot_radius")

    @property
    def sim_period(self) -> float:
        """Control period (s): the acceleration time of the dynamic window."""
        return 1.0 / self.controller_frequency

    @cached_property
    def circumscribed_radius(self) -> float:
        if not self.footprint:
            return self.robot_radius
        return max(math.hypot(x, y) for x, y in self.footprint)

    @property
    def inscribed_radius(self) -> float:
        if not self.footprint:
            return self.robot_radius
        pts = list(self.footprint)
        best = math.inf
        for (x0, y0), (x1, y1) in zip(pts, pts[1:] + pts[:1], strict=True):
            best = min(best, abs(x0 * (y1 - y0) - y0 * (x1 - x0)) / math.hypot(x1 - x0, y1 - y0))
        return best

    @classmethod
    def for_robot(cls, profile: Any, **overrides: Any) -> DwaOptions:
        """Options for a robot profile (duck-typed: anything with ``kinematics``, ``limits``,
        ``footprint`` and ``robot_radius`` like ``robot.profiles.RobotProfile``), then ``overrides``.

        Speed limits come from the profile; ``max_speed_xy`` is the larger of the axis limits so the
        omni base may use its full speed along each axis. A differential or skid base that can
        reverse (``min_vel_x`` < 0) gets the ``PreferForward`` critic too.
        """
        lim = profile.limits
        holonomic = profile.kinematics == "omni"
        base = cls(
            holonomic=holonomic,
            min_vel_x=lim.min_vel_x,
            max_vel_x=lim.max_vel_x,
            min_vel_y=-lim.max_vel_y if holonomic else 0.0,
            max_vel_y=lim.max_vel_y if holonomic else 0.0,
            max_vel_theta=lim.max_vel_theta,
            min_speed_xy=lim.min_speed_xy,
            max_speed_xy=max(lim.max_vel_x, lim.max_vel_y if holonomic else 0.0),
            min_speed_theta=lim.min_speed_theta,
            acc_lim_x=lim.acc_lim_x,
            acc_lim_y=lim.acc_lim_y if holonomic else 0.0,
            acc_lim_theta=lim.acc_lim_theta,
            decel_lim_x=lim.decel_lim_x,
            decel_lim_y=lim.decel_lim_y if holonomic else 0.0,
            decel_lim_theta=lim.decel_lim_theta,
            footprint=tuple(profile.footprint),
            robot_radius=profile.robot_radius if profile.robot_radius > 0 else 0.1,
        )
        if not holonomic and lim.min_vel_x < 0.0:
            # a base that can reverse but sees forwards: back up only when that is the only way
            base = replace(base, critics=(*base.critics, PREFER_FORWARD))
        known = {f.name for f in fields(cls)}
        bad = set(overrides) - known
        if bad:
            raise ValueError(f"unknown DwaOptions field(s) {sorted(bad)}")
        return replace(base, **overrides)
