"""Feature: click-to-navigate (Nav2 ``bt_navigator`` + ``planner_server`` + ``controller_server``).

Per tick, after localization: the rolling local costmap (3 x 3 m, Nav2's local costmap) takes the
new scan, the global costmap (static + obstacle + inflation, from the active map) takes one at its
``global_update_period``, plan results from the worker pool are handed to the ``Navigator``, and the
navigator ticks once with the localized pose. Its command is what the NAVIGATING command source
returns; its outcome puts the robot back in IDLE with a ``navigation`` event (reached / failed with
the typed reason / cancelled).

Planning runs on ``session.workers`` (``request_plan`` -> future -> ``deliver_plan`` on the loop
thread). With a virtual clock the loop waits for the future in the same tick, so a simulated run is
deterministic for a seed however fast the machine is.

Navigate while mapping. In MAPPING a goal drives the robot without leaving the mode (one mapping
session, one recorded run): the costmaps are rebuilt from each map SLAM publishes (about 1 Hz,
``Mapping.add_grid_listener``), SLAM's pose localizes (AMCL is off in MAPPING), the MAPPING command
source drives while such a request runs, and an operator's teleop input cancels it (the operator
took over). A stuck request recovers there too (the same recovery tree), without leaving MAPPING:
the policy's command is the MAPPING command source's while it runs (entering RECOVERING would end
the mapping session); no behaviour there touches AMCL, which stays off.

Recovery hook: when the navigator is STUCK and a ``RecoveryPolicy`` is installed
(``feature.recovery = policy``), the mode goes to RECOVERING and the policy drives until it says it
is done, then the navigator resumes. Without one the navigator's ``stuck_timeout`` fails the goal.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from enum import StrEnum
from functools import partial
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np

from app.features.localization import Localization
from app.features.mapping import Mapping
from app.modes import Mode, TransitionRefused
from nav.behaviors import BehaviorContext, Status
from nav.behaviors.base import BehaviorLimits
from nav.control import GoalChecker, ProgressChecker
from nav.control.teb import TebController
from nav.costmap import Costmap2D, CostmapOptions, InflationOptions, inflation_cost, local_costmap_options
from nav.localization.divergence import DivergenceMonitor, DivergenceOptions
from nav.navigator import TERMINAL, Navigator, NavigatorOptions, check_controller_name
from nav.planning import PlannerOptions, make_planner, nearest_free_pose
from nav.planning.errors import PlannerError
from nav.recovery import RecoveryPolicy as Nav2RecoveryPolicy
from nav.recovery import Trigger
from nav.types import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    ZERO_TWIST,
    Costmap,
    GridGeometry,
    OccupancyGrid,
    Path,
    Pose2D,
    Twist2D,
    wrap_angle,
)
from nav.walkers import MAX_SCAN_GAP, PERSON_RADIUS, WalkerTracker, near_points
from nav.warmup import warm_up_navigation

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session
    from nav.navigator import NavTick, PlanRequest
    from robot.base import SensorFrame

ORDER = 40
log = logging.getLogger("navdeck.navigation")


class GoalRejected(ValueError):
    """A goal the costmap refuses (422): ``reason`` names why, ``nearest_free`` suggests a pose."""

    def __init__(self, reason: str, goal: Pose2D, nearest_free: Pose2D | None, index: int = 0) -> None:
        where = f"goal {index + 1}" if index else "goal"
        super().__init__(f"{where} ({goal.x:.2f}, {goal.y:.2f}) is {reason}")
        self.reason = reason
        self.goal = goal
        self.nearest_free = nearest_free
        self.index = index

    def as_dict(self) -> dict[str, Any]:
        nf = self.nearest_free
        return {
            "detail": str(self),
            "reason": self.reason,
            "index": self.index,
            "nearest_free": None if nf is None else {"x": nf.x, "y": nf.y, "theta": nf.theta},
        }


class StopReason(StrEnum):
    """Why a navigation request was cancelled (issue 22 item 6: each cause is told apart)."""

    OPERATOR_CANCEL = "operator_cancel"  # an explicit cancel (API, dashboard)
    ESTOP = "estop"  # the e-stop latched
    FAULT = "fault"  # a fault stopped the robot
    SUPERSEDED = "superseded"  # a new request replaced it
    MODE_CHANGE = "mode_change"  # a mode request (teleop, mapping...) took the robot
    MAP_CHANGED = "map_changed"  # the active map changed under it
    TELEOP = "teleop"  # the operator drove by hand while a goal ran in MAPPING


@dataclass(frozen=True)
class StopCause:
    """Who ended a request and why: ``actor`` is the user name for an API call, ``robot`` for a fault."""

    reason: StopReason
    actor: str
    message: str = ""

    def as_dict(self) -> dict[str, str]:
        return {"reason": self.reason.value, "actor": self.actor, "message": self.message}


@dataclass
class _Request:
    """One navigation request (a mission): all its goals, and how many were reached already."""

    id: int
    goals: list[Pose2D]
    reached: int = 0  # goals reached so far (absolute indices below this are done)
    base: int = 0  # absolute index of the navigator's goal 0 (a request extended by a click)


NavListener = Callable[[str, int, dict[str, Any]], None]
"""``(kind, request_id, data)`` on the loop thread: kind ``started`` | ``progress`` | ``extended`` |
``ended`` (data: ``outcome``, ``goals``...). Listeners must be quick and never raise."""


class NavigationRefused(RuntimeError):
    """Navigation is not possible now (409): not localized, e-stop, fault, mode refuses."""

    def __init__(self, detail: str, mode: str, allowed: list[str] | None = None) -> None:
        super().__init__(detail)
        self.mode = mode
        self.allowed = allowed or []

    def as_dict(self) -> dict[str, Any]:
        return {"detail": str(self), "mode": self.mode, "allowed": self.allowed}


class RecoveryPolicy(Protocol):
    """Hook for recovery behaviours (Nav2's recovery subtree): spin, back up, clear costmaps..."""

    def start(self, feature: Navigation, reason: str, now: float) -> bool:
        """Begin recovering from ``reason`` (the navigator's stuck reason); False: nothing to try."""
        ...

    def tick(self, feature: Navigation, now: float) -> tuple[Twist2D | None, bool]:
        """(command, finished) for this cycle while in RECOVERING."""
        ...


_TRIGGERS = {
    "NoProgress": "no_progress",
    "Stalled": "no_progress",
    "PatienceExceeded": "controller_failure",
    "NoValidControl": "controller_failure",
    "LocalizationDiverged": "localization_divergence",
    "SafetyStop": "safety_stop",
}


class BehaviorRecovery:
    """``RecoveryPolicy`` hook over ``nav.recovery.RecoveryPolicy`` (Nav2's default tree: round robin
    clear local -> clear global -> spin -> wait -> back up, ``number_of_retries`` per goal).

    The behaviours get the localized pose and the local costmap, both in the map frame (one frame is
    all they need: they measure their own motion and check collisions in it). Every attempt and
    result becomes a ``recovery`` event."""

    def __init__(self, options: Any = None) -> None:
        self._feature: Navigation | None = None
        self.policy = Nav2RecoveryPolicy(options, on_event=self._event)

    def _event(self, ev: Any) -> None:
        if self._feature is not None:
            self._feature.session.add_event("recovery", **ev.as_dict())
            if ev.kind == "attempt":  # the 3D view marks where each attempt started
                self._feature.mark_recovery(ev.behavior)

    def _ctx(self, feature: Navigation, now: float) -> Any:
        s = feature.session
        return BehaviorContext(
            now=now,
            pose=s.pose,
            velocity=s.velocity,
            costmap=feature.local_costmap,
            footprint=np.asarray(feature.profile.footprint, dtype=float)
            if feature.profile.footprint
            else None,
            limits=BehaviorLimits.from_profile(feature.profile),
            scan_match_score=lambda: feature.localization.match_score,
            clear_local_costmap=feature.clear_local_costmap,
            clear_global_costmap=feature.clear_global_costmap,
            reinitialize_localization=feature.localization.reinitialize,
            walker_on_path=lambda: feature.walker_on_path(now),
        )

    def reset(self) -> None:
        """A new request: the full retry budget again."""
        self.policy.reset()

    def start(self, feature: Navigation, reason: str, now: float) -> bool:
        self._feature = feature
        trigger = Trigger(_TRIGGERS.get(reason, "planner_failure"))
        return self.policy.on_failure(trigger, self._ctx(feature, now), reason) is not None

    def tick(self, feature: Navigation, now: float) -> tuple[Twist2D | None, bool]:
        if self.policy.active is None:  # finished (or failed) right at start
            return ZERO_TWIST, True
        status = self.policy.tick(self._ctx(feature, now))
        return self.policy.command, status is not Status.RUNNING


@dataclass(frozen=True)
class NavigationOptions:
    """Options of the navigation stage; the algorithms' own options come from their dataclasses."""

    planner: Literal["astar", "dijkstra"] = "astar"
    """Global planner plugin (Nav2 ``planner_plugins``): ``astar`` or ``dijkstra`` (NavFn)."""
    inflation_radius: float = 0.55
    """Inflation radius (m) of both costmaps (Nav2 ``inflation_layer.inflation_radius`` 0.55)."""
    cost_scaling_factor: float = 3.0
    """Exponential decay rate of inflated cost (Nav2 ``cost_scaling_factor``, default 3.0 in
    the global costmap of nav2_params.yaml, 10.0 in the plugin)."""
    local_width: float = 3.0
    """Rolling local costmap width (m), Nav2 default 3."""
    local_height: float = 3.0
    """Rolling local costmap height (m), Nav2 default 3."""
    local_static_layer: bool = True
    """Include the map in the local costmap too (Nav2's default local costmap has no static layer;
    with it the controller keeps off walls the lidar cannot see, e.g. below ``range_min``)."""
    track_unknown_space: bool = True
    """Global costmap keeps unknown cells 255 (Nav2 name and global default); see docs/navigation.md."""
    local_track_unknown_space: bool = True
    """Local costmap keeps cells the lidar has not observed 255 and both controllers treat them as
    lethal: the robot never drives (nor reverses) into space not seen unless the map says it is free.
    Nav2's local default is false."""
    observation_max_age: float = 10.0
    """Seconds after which a free local-costmap cell not observed again returns to unknown."""
    allow_unknown: bool = True
    """The planner may cross unknown cells (Nav2 NavFn/Smac ``allow_unknown``)."""
    unknown_cost: int = 255
    """The planner's cost (0..255) of an unknown cell (``PlannerOptions.unknown_cost``)."""
    allow_unknown_goals: bool = False
    """Accept goals in unknown space; a request's ``allow_unknown`` overrides it for itself."""
    gap_margin: float = 0.05
    """Metres beyond the inscribed radius a path keeps from obstacles: gaps narrower than twice
    (inscribed radius + margin) are not planned through (``PlannerOptions.max_cost``)."""
    live_map_occupied_threshold: int = 65
    """Occupancy (0..100) from which a cell of SLAM's live map is lethal in the costmaps' static
    layer while mapping (map_server's ``occupied_thresh`` 0.65, as a saved map is thresholded; the
    frontier search reads the map the same way). The live map holds probabilities, so its walls
    stay below the static layer's ``lethal_cost_threshold`` 100 for a loaded map: with that
    threshold the global costmap had no walls, and paths went through them."""
    global_update_period: float = 1.0
    """Seconds between obstacle-layer updates of the global costmap (Nav2 ``update_frequency`` 1 Hz)."""
    goal_search_radius: float = 3.0
    """How far (m) from a refused goal to look for the nearest free pose to suggest."""
    costmap_view: Literal["global", "local"] = "global"
    """Which costmap the 3D view shows as ``extras["costmap"]``."""
    wait_for_plans: bool | None = None
    """Block the tick until a requested plan is back; None: only with a virtual clock."""
    warm_up: bool | None = None
    """Compile (or load from numba's cache) the costmap, planner and controller kernels on a worker
    at start-up (``nav.warmup``), so the first goal neither waits for the planner to compile nor
    stalls the loop while DWA compiles; None: only with a real clock (a simulated run on a virtual
    clock waits for nobody, and its CPU figures would count the warm-up)."""
    controller: Literal["dwa", "teb"] | None = None
    """Default local controller (Nav2 ``controller_plugins``); None: the profile's ``controller``.
    A goal request may pick the other one for itself."""
    dwa_overrides: dict[str, Any] = field(default_factory=dict)
    """DwaOptions fields over the profile-derived ones."""
    teb_overrides: dict[str, Any] = field(default_factory=dict)
    """TebOptions fields over the profile-derived ones."""
    recovery: bool = True
    """Install ``BehaviorRecovery`` (Nav2's recovery subtree) as the recovery hook."""
    divergence: DivergenceOptions = field(default_factory=DivergenceOptions)
    """When the robot counts as lost while navigating: it stops and the ``localization_divergence``
    recovery list runs (spin until matched, then relocalize over the whole map)."""
    jump_distance: float = 0.5
    """A change of the map -> odom correction larger than this (m) between two ticks means the
    estimate jumped (AMCL found the robot elsewhere): the obstacle layers are cleared, as after an
    initial pose (the filter corrects a few cm per update while tracking)."""
    jump_angle: float = 0.5
    """The same for the heading (rad)."""
    walker_path_margin: float = 0.3
    """Metres beyond touching (robot's circumscribed radius + a walker's body) at which a tracked
    walker counts as on the path when navigation fails (then the robot waits for it, see
    ``RecoveryOptions.walker_wait``)."""
    safety_stop_timeout: float = 5.0
    """Seconds the safety layer may hold the robot (every command toward an obstacle stopped)
    while navigating before the ``safety_stop`` recovery list runs; 0: never (then the progress
    checker's 10 s decide, as in Nav2)."""


class Navigation:
    """The navigation stage. ``set_goals`` / ``cancel`` are thread-safe (API, viewer clicks)."""

    def __init__(
        self,
        session: Session,
        localization: Localization,
        options: NavigationOptions | None = None,
    ) -> None:
        self.session = session
        self.localization = localization
        self.options = o = options or NavigationOptions()
        self.profile = session.profile
        self.planner = make_planner(o.planner, self._planner_options())
        self.navigator = Navigator.for_robot(
            self.profile,
            None,
            NavigatorOptions(nominal_speed=self.profile.limits.max_vel_x),
            request_plan=self._request_plan,
            goal_checker=GoalChecker(),
            progress_checker=ProgressChecker(),
            controller=o.controller,
            teb_overrides=self._controller_overrides("teb"),
            **self._controller_overrides("dwa"),
        )
        self.navigator.path_on_map_alone = self._path_on_map_alone
        self.default_controller = self.navigator.controller_name
        virtual = bool(getattr(session.clock, "is_virtual", False))
        self._wait = virtual if o.wait_for_plans is None else o.wait_for_plans
        self._lock = threading.Lock()
        self._pending: list[tuple[str, Any]] = []
        self._futures: list[tuple[int, Future]] = []
        self._cmd: Twist2D | None = ZERO_TWIST
        self._last_tick: NavTick | None = None
        self.last_outcome: dict[str, Any] | None = None
        self.recovery: RecoveryPolicy | None = BehaviorRecovery() if o.recovery else None
        self.recoveries = 0
        self.plans = 0
        self._global = None
        self._global_cm: Costmap | None = None
        self._local = None
        self._local_cm: Costmap | None = None
        self._costmap_version = 0
        # keepout filter mask (bool over its geometry: the active map's), from the zones feature; set
        # at once for goal checks, applied to the costmaps by the loop (a "keepout" pending item)
        self._keepout: tuple[np.ndarray, GridGeometry] | None = None
        self._last_global_update = -math.inf
        # walkers in the map frame, for a controller that predicts them (TEB's dynamic obstacles)
        self.walkers = WalkerTracker()
        self._seen_resets = 0
        self.costmap_view: str = o.costmap_view  # "global" | "local": which one the 3D view shows
        self._active = False
        self._request: _Request | None = None
        self._next_id = 0
        self._cause: StopCause | None = None
        self._listeners: list[NavListener] = []
        self._waypoints: tuple[tuple[Pose2D, ...], np.ndarray] | None = None
        # (x, y, theta, behaviour) where each recovery attempt of the current request started; a new
        # tuple on each change so the viewer can tell by identity
        self._recovery_marks: tuple[tuple[float, float, float, str], ...] = ()
        self.divergence = DivergenceMonitor(o.divergence)
        self._seen_updates = 0  # localization updates already given to the divergence monitor
        self._safety_stop_since: float | None = None
        self._last_map_to_odom = session.map_to_odom
        self.mapping: Mapping | None = None  # the mapping feature, when set up: goals while it runs
        self._live_generation: int | None = None  # mapping session whose live map the costmaps hold
        self._in_mapping = False  # the running request drives in MAPPING
        self._mapping_recovery = False  # a recovery runs for it (MAPPING has no RECOVERING mode)
        self.live_grid: OccupancyGrid | None = None  # the SLAM map the costmaps were built from
        self._build_costmaps(localization.grid)
        localization.add_map_listener(self._on_map)
        session.set_command_source(Mode.NAVIGATING, self._command)
        session.set_command_source(Mode.RECOVERING, self._recovery_command)
        session.set_command_source(Mode.MAPPING, self._command)
        session.mapping_autonomy = lambda: self._active and self._in_mapping
        session.modes.set_guard(Mode.NAVIGATING, self._guard)
        self._recovery_cmd: Twist2D | None = ZERO_TWIST
        warm = not virtual if o.warm_up is None else o.warm_up
        self.warmed_up: Future | None = session.workers.submit(self._warm_up) if warm else None
        """The start-up warm-up's job: seconds per stage (``nav.warmup.warm_up_navigation``)."""

    # ------------------------------------------------------------------ costmaps
    def _warm_up(self) -> dict[str, float]:
        grid = self.localization.grid
        o = self.options
        try:
            timings = warm_up_navigation(
                self.profile,
                o.planner,
                self._costmap_options(False),
                self._costmap_options(True),
                grid.resolution if grid is not None else 0.05,
                {"dwa": self._controller_overrides("dwa"), "teb": self._controller_overrides("teb")},
            )
        except Exception:  # a failed warm-up costs only time: the first goal compiles instead
            log.exception("navigation warm-up failed")
            return {}
        log.info("navigation kernels ready: %s", ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
        return timings

    def _controller_overrides(self, name: str) -> dict[str, Any]:
        """The options' overrides of one controller, with unknown cells lethal when the local
        costmap tracks unknown space (an explicit ``unknown_is_lethal`` override wins)."""
        o = self.options
        given = o.dwa_overrides if name == "dwa" else o.teb_overrides
        return {"unknown_is_lethal": o.local_track_unknown_space, **given}

    def _planner_options(self):
        o = self.options
        infl = InflationOptions(o.inflation_radius, o.cost_scaling_factor)
        inscribed = self.profile.inscribed_radius
        grid = self.localization.grid
        half_cell = 0.5 * (grid.resolution if grid is not None else 0.05)
        limit = 252  # Nav2's rule: anything below the inscribed cost
        if o.gap_margin > 0:
            # Inflation measures from obstacle cell centres, half a cell behind the obstacle's edge:
            # a centre nearer than inscribed + margin to that edge costs more than this, blocked.
            clearance = inscribed + o.gap_margin + half_cell
            limit = min(limit, int(inflation_cost(clearance, inscribed, infl)))
        return PlannerOptions(allow_unknown=o.allow_unknown, unknown_cost=o.unknown_cost, max_cost=limit)

    def _costmap_options(self, rolling: bool, live: bool = False) -> CostmapOptions:
        """Options of the local (``rolling``) or global costmap; ``live``: over SLAM's live map."""
        opts = self._layer_options(rolling)
        if not live:
            return opts
        static = replace(opts.static_layer, lethal_cost_threshold=self.options.live_map_occupied_threshold)
        return replace(opts, static_layer=static)

    def _layer_options(self, rolling: bool) -> CostmapOptions:
        fp = tuple(self.profile.footprint)
        radius = self.profile.robot_radius if self.profile.robot_radius > 0 else 0.1
        infl = InflationOptions(
            inflation_radius=self.options.inflation_radius,
            cost_scaling_factor=self.options.cost_scaling_factor,
        )
        if rolling:
            return local_costmap_options(
                width=self.options.local_width,
                height=self.options.local_height,
                footprint=fp,
                robot_radius=radius,
                use_static_layer=self.options.local_static_layer,
                inflation_layer=infl,
                track_unknown_space=self.options.local_track_unknown_space,
                observation_max_age=self.options.observation_max_age,
            )
        return CostmapOptions(
            footprint=fp,
            robot_radius=radius,
            inflation_layer=infl,
            track_unknown_space=self.options.track_unknown_space,
        )

    def _build_costmaps(self, grid: OccupancyGrid | None, live: bool = False) -> None:
        if grid is None:
            self._global = self._local = None
            self._global_cm = self._local_cm = None
            return
        lo = replace(self._costmap_options(True, live), resolution=grid.resolution)
        self._global = Costmap2D.from_map(grid, self._costmap_options(False, live))
        self._global_cm = self._global.costmap()
        self._local = Costmap2D.rolling(lo, self.session.pose, grid)
        self._local_cm = self._local.costmap()
        self._costmap_version += 1

    def set_keepout(self, mask: np.ndarray | None, geometry: GridGeometry) -> None:
        """Keepout filter over the active map (any thread; applied at the next tick): planners never
        route through the true cells of ``mask`` and the controller never enters them. Goals inside
        are refused from now on."""
        keepout = None if mask is None else (mask, geometry)
        with self._lock:
            self._keepout = keepout
            self._pending.append(("keepout", keepout))

    def _apply_keepout(self, keepout: tuple[np.ndarray, GridGeometry] | None) -> None:
        if self._global is None or self._local is None:
            return
        mask, geo = keepout if keepout is not None else (None, None)
        self._global.set_keepout(mask, geo)
        self._local.set_keepout(mask, geo)
        self._global_cm = self._global.costmap()
        self._local_cm = self._local.costmap()
        self._costmap_version += 1

    def in_keepout(self, x: float, y: float) -> bool:
        """Is the map point inside the keepout filter mask?"""
        keepout = self._keepout
        if keepout is None:
            return False
        mask, geo = keepout
        rows, cols = geo.world_to_cell(np.array([x, y]))
        return bool(geo.in_bounds(rows, cols)[0] and mask[rows[0], cols[0]])

    def _on_map(self, grid: OccupancyGrid, map_id: int | None) -> None:
        with self._lock:
            self._pending.append(("map", grid))

    def on_live_map(self, grid: OccupancyGrid, generation: int) -> None:
        """A map SLAM published while mapping (any thread): the costmaps follow it next tick,
        without ending a goal that runs (navigate while mapping)."""
        with self._lock:
            self._pending.append(("live", (grid, generation)))

    def mapping_live(self) -> bool:
        """Mapping runs and the costmaps hold its latest map: goals may be sent in MAPPING."""
        m = self.mapping
        return (
            m is not None
            and m.running
            and self._live_generation == m.generation
            and self.session.modes.mode == Mode.MAPPING
        )

    def _apply_live_map(self, grid: OccupancyGrid, generation: int) -> None:
        """Rebuild both costmaps over the grown map (its geometry changes as SLAM extends it). The
        local costmap keeps its obstacle layer: marks of what the map does not hold yet (a chair leg
        the lidar saw) must not vanish until a scan sees them again (Nav2 keeps them too)."""
        m = self.mapping
        if m is None or not m.running or generation != m.generation:
            return  # stale: a map of a session that has ended
        old_local = self._local
        self._build_costmaps(grid, live=True)
        if old_local is not None and self._local is not None:
            self._local.keep_observations(old_local)
            self._local_cm = self._local.costmap()
        self.live_grid = grid
        self._live_generation = generation

    @property
    def global_costmap(self) -> Costmap | None:
        """The latest global costmap snapshot (immutable once published)."""
        return self._global_cm

    @property
    def local_costmap(self) -> Costmap | None:
        return self._local_cm

    # ------------------------------------------------------------------ requests (any thread)
    def check_goal(self, goal: Pose2D, index: int = 0, allow_unknown: bool | None = None) -> None:
        """Raise ``GoalRejected`` for a goal off the map, in an obstacle, inside the inscribed radius
        of one, or in unknown space (unless ``allow_unknown``, default the option
        ``allow_unknown_goals``); the error carries the nearest traversable pose."""
        cm = self._global_cm
        if cm is None:
            raise NavigationRefused("no active map: choose a map first", self.session.modes.mode.value)
        if not goal.is_finite():
            raise GoalRejected("not a finite pose", goal, None, index)
        geo = cm.geometry
        rows, cols = geo.world_to_cell(np.array([goal.x, goal.y]))
        r = self.options.goal_search_radius
        if not geo.in_bounds(rows, cols)[0]:
            w, h = geo.size_m
            o = geo.origin
            inside = Pose2D(
                float(np.clip(goal.x, o.x, o.x + w - 1e-6)),
                float(np.clip(goal.y, o.y, o.y + h - 1e-6)),
                goal.theta,
            )
            raise GoalRejected("off the map", goal, nearest_free_pose(cm, inside, r), index)
        if self.in_keepout(goal.x, goal.y):
            raise GoalRejected("inside a keepout zone", goal, nearest_free_pose(cm, goal, r), index)
        cost = int(cm.costs[rows[0], cols[0]])
        reason = {
            LETHAL_OBSTACLE: "inside an obstacle",
            INSCRIBED_INFLATED_OBSTACLE: "inside the inscribed radius of an obstacle",
            NO_INFORMATION: 'in unknown space (allow_unknown is off: in the 3D view click a "goal in '
            'unknown space", or send allow_unknown: true with the goal, or set allow_unknown_goals)',
        }.get(cost)
        if cost == NO_INFORMATION and (
            self.options.allow_unknown_goals if allow_unknown is None else allow_unknown
        ):
            return
        if reason is not None:
            raise GoalRejected(reason, goal, nearest_free_pose(cm, goal, r), index)

    def add_listener(self, listener: NavListener) -> None:
        """Be told of request starts, waypoint progress and ends (``NavListener``)."""
        self._listeners.append(listener)

    def _notify(self, kind: str, request_id: int, **data: Any) -> None:
        for fn in self._listeners:
            try:
                fn(kind, request_id, data)
            except Exception:  # a listener must not stop the control loop
                log.exception("navigation listener failed")

    def set_goals(
        self,
        goals: Sequence[Pose2D],
        controller: str | None = None,
        *,
        actor: str = "operator",
        allow_unknown: bool | None = None,
    ) -> int:
        """Validate ``goals`` (raises GoalRejected / NavigationRefused) and start navigating through
        them in order; replaces (supersedes) the current request. ``controller`` ("dwa" | "teb")
        drives this request only; None: the default one (``NavigationOptions.controller`` or the
        profile's). ``actor`` names who asked (the cause of the superseded request's end). Returns
        the new request's id. ``allow_unknown`` accepts goals in unknown space for this request
        (None: the option ``allow_unknown_goals``)."""
        return self._submit(list(goals), controller, actor, extends=None, allow_unknown=allow_unknown)

    def _submit(
        self,
        goals: list[Pose2D],
        controller: str | None,
        actor: str,
        extends: int | None,
        allow_unknown: bool | None = None,
    ) -> int:
        if not goals:
            raise GoalRejected("missing", Pose2D(), None)
        if controller is not None:
            check_controller_name(controller)
        mode = self.session.modes.mode
        if mode in (Mode.ESTOP, Mode.FAULT) or self.session.estop_latched:
            raise NavigationRefused(f"cannot navigate in mode {mode.value} (reset first)", mode.value)
        in_mapping = mode == Mode.MAPPING
        if in_mapping:
            why = self._mapping_guard()
        else:  # a robot without a lidar says so first, not "not localized"
            why = self.session.modes.unavailable().get(Mode.NAVIGATING.value) or self._guard()
        if why:
            raise NavigationRefused(why, mode.value, self.session.modes.allowed())
        # an extension checks only the goal it adds: the earlier ones were accepted with their own
        # allow_unknown (a plain click after a "goal in unknown space" one must not refuse that one)
        first = len(goals) - 1 if extends is not None else 0
        for i in range(first, len(goals)):
            self.check_goal(goals[i], i, allow_unknown)
        if not in_mapping:
            try:  # mode first: the loop never sees goals without the mode that drives them
                self.session.modes.request(Mode.NAVIGATING, "navigation goal")
            except TransitionRefused as exc:
                raise NavigationRefused(exc.reason, exc.current.value, exc.allowed) from None
        chosen = controller or self.default_controller
        with self._lock:
            if extends is None:
                self._next_id += 1
                rid = self._next_id
            else:
                rid = extends
            self._pending.append(("goals", (goals, chosen, rid, actor, extends is not None, in_mapping)))
        if extends is None:
            self.session.add_event(
                "navigation",
                status="goal accepted",
                goals=[[g.x, g.y, g.theta] for g in goals],
                controller=chosen,
            )
        # the goal list of the run: each goal once (an extension adds only the clicked one); the
        # outcomes of a superseded request's goals come before this request's, so they pair in order
        self._announce(goals if extends is None else goals[-1:])
        return rid

    def add_goal(self, goal: Pose2D, allow_unknown: bool | None = None) -> None:
        """Queue ``goal`` after the current ones (a click in the 3D view); starts navigating if idle.
        Extends the current request (same id, its earlier goals are not announced or checked
        again). ``allow_unknown`` as in ``set_goals`` (the view's "goal in unknown space" click),
        for this goal only."""
        with self._lock:
            requests = [arg for kind, arg in self._pending if kind == "goals"]
        if requests:  # not picked up by the loop yet: extend the latest one
            goals, controller, rid, actor, *_ = requests[-1]
            self._submit([*goals, goal], controller, actor, extends=rid, allow_unknown=allow_unknown)
            return
        req = self._request
        if self._active and req is not None:
            current = self.navigator.goals[self._goal_index() :]
            self._submit(
                [*current, goal],
                self.navigator.controller_name,
                "operator",
                extends=req.id,
                allow_unknown=allow_unknown,
            )
            return
        self.set_goals([goal], allow_unknown=allow_unknown)

    def _goal_index(self) -> int:
        tick = self._last_tick
        return tick.feedback.goal_index if tick is not None else 0

    def cancel(self, actor: str = "operator", reason: StopReason = StopReason.OPERATOR_CANCEL) -> bool:
        """Cancel navigation (outcome ``cancelled`` next tick, with ``reason`` and ``actor``). False if
        nothing was running."""
        with self._lock:
            running = self._active or any(k == "goals" for k, _ in self._pending)
            self._pending.append(("cancel", StopCause(reason, actor)))
        return running

    def pending_request(self) -> int | None:
        """The id of a request accepted but not yet picked up by the loop (None if none)."""
        with self._lock:
            for kind, arg in reversed(self._pending):
                if kind == "goals":
                    return arg[2]
                if kind == "cancel":
                    return None
        return None

    @property
    def request_id(self) -> int | None:
        """The id of the request running now (None when idle)."""
        req = self._request
        return req.id if req is not None and self._active else None

    @property
    def current_request(self) -> int | None:
        """The request a cancel now would stop: one accepted but not picked up yet, else the running one."""
        return self.pending_request() or self.request_id

    def _mapping_guard(self) -> str | None:
        """Why a goal cannot be sent in MAPPING now (None: it can)."""
        m = self.mapping
        if m is None:
            return "this server has no mapping feature"
        if not self.mapping_live():
            return "the map is still being built: wait a second for SLAM's first map, then send the goal"
        return None

    def _guard(self) -> str | None:
        if not self.localization.localized:
            return self.localization.not_localized_reason
        if self._global_cm is None:
            return "no active map"
        return None

    # ------------------------------------------------------------------ the stage (loop thread)
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        with self._lock:
            pending, self._pending = self._pending, []
        for kind, arg in pending:
            if kind == "map":
                self._cause = StopCause(StopReason.MAP_CHANGED, "operator", "active map changed")
                self._abort("active map changed", now)
                self._build_costmaps(arg)
                self._live_generation = self.live_grid = None
            elif kind == "keepout":
                self._apply_keepout(arg)
            elif kind == "live":
                self._apply_live_map(*arg)
            elif kind == "goals":
                goals, controller, rid, actor, extends, in_mapping = arg
                req = self._request
                if extends and self._active and req is not None and req.id == rid:
                    # a click appended a goal: same request, the reached ones stay reached
                    req.base = req.reached
                    req.goals.extend(goals[len(req.goals) - req.base :])
                    self.navigator.select_controller(controller)
                    self.navigator.set_goals(goals)
                    self._futures.clear()
                    self._notify("extended", rid, goals=list(req.goals))
                    continue
                if self._active and req is not None:
                    self._supersede(req, actor, rid, now)
                self._request = _Request(rid, list(goals))
                self._cause = None
                if extends:  # the request it extended ended meanwhile: its earlier goals run again
                    self._announce(goals[:-1])
                self.navigator.select_controller(controller)  # resets it: a fresh band / window
                self.navigator.set_goals(goals)
                if self.recovery is not None and hasattr(self.recovery, "reset"):
                    self.recovery.reset()
                self.last_outcome = None  # the outcome of *this* request, once it ends
                self._watch_reset()
                self._recovery_marks = ()  # markers are kept for the current navigation only
                self._futures.clear()
                self._active = True
                self._in_mapping = in_mapping
                self._mapping_recovery = False
                self._notify("started", rid, goals=list(goals))
            elif kind == "cancel" and self._active:
                self._cause = arg
                self.navigator.cancel()
                self._mapping_recovery = False  # the navigator reports it on its next tick
                if session.modes.mode == Mode.RECOVERING:
                    session.modes.enter(Mode.NAVIGATING, "cancel during recovery")
        if self._global is None or self._local is None:
            self._cmd = None
            return
        self._update_costmaps(session, frame, now)
        self._track_walkers(session, frame, now)
        mode = session.modes.mode
        driving_modes = (Mode.MAPPING,) if self._in_mapping else (Mode.NAVIGATING, Mode.RECOVERING)
        if self._active and mode not in driving_modes:
            if self._cause is None:
                self._cause = self._mode_cause(mode)
            self.navigator.cancel()  # the operator took over, e-stop, fault...
            self._mapping_recovery = False
        elif self._active and self._in_mapping and session.teleop_engaged(now):
            if self._cause is None:
                self._cause = StopCause(StopReason.TELEOP, "operator", "the operator drove by hand")
            self.navigator.cancel()
            self._mapping_recovery = False
        if not self._active:
            self._cmd = ZERO_TWIST
            return
        if mode == Mode.RECOVERING or self._mapping_recovery:
            self._lost()
            self._tick_recovery(now)
            return
        self._collect_plans()
        tick = self.navigator.tick(now, session.pose, session.velocity, self._global_cm, self._local_cm)
        if tick.outcome is None and tick.state in TERMINAL and self.navigator.outcome is not None:
            # a plan failure delivered before the tick ends the request without a fresh NavTick
            tick = replace(tick, outcome=self.navigator.outcome)
        self._last_tick = tick
        self._cmd = tick.cmd
        self._progress(tick.feedback.goal_index)
        if tick.outcome is not None:
            self._finish(tick, now)
            return
        if tick.state.value != "stuck" and mode == Mode.NAVIGATING:
            self._watch(session, now)
        if self.navigator.state.value == "stuck" and mode == Mode.NAVIGATING:
            self._blame_localization()
            self._maybe_recover(self.navigator.stuck_reason, now)
        elif self.navigator.state.value == "stuck" and self._in_mapping:
            # SLAM localizes: no AMCL to blame; a wall under the footprint is SLAM's to fix
            self._maybe_recover(self.navigator.stuck_reason, now)

    def _mode_cause(self, mode: Mode) -> StopCause:
        why = self.session.modes.reason
        if mode == Mode.ESTOP:
            source = why.removeprefix("e-stop by ").strip() or "operator"
            return StopCause(StopReason.ESTOP, source, why)
        if mode == Mode.FAULT:
            return StopCause(StopReason.FAULT, "robot", self.session.fault or why)
        return StopCause(StopReason.MODE_CHANGE, "operator", f"mode changed to {mode.value}: {why}")

    def _announce(self, goals: Sequence[Pose2D]) -> None:
        """One typed ``goal`` event per goal, once: what run metrics and the run's goal list count."""
        for g in goals:
            self.session.add_event("goal", pose=[g.x, g.y, g.theta])

    def _progress(self, goal_index: int) -> None:
        """Waypoints passed since the last tick: one ``goal_reached`` each (the run's goal list)."""
        req = self._request
        if req is None:
            return
        reached = min(req.base + goal_index, len(req.goals))
        if reached > req.reached:
            for _ in range(reached - req.reached):
                self.session.add_event("goal_reached", reason="waypoint", message="")
            req.reached = reached
            self._notify("progress", req.id, goal_index=reached)

    def _close_goals(self, req: _Request, kind: str, reason: str, message: str) -> None:
        """End every goal of ``req`` not reached yet: the current one with ``kind``, the rest
        cancelled (never attempted), so the run's goal list has every waypoint once."""
        left = len(req.goals) - req.reached
        if kind == "reached":
            for _ in range(left):
                self.session.add_event("goal_reached", reason=reason, message=message)
            req.reached = len(req.goals)
            return
        typed = "goal_failed" if kind == "failed" else "goal_canceled"
        for i in range(left):
            if i == 0:
                self.session.add_event(typed, reason=reason, message=message)
            else:
                self.session.add_event("goal_canceled", reason="not_attempted", message=f"after {reason}")

    def _supersede(self, req: _Request, actor: str, new_id: int, now: float) -> None:
        """A new request replaces a running one: end the old one as cancelled, cause ``superseded``."""
        cause = StopCause(StopReason.SUPERSEDED, actor, f"replaced by request {new_id}")
        self.session.add_event(
            "navigation",
            status="cancelled",
            outcome="cancelled",
            goals_reached=req.reached,
            **cause.as_dict(),
        )
        self._close_goals(req, "cancelled", cause.reason.value, cause.message)
        self._notify(
            "ended",
            req.id,
            outcome={"kind": "cancelled", "goals_reached": req.reached},
            cause=cause.as_dict(),
        )

    def _track_walkers(self, session: Session, frame: SensorFrame, now: float) -> None:
        """Track walkers in the lidar's returns (map frame, placed like the costmaps' marks) and
        hand them, moved on to ``now``, to a controller that predicts them."""
        if not (self.localization.localized or self._active or self.mapping_live()):
            self.walkers.reset()
        elif frame.scan is not None:
            laser = session.pose.compose(self.localization.laser_pose)
            self.walkers.update(laser.transform_points(frame.scan.points()), frame.scan.stamp)
        teb = self.navigator.controller
        if not isinstance(teb, TebController):
            return
        age = now - self.walkers.stamp
        if 0.0 <= age <= MAX_SCAN_GAP:
            w = self.walkers
            teb.set_walkers(w.centres + w.velocities * age, w.velocities)
        else:
            teb.set_walkers(np.zeros((0, 2)), np.zeros((0, 2)))

    def walker_on_path(self, now: float) -> bool:
        """Whether a tracked walker (moved on to ``now``) is within the robot's circumscribed
        radius + a walker's body + ``walker_path_margin`` of the robot or of the path's next
        ``blocked_check_distance`` m: the failure is the walker's, and waiting for it is the
        recovery (``RecoveryOptions.walker_wait``)."""
        w = self.walkers
        age = now - w.stamp
        if not (0.0 <= age <= MAX_SCAN_GAP) or len(w.centres) == 0:
            return False
        pose = self.session.pose
        ahead = self.navigator.path_ahead(self.navigator.options.blocked_check_distance)
        points = np.vstack(([pose.x, pose.y], ahead))
        reach = self.profile.circumscribed_radius + PERSON_RADIUS + self.options.walker_path_margin
        return bool(near_points(w.centres + w.velocities * age, points, reach).any())

    def _blame_localization(self) -> None:
        """Stuck with the footprint on a wall of the map itself: no robot can stand there, so the
        estimate is wrong (a kidnapped robot the filter re-found a few decimetres off, fitting the
        scan well enough for the divergence monitor). Recover as lost: clearing costmaps, spinning or
        backing up all refuse or fail at a pose inside a wall."""
        reason = self.navigator.stuck_reason
        if reason in ("LocalizationDiverged", "SafetyStop") or self.localization.options.source != "amcl":
            return
        if self._global is not None and self._global.in_mapped_obstacle(self.session.pose):
            self.navigator.halt(
                "LocalizationDiverged",
                f"localization lost: stuck ({reason}) with the footprint on a wall of the map",
            )

    def _lost(self) -> bool:
        """Give the divergence monitor the localization updates since the last call (during
        recoveries too: a robot lost while backing off a phantom obstacle is still lost)."""
        loc = self.localization
        if loc.options.source != "amcl" or loc.updates == self._seen_updates:
            return False
        self._seen_updates = loc.updates
        return self.divergence.update(loc.quality, loc.spread_xy)

    def _watch(self, session: Session, now: float) -> None:
        """Causes of getting stuck the navigator cannot see: the robot is lost (the divergence
        monitor over localization updates), or the safety layer keeps stopping every command
        (``safety_stop_timeout``). Either halts the navigator, and recovery takes over."""
        if self._lost() or self.divergence.bad >= self.divergence.options.bad_updates:
            self.navigator.halt("LocalizationDiverged", self.divergence.reason)
            return
        status = getattr(session.safety, "status", None)
        timeout = self.options.safety_stop_timeout
        if timeout <= 0 or status is None or status.action != "stop":
            self._safety_stop_since = None
        elif self._safety_stop_since is None:
            self._safety_stop_since = now
        elif now - self._safety_stop_since >= timeout:
            self.navigator.halt(
                "SafetyStop", f"the safety layer held the robot for {timeout:g} s: {status.reason}"
            )

    def _watch_reset(self) -> None:
        self.divergence.reset()
        self._seen_updates = self.localization.updates
        self._safety_stop_since = None

    def _update_costmaps(self, session: Session, frame: SensorFrame, now: float) -> None:
        lp = self.localization.laser_pose
        pose = session.pose
        assert self._local is not None and self._global is not None
        loc = self.localization
        # where the correction moved the robot's estimate (same odometry pose, old vs new map -> odom)
        jump = session.map_to_odom.compose(session.odom_pose).relative_to(
            self._last_map_to_odom.compose(session.odom_pose)
        )
        self._last_map_to_odom = session.map_to_odom
        jumped = (
            math.hypot(jump.x, jump.y) > self.options.jump_distance
            or abs(jump.theta) > self.options.jump_angle
        )
        if loc.resets != self._seen_resets or jumped:
            # the pose jumped (initial pose, global reset, or the filter found the robot elsewhere
            # by itself): marks made from the old pose are in the wrong places
            if jumped and loc.resets == self._seen_resets:
                session.add_event(
                    "localization", status="estimate jumped", distance=round(math.hypot(jump.x, jump.y), 2)
                )
            self._seen_resets = loc.resets
            self.clear_costmaps()
        # scans placed with an unknown pose would mark obstacles in the wrong places; a running goal
        # keeps marking though: a crowd hiding the walls revokes ``localized`` (docs/localization.md)
        # while what the lidar sees around the robot is still where the controller must not go
        if not (loc.localized or self._active or self.mapping_live()):
            return
        if frame.scan is None:
            # The window follows the robot at scan rate (>= 5 Hz: a few cm of travel); moving it
            # without new data would only re-inflate the same cells every tick.
            return
        self._local.update_from_scan(pose, frame.scan, lp, stamp=now)
        self._local_cm = self._local.costmap()
        if now - self._last_global_update >= self.options.global_update_period:
            self._last_global_update = now
            self._global.update_from_scan(pose, frame.scan, lp)
            self._global_cm = self._global.costmap()
            self._costmap_version += 1

    def _path_on_map_alone(self, start: Pose2D, goal: Pose2D) -> bool:
        """Does the planner find a path on the global costmap without its sensed obstacles? (The
        navigator asks when a goal's first plan fails: a person in a doorway then blocks the way
        for a while, not for good.)"""
        if self._global is None:
            return False
        try:
            self.planner.plan(self._global.map_only(), start, goal)
        except PlannerError:
            return False
        return True

    def _request_plan(self, req: PlanRequest) -> None:
        self.plans += 1
        fut = self.session.workers.submit(self.planner.plan, req.costmap, req.start, req.goal)
        self._futures.append((req.id, fut))
        if self._wait:
            fut.exception()  # wait: deterministic under a virtual clock

    def _collect_plans(self) -> None:
        still = []
        for rid, fut in self._futures:
            if not fut.done():
                still.append((rid, fut))
                continue
            exc = fut.exception()
            self.navigator.deliver_plan(rid, exc if exc is not None else fut.result())
        self._futures = still

    def _finish(self, tick: NavTick, now: float) -> None:
        out = tick.outcome
        assert out is not None
        self._active = False
        self._mapping_recovery = False
        self._futures.clear()
        goals = self.navigator.goals
        # the goal it reached last, or the one it was heading for when it failed / was cancelled
        i = out.goals_reached - 1 if out.kind == "reached" else out.goals_reached
        goal = goals[min(max(i, 0), len(goals) - 1)] if goals else None
        cause = self._cause if out.kind == "cancelled" else None
        if out.kind == "cancelled" and cause is None:
            cause = StopCause(StopReason.OPERATOR_CANCEL, "operator", out.message)
        self._cause = None
        reason = cause.reason.value if cause is not None else out.reason
        message = cause.message if cause is not None and not out.message else out.message
        req = self._request
        self.last_outcome = {
            "kind": out.kind,
            "reason": reason,
            "message": message,
            "actor": None if cause is None else cause.actor,
            "request_id": None if req is None else req.id,
            "goals_reached": out.goals_reached,
            "t": round(now - self.session.started_at, 3),
            **self._tolerances(),
            **_offset(self.session.pose, goal),
        }
        self.session.add_event(
            "navigation",
            status={"reached": "goal reached", "failed": "navigation failed", "cancelled": "cancelled"}[
                out.kind
            ],
            outcome=out.kind,
            reason=reason,
            message=message,
            goals_reached=out.goals_reached,
            **({} if cause is None else {"actor": cause.actor}),
        )
        if req is not None:
            if out.kind != "reached":
                self._progress(out.goals_reached)  # waypoints passed in the last tick
            self._close_goals(req, out.kind, reason, message)
            self._notify(
                "ended",
                req.id,
                outcome=dict(self.last_outcome, goals_reached=req.reached),
                cause=None if cause is None else cause.as_dict(),
            )
        if out.kind == "failed" and isinstance(out.error, PlannerError):
            self.session.add_event("plan_failed", reason=out.reason)
        if self.session.modes.mode in (Mode.NAVIGATING, Mode.RECOVERING):
            self.session.modes.enter(Mode.IDLE, f"navigation {out.kind}")

    def _abort(self, reason: str, now: float) -> None:
        if self._active:
            self.navigator.cancel()
            tick = self.navigator.tick(now, self.session.pose, self.session.velocity, self._global_cm)
            if tick.outcome is not None:
                self._finish(tick, now)
            self._active = False

    def _maybe_recover(self, reason: str, now: float) -> None:
        """The recovery hook: hand a STUCK navigator to the policy (mode RECOVERING, or staying in
        MAPPING for a request sent there), if any."""
        if self.recovery is None or not self.recovery.start(self, reason, now):
            return
        self.recoveries += 1
        self.session.add_event("recovery", status="started", reason=reason)
        if self._in_mapping:
            self._mapping_recovery = True
        else:
            self.session.modes.enter(Mode.RECOVERING, f"recovering: {reason}")

    def _tick_recovery(self, now: float) -> None:
        assert self.recovery is not None
        cmd, done = self.recovery.tick(self, now)
        self._recovery_cmd = cmd
        if done:
            if self.navigator.stuck_reason == "LocalizationDiverged":
                self._watch_reset()  # judge the relocalized robot afresh
            self._safety_stop_since = None
            self.navigator.resume()
            self.session.add_event("recovery", status="finished")
            if self._mapping_recovery:
                self._mapping_recovery = False
            else:
                self.session.modes.enter(Mode.NAVIGATING, "recovery finished")

    def clear_local_costmap(self) -> None:
        """Clear the local obstacle layer (Nav2 ClearEntireCostmap on the local costmap)."""
        if self._local is not None:
            self._local.clear()
            self._local_cm = self._local.costmap()

    def clear_global_costmap(self) -> None:
        """Clear the global obstacle layer."""
        if self._global is not None:
            self._global.clear()
            self._global_cm = self._global.costmap()
            self._costmap_version += 1

    def clear_costmaps(self) -> None:
        """Clear the obstacle layers (Nav2 ClearEntireCostmap); loop thread only (recoveries)."""
        if self._local is not None and self._global is not None:
            self._local.clear()
            self._global.clear()
            self._global_cm = self._global.costmap()
            self._local_cm = self._local.costmap()
            self._costmap_version += 1

    def _command(self, now: float) -> Twist2D | None:
        return self._recovery_cmd if self._mapping_recovery else self._cmd

    def _recovery_command(self, now: float) -> Twist2D | None:
        return self._recovery_cmd

    # ------------------------------------------------------------------ outputs
    @property
    def active(self) -> bool:
        return self._active

    def state(self) -> dict[str, Any]:
        """``GET /api/navigation`` and telemetry: state, goal(s), feedback and the last outcome."""
        tick = self._last_tick
        fb = tick.feedback if tick is not None else None
        goals = self.navigator.goals if self._active else []
        goal = fb.goal if fb is not None and self._active else None
        state = self.navigator.state.value if self._active or tick is None else tick.state.value
        active, outcome = self._active, self.last_outcome
        with self._lock:  # a request the loop has not picked up yet: answer with the state it leads to
            last = next((p for p in reversed(self._pending) if p[0] in ("goals", "cancel")), None)
        if last is not None and last[0] == "goals":
            goals, goal, fb, state, active, outcome = last[1][0], last[1][0][0], None, "planning", True, None
        elif last is not None and active:
            state, active = "cancelled", False
        request = last[1][2] if last is not None and last[0] == "goals" else self.request_id
        return {
            "state": state,
            "active": active,
            "request_id": request,
            "planner": self.options.planner,
            "controller": self.navigator.controller_name,
            "goal": None if goal is None else _pose(goal),
            "goal_index": fb.goal_index if fb is not None else 0,
            "goals": [_pose(g) for g in goals],
            "distance_remaining": None if fb is None else round(fb.distance_remaining, 3),
            "eta_s": None if fb is None or not math.isfinite(fb.eta) else round(fb.eta, 1),
            **self._tolerances(),
            **_offset(self.session.pose, goal),
            "activity": "idle" if fb is None else fb.activity,
            "outcome": outcome,
            "recoveries": self.recoveries,
            "costmap_view": self.costmap_view,
        }

    def _tolerances(self) -> dict[str, float]:
        """The goal checker's tolerances: "reached" means within both (Nav2 names, m and rad)."""
        xy, yaw = self.navigator.goal_checker.tolerances()
        return {"xy_goal_tolerance": xy, "yaw_goal_tolerance": yaw}

    def path(self) -> Path | None:
        return self.navigator.path if self._active else None

    @property
    def recovering(self) -> bool:
        """A recovery behaviour drives now (mode RECOVERING, or inside MAPPING)."""
        return self.session.modes.mode == Mode.RECOVERING or (self._active and self._mapping_recovery)

    def mark_recovery(self, behavior: str) -> None:
        """Remember where a recovery attempt started (loop thread), for the 3D view."""
        p = self.session.pose
        self._recovery_marks = (*self._recovery_marks, (p.x, p.y, p.theta, behavior))

    def current_behavior(self) -> str | None:
        """The behaviour running now, named as in the viewer palette: the active recovery's own name
        while RECOVERING, else compute_path / follow_path / blocked; None when not navigating."""
        if not self._active:
            return None
        policy = getattr(self.recovery, "policy", None)
        if self.recovering:
            active = getattr(policy, "active", None)
            return getattr(active, "name", None) or "recovery"
        tick = self._last_tick
        if tick is None or tick.state.value == "planning":
            return "compute_path"
        if tick.feedback.activity.startswith("no safe trajectory"):
            return "blocked"
        return "follow_path" if tick.state.value == "following" else tick.state.value

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None:
        tick = self._last_tick
        local = self.costmap_view == "local"
        extras: dict[str, Any] = {
            "costmap": self._local_cm if local else self._global_cm,
            "costmap_version": ("local", id(self._local_cm)) if local else self._costmap_version,
            "navigation": self.state(),
        }
        if self._recovery_marks:
            extras["recovery_markers"] = self._recovery_marks
        if not self._active or tick is None:
            return {"extras": extras}
        fb = tick.feedback
        goals = self.navigator.goals[fb.goal_index :]
        if goals:
            key = tuple(goals)
            if self._waypoints is None or self._waypoints[0] != key:
                self._waypoints = (key, np.array([[g.x, g.y, g.theta] for g in goals]))
            extras["waypoints"] = self._waypoints[1]
        if fb.trajectories is not None and fb.chosen >= 0:
            extras["local_plan_best"] = fb.chosen
        band = getattr(getattr(self.navigator.controller, "last_debug", None), "band", None)
        if band is not None:  # TEB: the optimized band's poses, for the 3D view
            extras["teb_band"] = band
        return {
            "path": fb.path,
            "goal": fb.goal,
            "local_plan": fb.trajectories,
            "behavior": self.current_behavior(),
            "extras": extras,
        }

    def close(self) -> None:
        for _, fut in self._futures:
            fut.cancel()
        self._futures.clear()


def _pose(p: Pose2D) -> dict[str, float]:
    return {"x": round(p.x, 4), "y": round(p.y, 4), "theta": round(p.theta, 4)}


def _offset(pose: Pose2D, goal: Pose2D | None) -> dict[str, float | None]:
    """How far the (localized) robot is from ``goal``: straight-line distance (m) and heading error
    (rad, goal minus robot), the quantities the goal checker compares with its tolerances."""
    if goal is None:
        return {"distance_to_goal": None, "yaw_to_goal": None}
    return {
        "distance_to_goal": round(pose.distance_to(goal), 3),
        "yaw_to_goal": round(float(wrap_angle(goal.theta - pose.theta)), 4),
    }


def setup(runtime: Runtime) -> Navigation | None:
    loc = runtime.find_feature(Localization)
    if loc is None:
        log.warning("navigation needs the localization feature")
        return None
    nav = Navigation(runtime.session, loc)
    mapping = runtime.find_feature(Mapping)
    if mapping is not None:
        nav.mapping = mapping
        mapping.add_grid_listener(nav.on_live_map)
    runtime.session.add_stage(nav)
    runtime.pose_input_handlers["goal"] = nav.add_goal
    # navigate while mapping: a click beyond what the map has seen (Nav2's allow_unknown goal)
    runtime.pose_input_handlers["goal_unknown"] = partial(nav.add_goal, allow_unknown=True)
    return nav
