"""Feature: explore with one click (``explore_lite`` / m-explore, inside the server).

Exploration is a sub-state of MAPPING: starting it starts a mapping session (or joins the one that
runs), then, on every map SLAM publishes, the explorer (:mod:`nav.exploration`) finds the frontiers
of the live map and sends the navigation feature the best one's goal (navigate while mapping: the
mode stays MAPPING, one session, one recorded run). A goal that fails (no path, no progress, the
controller gives up) is blacklisted and the next frontier is tried; a goal whose frontier has been
mapped on the way is replaced by the next best at once, as ``explore_lite`` re-plans.

It ends when no reachable frontier is left (``complete``: mapping stops, its final optimization
runs, and the dashboard offers to save the map), on the time budget (``time_budget``, the same),
on ``stop`` (``stopped``: mapping keeps running, the operator may drive on), on e-stop, a fault or
any mode change (``interrupted``), or when the operator drives by hand (``stopped``, teleop).
"""

from __future__ import annotations

import logging
import math
import threading
from concurrent.futures import Future
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from app.features.mapping import Mapping
from app.features.navigation import Navigation
from app.modes import Mode, TransitionRefused
from nav.exploration import FrontierExplorer, FrontierOptions, FrontierReport, goal_pose
from nav.types import Pose2D

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session
    from robot.base import SensorFrame

PROGRESS_STEP = 0.1  # m closer along the distance field that counts as progress (two cells)
ORDER = 45  # after navigation: a goal sent here is picked up by its next tick
log = logging.getLogger("navdeck.exploration")


class ExplorationState(StrEnum):
    IDLE = "idle"  # never started
    EXPLORING = "exploring"
    COMPLETE = "complete"  # no reachable frontier left
    TIME_BUDGET = "time_budget"  # the budget ran out
    STOPPED = "stopped"  # the operator stopped it (API, dashboard, driving by hand)
    INTERRUPTED = "interrupted"  # e-stop, fault or a mode change


ENDED = frozenset(
    {
        ExplorationState.COMPLETE,
        ExplorationState.TIME_BUDGET,
        ExplorationState.STOPPED,
        ExplorationState.INTERRUPTED,
    }
)


class ExplorationRefused(RuntimeError):
    """Exploration cannot start now (409): the mode refuses mapping, no lidar, already running."""

    def __init__(self, detail: str, mode: str, allowed: list[str] | None = None) -> None:
        super().__init__(detail)
        self.mode = mode
        self.allowed = allowed or []


@dataclass(frozen=True)
class ExplorationOptions:
    frontiers: FrontierOptions = field(default_factory=FrontierOptions)
    replan_interval: float = 1.0
    """Seconds between re-evaluations of the frontiers while driving to one (``explore_lite``
    ``planner_frequency`` 0.33 Hz; the map is published at 1 Hz here)."""
    progress_timeout: float = 30.0
    """A goal the robot has not come closer to for this long (s) is given up and blacklisted
    (``explore_lite`` ``progress_timeout``, 30 s). Closer is measured along the frontier search's
    distance field, so a long way round that follows it is progress and driving off elsewhere is
    not (office:1: 310 s spent on a goal 1.9 m away while the robot drove 14 m off and back)."""
    max_frontier_points: int = 4000
    """Frontier cells sent to the 3D view, at most (a decimated sample of a large map's)."""
    stop_mapping_at_end: bool = True
    """On ``complete`` or ``time_budget`` stop mapping (final optimization, map ready to save)."""


class Exploration:
    """The exploration stage; ``start`` / ``stop`` are thread-safe (API)."""

    def __init__(
        self,
        session: Session,
        mapping: Mapping,
        navigation: Navigation,
        options: ExplorationOptions | None = None,
    ) -> None:
        self.session = session
        self.mapping = mapping
        self.navigation = navigation
        self.options = options or ExplorationOptions()
        self.explorer = FrontierExplorer(self.options.frontiers)
        self._lock = threading.Lock()
        self.state = ExplorationState.IDLE
        self.reason = ""
        self.time_budget: float | None = None
        self._started: float | None = None
        self._ended: float | None = None
        self._request: int | None = None  # the navigation request of the current goal
        self._goal: tuple[float, float] | None = None
        self._goal_cells: np.ndarray | None = None
        """The cells of the frontier ``_goal`` was chosen from: blacklisted with it when it fails."""
        self._best_travel = math.inf  # the least field travel to the goal seen so far, and when
        self._progress_at = 0.0
        self._arrival_grid: Any = None  # the map when a goal was reached: too old to judge it by
        self._last_eval = -math.inf
        self._evaluated_grid: Any = None
        self._need_eval = False  # a goal ended (or exploring began): evaluate without waiting
        self._job: Future | None = None  # a frontier search on a worker (real clock)
        # On a virtual clock the search runs in the tick (deterministic); on a real one on a worker:
        # its Dijkstra over a large map takes longer than a control period.
        self.synchronous = bool(getattr(session.clock, "is_virtual", False))
        self._report: FrontierReport | None = None
        self._frontier_points: np.ndarray | None = None
        self.goals_sent = 0
        self.goals_reached = 0
        self.goals_failed = 0
        self._start_pending = False
        self._stop_pending: str | None = None

    # ------------------------------------------------------------------ requests (any thread)
    def start(self, time_budget: float | None = None) -> None:
        """Start exploring (mapping starts too unless it runs). ``time_budget`` in seconds of the
        session clock; None: until no frontier is left. Raises ``ExplorationRefused``."""
        if time_budget is not None and not (math.isfinite(time_budget) and time_budget > 0):
            raise ValueError(f"time budget must be a positive number of seconds, got {time_budget}")
        modes = self.session.modes
        with self._lock:
            if self.state == ExplorationState.EXPLORING or self._start_pending:
                raise ExplorationRefused("already exploring", modes.mode.value, modes.allowed())
            if modes.mode != Mode.MAPPING:
                try:
                    self.mapping.start()
                except TransitionRefused as exc:
                    raise ExplorationRefused(exc.reason, exc.current.value, exc.allowed) from None
            self.time_budget = time_budget
            self._start_pending = True
            self._stop_pending = None

    def stop(self, actor: str = "operator") -> bool:
        """Stop exploring (the goal running is cancelled, mapping keeps running). False if idle."""
        with self._lock:
            running = self.state == ExplorationState.EXPLORING or self._start_pending
            if running:
                self._stop_pending = actor
                self._start_pending = False
        return running

    # ------------------------------------------------------------------ the stage (loop thread)
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        with self._lock:
            start, self._start_pending = self._start_pending, False
            stop, self._stop_pending = self._stop_pending, None
        if start:
            self._begin(now)
        if self.state != ExplorationState.EXPLORING:
            return
        if stop is not None:
            self._cancel_goal(actor=stop)
            self._end(now, ExplorationState.STOPPED, f"stopped by {stop}")
            return
        mode = session.modes.mode
        if mode != Mode.MAPPING:
            self._end(
                now, ExplorationState.INTERRUPTED, f"mode changed to {mode.value}: {session.modes.reason}"
            )
            return
        assert self._started is not None
        if self.time_budget is not None and now - self._started >= self.time_budget:
            self._cancel_goal()
            self._end(now, ExplorationState.TIME_BUDGET, f"time budget of {self.time_budget:g} s used")
            return
        if not self.navigation.mapping_live():
            return  # SLAM's first map is not out yet
        if self._check_goal_outcome(now):
            return
        self._check_goal_progress(session.pose)
        if self._job is not None:
            if not self._job.done():
                return
            job, self._job = self._job, None
            try:
                report, grid, pose = job.result()
            except Exception:  # a failed search must not end exploring: the next map is tried
                log.exception("frontier search failed")
                return
            self._decide(report, grid, pose, now)
            return
        grid, costmap = self.navigation.live_grid, self.navigation.global_costmap
        if grid is None or costmap is None:
            return
        if grid is self._arrival_grid:
            return  # a goal was reached on this map: wait for one with what the robot sees there
        fresh = grid is not self._evaluated_grid
        due = now - self._last_eval >= self.options.replan_interval
        if not ((fresh and due) or (self._need_eval and self._request is None)):
            return
        self._need_eval = False
        self._evaluated_grid, self._last_eval = grid, now
        pose = session.pose
        if self.synchronous:
            self._decide(*self._search(grid, costmap, pose), now)
        else:
            self._job = session.workers.submit(self._search, grid, costmap, pose)

    def _search(self, grid: Any, costmap: Any, pose: Pose2D) -> tuple[FrontierReport, Any, Pose2D]:
        """The frontier search (a worker on a real clock; it only reads the explorer's blacklist)."""
        return self.explorer.find(grid, costmap, pose), grid, pose

    def _begin(self, now: float) -> None:
        self.explorer.clear_blacklist()
        self.state = ExplorationState.EXPLORING
        self.reason = ""
        self._started, self._ended = now, None
        self._request = self._goal = None
        self._report = None
        self._frontier_points = None
        self._evaluated_grid = None
        self._need_eval = True
        self._job = None
        self._last_eval = -math.inf
        self.goals_sent = self.goals_reached = self.goals_failed = 0
        self.session.add_event(
            "exploration",
            status="started",
            **({} if self.time_budget is None else {"time_budget_s": self.time_budget}),
        )

    def _check_goal_outcome(self, now: float) -> bool:
        """Account for the goal that ended since the last tick; True when exploration ended."""
        nav = self.navigation
        if self._request is None or nav.current_request == self._request:
            return False
        out = nav.last_outcome or {}
        if out.get("request_id") == self._request:
            kind = out.get("kind")
            if kind == "reached":
                self.goals_reached += 1
            elif kind == "failed" and self._goal is not None:
                self.goals_failed += 1
                self.explorer.mark_failed(self._goal, self._goal_cells)
                self.session.add_event(
                    "exploration",
                    status="frontier blacklisted",
                    goal=list(self._goal),
                    reason=out.get("reason"),
                )
            elif kind == "cancelled" and out.get("reason") == "teleop":
                self._request = None
                self._end(now, ExplorationState.STOPPED, "the operator drove by hand")
                return True
        self._request = self._goal = None
        self._need_eval = True
        return False

    def _check_goal_progress(self, pose: Pose2D) -> None:
        """Count the current goal reached once the robot is within ``min_goal_distance`` of it: the
        frontier is in sight from there, and the last turns onto a goal near furniture ended in
        ``NoProgress`` 10-30 s later (traced in the office). The frontiers are evaluated again at
        once. A STUCK goal is left to navigation's recoveries, which run in MAPPING."""
        nav = self.navigation
        if self._request is None or self._goal is None or nav.current_request != self._request:
            return
        goal = self._goal
        if math.hypot(goal[0] - pose.x, goal[1] - pose.y) > self.options.frontiers.min_goal_distance:
            return
        self.goals_reached += 1
        self.session.add_event("exploration", status="frontier reached", goal=list(goal))
        self._arrival_grid = self.navigation.live_grid
        self._cancel_goal()
        self._need_eval = True

    def _decide(self, report: FrontierReport, grid: Any, pose: Pose2D, now: float) -> None:
        """Act on a frontier search: keep the goal, send the best frontier's, or end (loop thread)."""
        self._report = report
        # The robot stands there and still does not see past it -- judged on a map SLAM published
        # after it arrived (the one of the arrival tick does not hold what it sees from there yet).
        if grid is not self._arrival_grid:
            for goal, cells in zip(report.unobservable, report.unobservable_cells, strict=True):
                self.explorer.mark_failed(goal, cells)
                self.session.add_event("exploration", status="frontier unobservable", goal=list(goal))
        self._frontier_points = self._sample(report)
        if self._request is not None and self._goal is not None and self._goal_still_frontier(report):
            if self._making_progress(report.travel_to(self._goal), now):
                return  # keep driving to it
            self._give_up_goal("no progress towards the frontier")
            self._need_eval = True  # the next tick searches without the banned cells
            return
        chosen = report.chosen
        if chosen is None:
            if self._request is None and report.free_area_m2 > 0 and self.explorer.forgive():
                # Before ending, places that failed once are tried again from here, on the map as
                # it is now (a goal fails for the way the robot came, a doorway seen edge-on...).
                self.session.add_event("exploration", status="blacklist forgiven")
                self._need_eval = True
                return
            if self._request is None and report.free_area_m2 > 0:  # not before SLAM saw anything
                left = len(report.frontiers)
                why = (
                    "no frontier left"
                    if left == 0
                    else f"no reachable frontier left ({left} unreachable or blacklisted)"
                )
                self._end(now, ExplorationState.COMPLETE, why)
            return  # the running goal finishes (its frontier is mapped): re-evaluated after it
        assert chosen.goal is not None
        target = goal_pose(chosen.goal, pose)
        try:
            rid = self.navigation.set_goals([target], actor="explorer")
        except (ValueError, RuntimeError) as exc:  # GoalRejected / NavigationRefused: try another
            self.explorer.mark_failed(chosen.goal, chosen.cells)
            self.goals_failed += 1
            self._need_eval = True
            self.session.add_event(
                "exploration", status="goal refused", goal=list(chosen.goal), reason=str(exc)
            )
            return
        self._request, self._goal, self._goal_cells = rid, chosen.goal, chosen.cells
        self._best_travel, self._progress_at = chosen.travel, now
        self.goals_sent += 1
        self.session.add_event(
            "exploration",
            status="frontier chosen",
            goal=[round(chosen.goal[0], 3), round(chosen.goal[1], 3)],
            length_m=round(chosen.length, 2),
            travel_m=round(chosen.travel, 2),
            frontiers=len(report.frontiers),
        )

    def _making_progress(self, travel: float, now: float) -> bool:
        """Has the robot come closer to the goal (along the distance field) within
        ``progress_timeout``? Every call with a shorter travel counts as progress."""
        if travel < self._best_travel - PROGRESS_STEP:
            self._best_travel, self._progress_at = travel, now
        return now - self._progress_at <= self.options.progress_timeout

    def _give_up_goal(self, reason: str) -> None:
        assert self._goal is not None
        goal, cells = self._goal, self._goal_cells
        self._cancel_goal()
        self.explorer.mark_failed(goal, cells)
        self.goals_failed += 1
        self.session.add_event("exploration", status="frontier blacklisted", goal=list(goal), reason=reason)

    def _goal_still_frontier(self, report: FrontierReport) -> bool:
        """Does a reachable, not blacklisted frontier still lie at the current goal?"""
        assert self._goal is not None
        gx, gy = self._goal
        reach = self.options.frontiers.goal_reach + 2 * self.options.frontiers.blacklist_radius
        return any(np.hypot(f.cells[:, 0] - gx, f.cells[:, 1] - gy).min() <= reach for f in report.reachable)

    def _sample(self, report: FrontierReport) -> np.ndarray | None:
        if not report.frontiers:
            return None
        pts = np.vstack([f.cells for f in report.frontiers])
        k = math.ceil(len(pts) / self.options.max_frontier_points)
        return np.ascontiguousarray(pts[::k], dtype=np.float32)

    def _cancel_goal(self, actor: str = "explorer") -> None:
        if self._request is not None and self.navigation.current_request == self._request:
            self.navigation.cancel(actor=actor)
        self._request = self._goal = None

    def _end(self, now: float, state: ExplorationState, reason: str) -> None:
        self.state, self.reason, self._ended = state, reason, now
        self._job = None  # a search still running is not acted on
        area = self._report.free_area_m2 if self._report is not None else 0.0
        self.session.add_event(
            "exploration",
            status=state.value,
            reason=reason,
            explored_area_m2=round(area, 2),
            goals_sent=self.goals_sent,
            goals_failed=self.goals_failed,
        )
        if state in (ExplorationState.COMPLETE, ExplorationState.TIME_BUDGET):
            self._frontier_points = None if state == ExplorationState.COMPLETE else self._frontier_points
            if self.options.stop_mapping_at_end and self.session.modes.mode == Mode.MAPPING:
                try:
                    self.mapping.stop()
                except Exception:  # a refused stop leaves mapping running: the operator stops it
                    log.exception("stopping mapping after exploration failed")

    # ------------------------------------------------------------------ outputs
    def status(self) -> dict[str, Any]:
        """``GET /api/exploration``: state, time, explored area, frontiers, and the save offer."""
        now = self.session.clock.now()
        started, ended = self._started, self._ended
        elapsed = None if started is None else (ended if ended is not None else now) - started
        left = None
        if self.time_budget is not None and elapsed is not None:
            left = max(0.0, self.time_budget - elapsed)
        report = self._report
        pending = self._start_pending
        state = ExplorationState.EXPLORING if pending else self.state
        stopping = self._stop_pending
        if stopping is not None and state == ExplorationState.EXPLORING:  # the loop ends it next tick
            state = ExplorationState.STOPPED
        ended_with_map = state in (
            ExplorationState.COMPLETE,
            ExplorationState.TIME_BUDGET,
            ExplorationState.STOPPED,
        )
        return {
            "state": state.value,
            "active": state == ExplorationState.EXPLORING,
            "reason": f"stopped by {stopping}" if stopping is not None else "" if pending else self.reason,
            "elapsed_s": None if elapsed is None or pending else round(elapsed, 1),
            "time_budget_s": self.time_budget,
            "time_left_s": None if left is None or pending else round(left, 1),
            "explored_area_m2": None if report is None else round(report.free_area_m2, 2),
            "frontiers": None if report is None else len(report.frontiers),
            "reachable_frontiers": None if report is None else len(report.reachable),
            "frontier_cells": None if report is None else report.frontier_cells,
            "goal": None
            if self._goal is None
            else {"x": round(self._goal[0], 3), "y": round(self._goal[1], 3)},
            "goals_sent": self.goals_sent,
            "goals_reached": self.goals_reached,
            "goals_failed": self.goals_failed,
            "blacklisted": len(self.explorer.blacklist),
            "save_offered": ended_with_map and not pending and self.mapping.saved_map_id is None,
            "saved_map_id": self.mapping.saved_map_id,
        }

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None:
        if self.state == ExplorationState.IDLE and not self._start_pending:
            return None
        extras: dict[str, Any] = {"exploration": self.status()}
        if self._frontier_points is not None and self.state == ExplorationState.EXPLORING:
            extras["frontiers"] = self._frontier_points
            if self._goal is not None:
                extras["frontier_goal"] = self._goal
        return {"extras": extras}

    def close(self) -> None:
        pass


def setup(runtime: Runtime) -> Exploration | None:
    mapping = runtime.find_feature(Mapping)
    navigation = runtime.find_feature(Navigation)
    if mapping is None or navigation is None:
        log.warning("exploration needs the mapping and navigation features")
        return None
    exploration = Exploration(runtime.session, mapping, navigation)
    runtime.session.add_stage(exploration)
    return exploration
