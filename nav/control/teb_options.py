"""Options of the TEB controller, with ``teb_local_planner``'s parameter names, units and defaults.

Defaults are teb_local_planner's (ROS 2 port, ``teb_config.h``) except where noted: navdeck caps the
band at 60 poses (one optimization must fit a 10 Hz cycle with room to spare on a small computer)
and measures ``min_obstacle_dist`` from a circular footprint's edge, not from the robot's centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

SOLVERS = ("lm_banded", "scipy")


class TebConfigError(ValueError):
    """A TEB option is out of range; the message names the field."""


FORWARD_DRIVE_WEIGHT = 1000.0
"""``weight_kinematics_forward_drive`` for a differential or skid base that can reverse: the
original TEB documents "around 1000 almost prevents backward driving" (with its default 1.0 the
skid4 robot reversed 1.5 s while turning round at the start of a route behind it)."""


@dataclass(frozen=True)
class TebOptions:
    """Every knob of :class:`nav.control.teb.TebController` (SI units, radians)."""

    # --- Robot (teb_local_planner "Robot configuration") -----------------------------------------
    holonomic: bool = False
    """True for omni bases: lateral velocity is allowed and the non-holonomic terms are off."""
    max_vel_x: float = 0.4
    """Largest forward speed, m/s. TEB 0.4."""
    max_vel_x_backwards: float = 0.2
    """Largest backward speed (positive), m/s. TEB 0.2."""
    max_vel_y: float = 0.0
    """Largest |lateral speed| for holonomic bases, m/s. TEB 0.0."""
    max_vel_theta: float = 0.3
    """Largest |angular speed|, rad/s. TEB 0.3."""
    acc_lim_x: float = 0.5
    """Forward acceleration limit, m/s^2. TEB 0.5."""
    acc_lim_y: float = 0.5
    """Lateral acceleration limit (holonomic), m/s^2. TEB 0.5."""
    acc_lim_theta: float = 0.5
    """Angular acceleration limit, rad/s^2. TEB 0.5."""
    min_turning_radius: float = 0.0
    """Smallest turning radius, m; 0 for a differential drive that turns in place. TEB 0.0."""
    footprint: tuple[tuple[float, float], ...] = ()
    """Footprint polygon in base_link, m: used for the feasibility check; the optimizer models the
    robot as its circumscribed circle (TEB ``footprint_model: circular``)."""
    robot_radius: float = 0.1
    """Radius of a round robot, m, when ``footprint`` is empty (Nav2 0.1)."""

    # --- Trajectory (teb_local_planner "Trajectory configuration") -------------------------------
    dt_ref: float = 0.3
    """Desired time between band poses, s. TEB 0.3."""
    dt_hysteresis: float = 0.1
    """Slack around ``dt_ref`` before the band is resized, s. TEB 0.1."""
    min_samples: int = 3
    """Fewest poses in the band. TEB 3."""
    max_samples: int = 60
    """Most poses in the band (TEB 500; navdeck 60 for a bounded cycle time)."""
    max_global_plan_lookahead_dist: float = 3.0
    """Length of global path the band covers, m; its end is the local goal. TEB 3.0."""
    max_pose_separation: float = 0.1
    """Largest distance between band poses, m (navdeck: keeps a thin obstacle from slipping
    between two poses, which TEB's dt-based sizing allows for a fast robot)."""
    include_dynamic_obstacles: bool = True
    """Take the walkers given by ``TebController.set_walkers`` as obstacles at their predicted
    position at each band pose's time (TEB's ``include_dynamic_obstacles``, default False there;
    on here: issue 16, TEB must respect people's predicted motion)."""
    feasibility_check_no_poses: int = 5
    """Band poses footprint-checked against the costmap before a command is sent. TEB 5."""
    force_reinit_new_goal_dist: float = 1.0
    """Re-initialize the band from the global path instead of warm-starting it when the local goal
    moved farther than this from the previous band's end, m (a replan took another route). TEB 1.0."""
    force_reinit_new_goal_angular: float = 0.5 * math.pi
    """... or its heading turned by more than this, rad. TEB 0.5 pi."""
    fold_reinit_dist: float = 0.3
    """A band whose progress along the local path runs backwards by more than this (m) has folded
    back on itself (a warm start from another route, or an optimizer detour): it is re-initialized
    from the path (navdeck; TEB's ``detectDetoursBackwards`` deletes such bands)."""
    global_plan_overwrite_orientation: bool = True
    """Replace the path's orientations by its segments' directions (diff drive). TEB true."""

    # --- Goal --------------------------------------------------------------------------------------
    xy_goal_tolerance: float = 0.2
    """Distance to the final goal under which only the heading is corrected, m. TEB 0.2."""
    yaw_goal_tolerance: float = 0.2
    """Heading tolerance at the goal, rad. TEB 0.2."""
    free_goal_vel: bool = False
    """Allow arriving at the final goal at speed. TEB false."""

    # --- Obstacles ---------------------------------------------------------------------------------
    min_obstacle_dist: float = 0.1
    """Desired clearance from the footprint circle's edge to obstacles, m (TEB 0.5 from the centre
    of a point robot)."""
    inflation_dist: float = 0.3
    """Clearance (m) below which the soft inflation term starts pushing. TEB 0.6 (point robot)."""

    # --- Optimization ------------------------------------------------------------------------------
    solver: str = "lm_banded"
    """"lm_banded": Levenberg-Marquardt on the banded normal equations with the analytic Jacobian
    (navdeck's default: 2-5x less CPU than "scipy" for similar final costs, docs/behaviors.md); "scipy":
    ``scipy.optimize.least_squares`` (trust-region reflective) on the same residuals and Jacobian."""
    solver_ftol: float = 0.01
    """Stop once an accepted step lowers the cost by less than this fraction (navdeck; scipy's
    ``ftol``). 0.01 saves about half of the iterations for +8 % final cost (docs/behaviors.md)."""
    no_inner_iterations: int = 5
    """Solver iterations per outer iteration. TEB 5."""
    no_outer_iterations: int = 4
    """Outer iterations (the solver's budget is inner x outer iterations, each one evaluation of the
    residuals and Jacobian). TEB 4."""
    penalty_epsilon: float = 0.1
    """Safety margin inside every limit, in the limit's unit. TEB 0.1; navdeck caps it at 10 % of
    each velocity/acceleration limit so a slow robot (0.26 m/s) is not held to 60 % of its speed."""
    weight_max_vel_x: float = 2.0
    """Weight of the forward/backward speed limit. TEB 2."""
    weight_max_vel_y: float = 2.0
    """Weight of the lateral speed limit. TEB 2."""
    weight_max_vel_theta: float = 1.0
    """Weight of the angular speed limit. TEB 1."""
    weight_acc_lim_x: float = 1.0
    """Weight of the forward acceleration limit. TEB 1."""
    weight_acc_lim_y: float = 1.0
    """Weight of the lateral acceleration limit. TEB 1."""
    weight_acc_lim_theta: float = 1.0
    """Weight of the angular acceleration limit. TEB 1."""
    weight_kinematics_nh: float = 1000.0
    """Weight of the non-holonomic constraint (diff drive). TEB 1000."""
    weight_kinematics_forward_drive: float = 1.0
    """Weight that prefers driving forwards (diff drive). TEB 1 ("still allows driving
    backwards"); ``for_robot`` gives a differential or skid base that can reverse
    ``FORWARD_DRIVE_WEIGHT``."""
    weight_kinematics_turning_radius: float = 1.0
    """Weight of ``min_turning_radius``. TEB 1."""
    weight_optimaltime: float = 1.0
    """Weight of the total-time term (the fastest trajectory). TEB 1."""
    weight_obstacle: float = 50.0
    """Weight of ``min_obstacle_dist``. TEB 50."""
    weight_inflation: float = 0.1
    """Weight of ``inflation_dist``. TEB 0.1."""
    weight_viapoint: float = 1.0
    """Weight pulling the band onto the global path. TEB 1."""

    # --- Controller server ---------------------------------------------------------------------------
    controller_frequency: float = 10.0
    """Control rate, Hz (source A's measured 10 Hz). Nav2 controller_server 20.0."""
    failure_tolerance: float = 0.3
    """How long (s) the controller may fail before ``PatienceExceeded``. Nav2 0.3."""
    unknown_is_lethal: bool = False
    """Treat NO_INFORMATION (255) cells as obstacles."""

    def __post_init__(self) -> None:
        positive = ("max_vel_x", "max_vel_theta", "acc_lim_x", "acc_lim_theta", "dt_ref")
        positive += ("max_global_plan_lookahead_dist", "max_pose_separation", "controller_frequency")
        positive += ("force_reinit_new_goal_dist", "force_reinit_new_goal_angular", "fold_reinit_dist")
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise TebConfigError(f"TebOptions.{name} must be positive, got {v!r}")
        non_negative = ("max_vel_x_backwards", "max_vel_y", "acc_lim_y", "min_turning_radius")
        non_negative += ("dt_hysteresis", "min_obstacle_dist", "inflation_dist", "penalty_epsilon")
        non_negative += ("xy_goal_tolerance", "yaw_goal_tolerance", "failure_tolerance")
        non_negative += tuple(f.name for f in fields(self) if f.name.startswith("weight_"))
        for name in non_negative:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise TebConfigError(f"TebOptions.{name} must be a non-negative number, got {v!r}")
        if self.holonomic and self.max_vel_y <= 0:
            raise TebConfigError("TebOptions.max_vel_y must be positive for a holonomic base")
        if not 3 <= self.min_samples <= self.max_samples:
            raise TebConfigError("TebOptions.min_samples must be >= 3 and <= max_samples")
        if not (isinstance(self.solver_ftol, int | float) and 0.0 < self.solver_ftol < 1.0):
            raise TebConfigError(f"TebOptions.solver_ftol must be in (0, 1), got {self.solver_ftol!r}")
        if self.solver not in SOLVERS:
            raise TebConfigError(f"TebOptions.solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.max_samples > 500:
            raise TebConfigError("TebOptions.max_samples must be at most 500")
        if self.no_inner_iterations < 1 or self.no_outer_iterations < 1:
            raise TebConfigError("TebOptions.no_inner_iterations and no_outer_iterations must be >= 1")
        if self.feasibility_check_no_poses < 0:
            raise TebConfigError("TebOptions.feasibility_check_no_poses must be >= 0")
        if self.inflation_dist < self.min_obstacle_dist:
            raise TebConfigError("TebOptions.inflation_dist must be >= min_obstacle_dist")
        if not self.footprint and self.robot_radius <= 0:
            raise TebConfigError("TebOptions.robot_radius must be positive without a footprint")

    @property
    def control_period(self) -> float:
        return 1.0 / self.controller_frequency

    @property
    def circumscribed_radius(self) -> float:
        if not self.footprint:
            return self.robot_radius
        return max(math.hypot(x, y) for x, y in self.footprint)

    @classmethod
    def for_robot(cls, profile: Any, **overrides: Any) -> TebOptions:
        """Options for a robot profile (duck-typed ``robot.profiles.RobotProfile``), then
        ``overrides`` (unknown names refused)."""
        lim = profile.limits
        holonomic = profile.kinematics == "omni"
        base = cls(
            holonomic=holonomic,
            max_vel_x=lim.max_vel_x,
            max_vel_x_backwards=max(-lim.min_vel_x, 0.0),
            max_vel_y=lim.max_vel_y if holonomic else 0.0,
            max_vel_theta=lim.max_vel_theta,
            acc_lim_x=lim.acc_lim_x,
            acc_lim_y=lim.acc_lim_y if holonomic else 0.0,
            acc_lim_theta=lim.acc_lim_theta,
            footprint=tuple(profile.footprint),
            robot_radius=profile.robot_radius if profile.robot_radius > 0 else 0.1,
        )
        if not holonomic and lim.min_vel_x < 0.0:
            # a base that can reverse but sees forwards (DWA gets PreferForward for the same reason)
            base = replace(base, weight_kinematics_forward_drive=FORWARD_DRIVE_WEIGHT)
        known = {f.name for f in fields(cls)}
        bad = sorted(set(overrides) - known)
        if bad:
            raise TebConfigError(f"unknown TebOptions field(s) {bad}")
        return replace(base, **overrides)


__all__ = ["SOLVERS", "TebConfigError", "TebOptions"]
