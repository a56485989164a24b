"""Navigator: drive the robot through a queue of goal poses, one control-loop tick at a time.

The logic of Nav2's ``bt_navigator`` default tree (NavigateToPose / NavigateThroughPoses) written
as a plain state machine, because navdeck runs one control loop and no behaviour-tree engine:
plan to the current goal, replan every ``replan_period`` (Nav2's ``RateController`` at 1 Hz) and at
once when the remaining path is blocked (Nav2 ``IsPathValid``), let the controller follow the path,
check the goal (``GoalChecker``) and progress (``ProgressChecker``), and report *why* it stopped.

Replanning hysteresis (``keep_valid_path``): a periodic replan that would send the robot on a much
longer route is not taken while the current path is still valid (no lethal cell on what is left of
it), as Nav2's ``navigate_w_replanning_only_if_path_becomes_invalid`` tree keeps its path and its
``PathLongerOnApproach`` condition refuses a much longer one. Without it, lidar marks that close a
narrow gap now and then make the 1 Hz replans flip between the gap and a detour, and the robot
dithers between the two (greenhouse aisle at y 6.2: 537 against 178 path poses).

Pure logic, no threads and no clock of its own: ``tick(now, ...)`` is called by the control loop.
Planning goes through ``plan_fn`` (synchronous, default ``planner.plan``) or, for a worker thread,
through ``request_plan`` (called with a ``PlanRequest``) and ``deliver_plan`` (the result, or the
planner's exception). Recovery behaviours live elsewhere: on controller failure or no progress the
navigator enters ``STUCK`` with the reason, stops the robot, and waits for ``resume()`` (or fails
after ``stuck_timeout``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Literal, Protocol

import numpy as np

from nav.control import Controller, prepare_retry
from nav.control.dwa import DwaController
from nav.control.errors import ControllerError, NoValidControl, PatienceExceeded
from nav.control.goal_checker import GoalChecker
from nav.control.options import DwaOptions
from nav.control.progress_checker import ProgressChecker
from nav.control.teb import TebController
from nav.control.teb_options import TebOptions
from nav.planning.errors import NoValidPathFound, PlannerError
from nav.types import LETHAL_OBSTACLE, ZERO_TWIST, Costmap, Path, Pose2D, Twist2D, wrap_angle


class GlobalPlanner(Protocol):
    def plan(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> Path: ...


PlanFn = Callable[[Costmap, Pose2D, Pose2D], Path]


class NavState(StrEnum):
    IDLE = "idle"
    PLANNING = "planning"  # waiting for the first path to the current goal
    FOLLOWING = "following"
    STUCK = "stuck"  # stopped; recovery is needed (see NavFeedback.stuck_reason)
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"


TERMINAL = frozenset({NavState.IDLE, NavState.SUCCEEDED, NavState.FAILED, NavState.CANCELLED})

_ALWAYS_TAKEN = frozenset({"new goal", "blocked", "resume"})
"""Replan reasons whose result replaces the path whatever its length: the current path is gone,
blocked, or could not be followed (a recovery ran)."""


@dataclass(frozen=True)
class NavigatorOptions:
    """Options of :class:`Navigator`."""

    replan_period: float = 1.0
    """Seconds between periodic replans (1 / Nav2 ``planner_frequency``-style rate, 1 Hz in Nav2's
    default tree); <= 0 plans only when needed."""
    replan_on_blocked: bool = True
    """Replan as soon as a lethal cell lies on the remaining path (Nav2 ``IsPathValid``)."""
    blocked_check_distance: float = 2.0
    """Length of remaining path (m) checked for lethal cells each tick."""
    blocked_replan_period: float = 0.25
    """Minimum seconds between replans triggered by a blocked path (keeps planning off every tick)."""
    keep_valid_path: bool = True
    """Replanning hysteresis: while no lethal cell lies on the remaining path (Nav2 ``IsPathValid``,
    ``max_cost`` 254), a replan longer than ``length_factor`` x the remaining length (and by more than
    ``length_margin``) is not taken. Blocked-path replans, replans after a recovery (``resume``) and
    similar or shorter routes are always taken."""
    length_factor: float = 1.5
    """How much longer (ratio) a new route must be to be refused while the current one is valid (Nav2
    ``PathLongerOnApproach`` ``length_factor``, 2.0 there)."""
    length_margin: float = 1.0
    """... and by at least this many metres, so short remaining paths near the goal still update."""
    stuck_timeout: float = 10.0
    """Seconds in STUCK without ``resume()`` or a fresh path before the goal fails; inf: never."""
    nominal_speed: float = 0.26
    """Expected average speed (m/s): the ETA's speed until the robot has driven a while, and the
    weight of the prior below."""
    speed_prior_time: float = 10.0
    """The ETA's speed is the average speed while following a path in this request, with
    ``nominal_speed`` counted as if driven for this many seconds (s): a turn on the spot at the
    start or a short stop moves the ETA a little, not by minutes. Time spent waiting for a path,
    stuck or recovering is not driving and does not count."""


@dataclass(frozen=True)
class PlanRequest:
    """A planning job for a worker: call ``navigator.deliver_plan(request.id, path_or_error)``."""

    id: int
    costmap: Costmap
    start: Pose2D
    goal: Pose2D
    goal_index: int
    reason: str  # "new goal", "periodic", "blocked", "controller failed", "resume"


@dataclass(frozen=True)
class NavOutcome:
    """How a navigation request ended; ``reason`` names the typed error (``NoValidPathFound``,
    ``PatienceExceeded``, ``NoProgress``, ...) when it failed."""

    kind: Literal["reached", "failed", "cancelled"]
    reason: str = ""
    message: str = ""
    goals_reached: int = 0
    error: BaseException | None = None


@dataclass(frozen=True)
class NavFeedback:
    activity: str  # what it is doing, for people
    goal_index: int
    goal_count: int
    goal: Pose2D | None
    distance_remaining: float  # m, along the path, then straight between remaining waypoints
    eta: float  # s
    path: Path | None
    trajectories: np.ndarray | None = None  # (K, T, 2) controller samples, for the 3D view
    chosen: int = -1
    stuck_reason: str = ""
    time_without_progress: float = 0.0


@dataclass(frozen=True)
class NavTick:
    cmd: Twist2D
    state: NavState
    feedback: NavFeedback
    outcome: NavOutcome | None = None  # set on the tick the request ends


@dataclass
class _Goal:
    goals: list[Pose2D] = field(default_factory=list)
    index: int = 0


class Navigator:
    """Queue goals with ``set_goals``, call ``tick`` every control cycle, send ``NavTick.cmd``."""

    def __init__(
        self,
        planner: GlobalPlanner | None,
        controller: Controller,
        goal_checker: GoalChecker,
        progress_checker: ProgressChecker,
        options: NavigatorOptions | None = None,
        *,
        plan_fn: PlanFn | None = None,
        request_plan: Callable[[PlanRequest], None] | None = None,
    ) -> None:
        if plan_fn is None and request_plan is None:
            if planner is None:
                raise ValueError("Navigator needs a planner, a plan_fn or a request_plan callback")
            plan_fn = planner.plan
        self.controller = controller
        self.controllers: dict[str, Controller] = {"custom": controller}
        self.goal_checker = goal_checker
        self.progress_checker = progress_checker
        self.options = options or NavigatorOptions()
        self._plan_fn = plan_fn
        self._request_plan = request_plan
        self.state = NavState.IDLE
        self.outcome: NavOutcome | None = None
        self._q = _Goal()
        self._path: Path | None = None
        self._path_s = np.zeros(0)
        self._pending: int | None = None
        self._next_id = 0
        self._last_plan_time = -math.inf
        self._last_attempt_time = -math.inf
        self._last_plan_error: PlannerError | None = None
        self._stuck_reason = ""
        self._stuck_message = ""
        self._stuck_error: BaseException | None = None
        self._stuck_since = 0.0
        self._cancel_requested = False
        self._force_plan = ""
        self._driven = 0.0  # m travelled while following a path in this request (for the ETA)
        self._driving_time = 0.0  # s spent following a path in this request
        self._last_now: float | None = None
        self._debug: Any = None
        self.path_on_map_alone: Callable[[Pose2D, Pose2D], bool] | None = None
        """Whether a path from the pose to the goal exists on the map alone (no sensed obstacles).
        Asked only when a goal's first plan finds no path: if the map alone has one, sensed obstacles
        block the way (a person in the only doorway), so the navigator goes STUCK and the recoveries
        clear the costmaps and wait before it plans again, as Nav2's ClearGlobalCostmap recovery
        around ComputePathToPose; otherwise the goal fails at once. None: always fail at once."""
        self._activity = "idle"
        self._held: tuple[float, Twist2D, Any] | None = None  # (time, cmd, debug) of the last compute
        self._tick_dt = 0.0  # seconds between the last two ticks
        self._local: Costmap | None = None  # the local costmap of the last tick
        self._plan_reason = ""  # why the plan being waited for (or just computed) was asked for
        self.plans_kept = 0  # replans refused by the hysteresis (the current path was kept)
        self._last_cmd = ZERO_TWIST  # the command of the last tick (the stall check's)

    @classmethod
    def for_robot(
        cls,
        profile: Any,
        planner: GlobalPlanner | None,
        options: NavigatorOptions | None = None,
        *,
        plan_fn: PlanFn | None = None,
        request_plan: Callable[[PlanRequest], None] | None = None,
        goal_checker: GoalChecker | None = None,
        progress_checker: ProgressChecker | None = None,
        controller: str | None = None,
        teb_overrides: dict[str, Any] | None = None,
        **dwa_overrides: Any,
    ) -> Navigator:
        """A navigator configured from a robot profile (duck-typed like ``DwaOptions.for_robot``)
        with Nav2's default goal and progress checkers and both local controllers built (DWA from
        ``dwa_overrides``, TEB from ``teb_overrides``, over the profile-derived options), so a goal
        can switch between them. The active one is ``controller``, else the profile's
        ``controller`` field; an unknown name raises ``ValueError`` naming the field."""
        field_name = "controller" if controller is not None else "profile field controller"
        name = controller if controller is not None else str(getattr(profile, "controller", "dwa"))
        check_controller_name(name, field_name)
        controllers = {
            "dwa": make_controller("dwa", profile, **dwa_overrides),
            "teb": make_controller("teb", profile, **(teb_overrides or {})),
        }
        nav = cls(
            planner,
            controllers[name],
            goal_checker or GoalChecker(),
            progress_checker or ProgressChecker(),
            options,
            plan_fn=plan_fn,
            request_plan=request_plan,
        )
        nav.controllers = controllers
        return nav

    @property
    def controller_name(self) -> str:
        """The active controller's key in ``controllers`` ("custom" for one given to the constructor)."""
        return next((n for n, c in self.controllers.items() if c is self.controller), "custom")

    def select_controller(self, name: str) -> None:
        """Make ``controllers[name]`` the active controller and reset it (a goal that asks for DWA or
        TEB); a path being followed is handed to it. Unknown names raise ``ValueError``."""
        check_controller_name(name, "controller", tuple(self.controllers))
        new = self.controllers[name]
        if new is not self.controller:
            self.controller.reset()
            self.controller = new
        new.reset()
        self._held = None
        if self._path is not None:
            new.set_path(self._path)

    # -- requests ---------------------------------------------------------------------------------
    def set_goals(self, goals: Sequence[Pose2D]) -> None:
        """Start navigating through ``goals`` in order (replaces any current request)."""
        if not goals:
            raise ValueError("set_goals needs at least one goal")
        if not all(g.is_finite() for g in goals):
            raise ValueError("goals must be finite poses")
        self._q = _Goal(list(goals), 0)
        self.outcome = None
        self._driven = self._driving_time = 0.0
        self._cancel_requested = False
        self._start_goal()

    def cancel(self) -> None:
        """Stop; the next tick reports the ``cancelled`` outcome."""
        if self.state not in TERMINAL:
            self._cancel_requested = True

    def resume(self) -> None:
        """Leave STUCK after a recovery behaviour: reset progress tracking, re-arm the goal checker,
        ready the controller for a retry (``prepare_retry``: its failure count and goal window), and
        replan. Not a full ``reset()``: the controller keeps its critics' memories and band (that
        made the robot dither between chair legs), but a count left at its limit would raise
        ``PatienceExceeded`` again on the very next cycle, and four recoveries ran in 0.3 s while
        a walker stood in a door (Nav2 retries with a fresh FollowPath, which also re-arms its goal
        checker: a position latched before the recovery, the robot turning to the goal's heading,
        no longer counts once a back-up has moved the robot away)."""
        if self.state == NavState.STUCK:
            self._clear_stuck()
            self.goal_checker.reset()
            self.progress_checker.reset()
            prepare_retry(self.controller)
            self._force_plan = "resume"

    def path_ahead(self, distance: float) -> np.ndarray:
        """(M, 2) points of the path from the one nearest the robot to ``distance`` m along it;
        empty without a path."""
        if self._path is None:
            return np.zeros((0, 2))
        s = self._path_s
        i = self._nearest_index()
        j = int(np.searchsorted(s, s[i] + distance, side="right"))
        return self._path.poses[i : max(j, i + 1), :2].copy()

    def halt(self, reason: str, message: str) -> None:
        """Enter STUCK for a cause the navigator cannot see itself (localization lost, the safety
        layer holding the robot): it stops until ``resume()`` after a recovery, like any STUCK."""
        if self.state not in TERMINAL and not self._cancel_requested:
            self._enter_stuck(reason, message, None)

    def deliver_plan(self, request_id: int, result: Path | BaseException) -> None:
        """Hand in the result of a ``PlanRequest`` (a path, or the planner's exception). Call it
        from the control-loop thread (e.g. when polling the worker's future before ``tick``).
        Results of superseded requests are ignored; non-planner exceptions are re-raised."""
        if request_id != self._pending:
            return
        self._pending = None
        if isinstance(result, BaseException):
            if not isinstance(result, PlannerError):
                raise result
            self._plan_failed(result)
        else:
            self._accept_plan(result)

    @property
    def stuck_reason(self) -> str:
        """Why the navigator is STUCK (a typed error's name, or a ``halt`` reason); "" otherwise."""
        return self._stuck_reason

    @property
    def path(self) -> Path | None:
        return self._path

    @property
    def goals(self) -> list[Pose2D]:
        return list(self._q.goals)

    # -- the tick ---------------------------------------------------------------------------------
    def tick(
        self,
        now: float,
        pose: Pose2D,
        velocity: Twist2D,
        global_costmap: Costmap,
        local_costmap: Costmap | None = None,
    ) -> NavTick:
        """Advance one control cycle and return the command to send."""
        local = local_costmap if local_costmap is not None else global_costmap
        self._now, self._pose, self._global = now, pose, global_costmap
        self._local = local_costmap
        if self._last_now is not None and now > self._last_now:
            self._tick_dt = now - self._last_now
        self._update_speed(now, velocity)
        self._last_now = now
        self._debug = None
        if self._cancel_requested:
            self._cancel_requested = False
            self._pending = None
            return self._finish(NavOutcome("cancelled", goals_reached=self._q.index), NavState.CANCELLED)
        if self.state in TERMINAL:
            return self._tick(ZERO_TWIST)

        goal = self._q.goals[self._q.index]
        if self._path is not None and self.goal_checker.is_goal_reached(pose, goal, velocity):
            self._q.index += 1
            if self._q.index >= len(self._q.goals):
                return self._finish(NavOutcome("reached", goals_reached=self._q.index), NavState.SUCCEEDED)
            self._start_goal()
            goal = self._q.goals[self._q.index]

        self._maybe_plan(local)
        if self.state in TERMINAL:  # planning failed with no path to fall back on
            return self._tick(ZERO_TWIST, self.outcome)
        if self._path is None and self.state != NavState.STUCK:
            self.state = NavState.PLANNING
            self._activity = "waiting for a path" if self._pending is not None else "planning"
            return self._tick(ZERO_TWIST)

        if self.state == NavState.STUCK:
            if now - self._stuck_since > self.options.stuck_timeout:
                message = str(self._stuck_error) if self._stuck_error is not None else self._stuck_message
                return self._fail(self._stuck_reason, message or self._stuck_reason, self._stuck_error)
            return self._tick(ZERO_TWIST)

        if not self.progress_checker.check(pose, now):
            allowance = self.progress_checker.options.movement_time_allowance
            message = f"moved less than the required radius in {allowance:g} s"
            if self.goal_checker.position_latched:  # the operator should know only the turn was left
                left = abs(float(wrap_angle(goal.theta - pose.theta)))
                message = (
                    f"reached the goal's position ({math.hypot(pose.x - goal.x, pose.y - goal.y):.2f} m"
                    f" away) but could not turn to its heading ({left:.2f} rad left) in {allowance:g} s"
                )
            return self._stuck("NoProgress", message, None)
        if self.state != NavState.FOLLOWING:
            self.progress_checker.reset_stall()
        elif self.progress_checker.stalled(self._last_cmd, velocity, now):
            stall = self.progress_checker.options.stall_time_allowance
            return self._stuck("Stalled", f"commanded to stand still while following for {stall:g} s", None)

        held = self._held
        if held is not None and now < held[0] + _control_period(self.controller) - 0.5 * self._tick_dt:
            # the controller runs at its own controller_frequency (TEB 10 Hz in a 20 Hz loop): keep
            # its last command until it is due, as Nav2's controller_server would
            cmd, self._debug = held[1], held[2]
        else:
            self._held = None
            try:
                cmd, self._debug = self.controller.compute(pose, velocity, local)
            except PatienceExceeded as exc:
                return self._stuck(type(exc).__name__, str(exc), exc)
            except NoValidControl:
                # stop for this cycle and look for another way (Nav2 retries with a fresh path too)
                self._debug = getattr(self.controller, "last_debug", None)
                self._activity = "no safe trajectory: stopping"
                if now - self._last_attempt_time >= self.options.blocked_replan_period:
                    self._force_plan = "controller failed"
                self.state = NavState.FOLLOWING
                return self._tick(ZERO_TWIST)
            except ControllerError as exc:
                return self._fail(type(exc).__name__, str(exc), exc)
            self._held = (now, cmd, self._debug)
        self.state = NavState.FOLLOWING
        in_window = bool(getattr(self._debug, "in_goal_window", False))
        self._activity = (
            "turning to the goal heading" if in_window else f"following path to goal {self._q.index + 1}"
        )
        return self._tick(cmd)

    # -- planning ---------------------------------------------------------------------------------
    def _maybe_plan(self, local: Costmap) -> None:
        o = self.options
        now = self._now
        reason = ""
        if self._force_plan:
            reason, self._force_plan = self._force_plan, ""
        elif self._path is None and self.state != NavState.STUCK:  # STUCK waits for resume()
            reason = "new goal"
        elif (
            o.replan_on_blocked
            and now - self._last_attempt_time >= o.blocked_replan_period
            and self._blocked(local)
        ):
            reason = "blocked"
        elif o.replan_period > 0 and now - self._last_attempt_time >= o.replan_period:
            reason = "periodic"
        if not reason or (self._pending is not None and reason == "periodic"):
            return
        if self._path is None and self._pending is not None and reason == "new goal":
            return  # the first plan is on its way
        self._last_attempt_time = now
        self._plan_reason = reason
        goal = self._q.goals[self._q.index]
        if self._request_plan is not None:
            self._next_id += 1
            self._pending = self._next_id
            self._request_plan(
                PlanRequest(self._next_id, self._global, self._pose, goal, self._q.index, reason)
            )
            return
        assert self._plan_fn is not None
        try:
            path = self._plan_fn(self._global, self._pose, goal)
        except PlannerError as exc:
            self._plan_failed(exc)
            return
        self._accept_plan(path)

    def _accept_plan(self, path: Path) -> None:
        if len(path) == 0:
            self._plan_failed(NoValidPathFound("planner returned an empty path"))
            return
        goal = self._q.goals[self._q.index]
        poses = np.array(path.poses, dtype=float, copy=True)
        poses[-1, 2] = goal.theta  # the controller turns to the goal's heading, not the path's
        seg = np.hypot(*np.diff(poses[:, :2], axis=0).T) if len(poses) > 1 else np.zeros(0)
        s = np.concatenate(([0.0], np.cumsum(seg)))
        if self._keep_current(float(s[-1])):
            self.plans_kept += 1
            self._last_plan_error = None
            return
        self._path = Path(poses)
        self._path_s = s
        self._last_plan_time = self._now
        self._last_plan_error = None
        self.controller.set_path(self._path)
        if (
            self.state == NavState.STUCK
            and self._stuck_error is not None
            and isinstance(self._stuck_error, PlannerError)
        ):
            self._clear_stuck()

    def _plan_failed(self, exc: PlannerError) -> None:
        self._last_plan_error = exc
        if self._path is None:
            if isinstance(exc, NoValidPathFound) and self._sensed_obstacles_block():
                self._enter_stuck(
                    type(exc).__name__, f"no path while sensed obstacles block the way: {exc}", exc
                )
            else:
                self._fail(type(exc).__name__, str(exc), exc)
        elif self._blocked(None) and self.state != NavState.STUCK:
            self._stuck(type(exc).__name__, f"path blocked and no new path: {exc}", exc)
        # otherwise keep following the current path; the next periodic replan tries again

    def _sensed_obstacles_block(self) -> bool:
        check = self.path_on_map_alone
        return check is not None and check(self._pose, self._q.goals[self._q.index])

    def _keep_current(self, new_length: float) -> bool:
        """Hysteresis: refuse a new path of ``new_length`` m because the current one is still valid
        and the new one is a much longer route (see ``NavigatorOptions.keep_valid_path``)."""
        o = self.options
        if not o.keep_valid_path or self._path is None or self._plan_reason in _ALWAYS_TAKEN:
            return False
        i = self._nearest_index()
        remaining = float(self._path_s[-1] - self._path_s[i]) + self._pose.distance_to(
            Pose2D.from_array(self._path.poses[i])
        )
        if new_length <= max(o.length_factor * remaining, remaining + o.length_margin):
            return False  # a similar or shorter route: take it (it follows the costs as they are now)
        # IsPathValid over everything left: the global costmap, and the local one where it reaches
        return not self._blocked(self._local, math.inf)

    def _blocked(self, local: Costmap | None, distance: float | None = None) -> bool:
        """Whether a lethal cell lies on the next ``distance`` (default ``blocked_check_distance``)
        m of the path, in the global costmap or ``local``."""
        if self._path is None:
            return False
        ahead = self.path_ahead(self.options.blocked_check_distance if distance is None else distance)
        maps = [self._global] if local is None else [self._global, local]
        for cm in maps:
            rows, cols = cm.geometry.world_to_cell(ahead)
            inside = cm.geometry.in_bounds(rows, cols)
            if np.any(cm.costs[rows[inside], cols[inside]] == LETHAL_OBSTACLE):
                return True
        return False

    def _nearest_index(self) -> int:
        assert self._path is not None
        p = self._path.poses
        return int(np.argmin(np.hypot(p[:, 0] - self._pose.x, p[:, 1] - self._pose.y)))

    # -- state helpers ----------------------------------------------------------------------------
    def _start_goal(self) -> None:
        self._path = None
        self._pending = None
        self._last_attempt_time = -math.inf
        self._clear_stuck()
        self.goal_checker.reset()
        self.progress_checker.reset()
        self.controller.reset()
        self._held = None
        self.state = NavState.PLANNING
        self._activity = "planning"

    def _clear_stuck(self) -> None:
        self._stuck_reason, self._stuck_error = "", None
        self._held = None
        if self.state == NavState.STUCK:
            self.state = NavState.FOLLOWING

    def _stuck(self, reason: str, message: str, error: BaseException | None) -> NavTick:
        self._enter_stuck(reason, message, error)
        return self._tick(ZERO_TWIST)

    def _enter_stuck(self, reason: str, message: str, error: BaseException | None) -> None:
        if self.state != NavState.STUCK:
            self._stuck_since = self._last_now if self._last_now is not None else 0.0
        self.state = NavState.STUCK
        self._stuck_reason, self._stuck_error = reason, error
        self._stuck_message = message
        self._held = None
        self._activity = f"stuck: {message}"

    def _fail(self, reason: str, message: str, error: BaseException | None) -> NavTick:
        self._activity = f"failed: {message}"
        return self._finish(
            NavOutcome("failed", reason, message, goals_reached=self._q.index, error=error), NavState.FAILED
        )

    def _finish(self, outcome: NavOutcome, state: NavState) -> NavTick:
        self.outcome = outcome
        self.state = state
        if state != NavState.FAILED:
            self._activity = state.value
        self.controller.reset()
        self._held = None
        return self._tick(ZERO_TWIST, outcome)

    def _update_speed(self, now: float, velocity: Twist2D) -> None:
        """Count the last interval as driving when the previous tick was following a path (the
        velocity measured now is what that tick's command produced)."""
        if self.state == NavState.FOLLOWING and self._last_now is not None and now > self._last_now:
            dt = now - self._last_now
            self._driven += math.hypot(velocity.vx, velocity.vy) * dt
            self._driving_time += dt

    @property
    def expected_speed(self) -> float:
        """The ETA's speed (m/s): the average while following in this request, ``nominal_speed``
        weighted as ``speed_prior_time`` s of driving (so it starts at ``nominal_speed``)."""
        o = self.options
        prior = max(o.speed_prior_time, 0.0)
        if self._driving_time + prior <= 0.0:
            return o.nominal_speed
        return (self._driven + o.nominal_speed * prior) / (self._driving_time + prior)

    def _remaining(self) -> float:
        q = self._q
        if not q.goals or self.state in TERMINAL:
            return 0.0
        if self._path is not None:
            i = self._nearest_index()
            d = float(self._path_s[-1] - self._path_s[i]) + self._pose.distance_to(
                Pose2D.from_array(self._path.poses[i])
            )
        else:
            d = self._pose.distance_to(q.goals[q.index])
        for a, b in zip(q.goals[q.index : -1], q.goals[q.index + 1 :], strict=True):
            d += a.distance_to(b)
        return d

    def _tick(self, cmd: Twist2D, outcome: NavOutcome | None = None) -> NavTick:
        self._last_cmd = cmd
        remaining = self._remaining()
        speed = self.expected_speed
        q = self._q
        goal = q.goals[q.index] if q.goals and q.index < len(q.goals) else None
        dbg = self._debug
        fb = NavFeedback(
            activity=self._activity,
            goal_index=q.index,
            goal_count=len(q.goals),
            goal=goal,
            distance_remaining=remaining,
            eta=remaining / speed if speed > 0.0 else math.inf,
            path=self._path,
            trajectories=getattr(dbg, "trajectories", None),
            chosen=int(getattr(dbg, "chosen", -1)),
            stuck_reason=self._stuck_reason,
            time_without_progress=self.progress_checker.time_without_progress(self._now),
        )
        return NavTick(cmd, self.state, fb, outcome)


CONTROLLERS = ("dwa", "teb")
"""Local controllers a profile or a goal can name (Nav2 ``controller_plugins``)."""


def check_controller_name(
    name: object, field_name: str = "controller", known: Sequence[str] = CONTROLLERS
) -> str:
    """``name`` if it is a known controller, else ``ValueError`` naming ``field_name``."""
    if not isinstance(name, str) or name not in known:
        raise ValueError(f"{field_name} must be one of {', '.join(known)}, got {name!r}")
    return name


def make_controller(name: str, profile: Any, **overrides: Any) -> Controller:
    """A ``DwaController`` or ``TebController`` with options derived from ``profile`` then
    ``overrides`` (fields of ``DwaOptions`` / ``TebOptions``)."""
    check_controller_name(name)
    if name == "teb":
        return TebController(TebOptions.for_robot(profile, **overrides))
    return DwaController(DwaOptions.for_robot(profile, **overrides))


def _control_period(controller: Controller) -> float:
    """Seconds between compute calls: 1 / the controller's ``controller_frequency`` (0: every tick)."""
    hz = getattr(getattr(controller, "options", None), "controller_frequency", None)
    return 1.0 / hz if isinstance(hz, int | float) and hz > 0 else 0.0


__all__ = [
    "CONTROLLERS",
    "GlobalPlanner",
    "NavFeedback",
    "NavOutcome",
    "NavState",
    "NavTick",
    "Navigator",
    "NavigatorOptions",
    "PlanFn",
    "PlanRequest",
    "check_controller_name",
    "make_controller",
]
