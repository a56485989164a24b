"""Feature: the active map and AMCL localization on it (Nav2 ``amcl`` + Rviz2's "2D Pose Estimate").

The *active map* is the grid the robot localizes and plans in: the simulated world's grid at start,
switched by the maps API through :meth:`Localization.set_map` (AMCL restarts, listeners such as the
navigation feature rebuild their global costmap).

Each tick the stage runs AMCL on a new scan (gated by Nav2's ``update_min_d`` / ``update_min_a``),
publishes ``session.map_to_odom`` (REP-105) and the particles, and keeps a *localized* flag that
guards NAVIGATING. Like Nav2 the filter does nothing until it has an initial pose (API, a click in
the 3D view) or is asked to localize globally. Global localization follows source A rather than Nav2:
the robot rotates in place (mode LOCALIZING, a command source) until the particle cloud has
converged and the scan fits the map, then returns to IDLE.

Requests arrive on other threads (uvicorn, viser); they are validated at once against the immutable
grid and applied by the control loop at its next tick, so AMCL is only ever touched by one thread.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from app.modes import Mode, no_lidar_reason
from nav.localization import Amcl, AmclOptions
from nav.localization import sensor_models as sm
from nav.planning.goal import nearest_free_pose as nearest_traversable
from nav.types import Costmap, OccupancyGrid, Pose2D, Twist2D

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session
    from robot.base import SensorFrame

ORDER = 20
log = logging.getLogger("navdeck.localization")

APPLY_TIMEOUT_S = 5.0
"""How long a request waits for the control loop to apply an initial pose and weigh a scan there."""
NEAREST_FREE_RADIUS_M = 3.0
"""How far from a refused pose the nearest free pose is looked for."""

MapListener = Callable[[OccupancyGrid, "int | None"], None]


def nearest_free_pose(loc: Localization, pose: Pose2D) -> Pose2D | None:
    """The free cell of the active map nearest to ``pose`` (within ``NEAREST_FREE_RADIUS_M``), what a
    refused initial pose suggests instead; None without a map or a free cell near."""
    grid = loc.grid
    if grid is None or not pose.is_finite():
        return None
    costs = np.where(grid.data >= loc.options.occupied_threshold, 254, np.where(grid.data < 0, 255, 0))
    return nearest_traversable(Costmap(grid.geometry, costs.astype(np.uint8)), pose, NEAREST_FREE_RADIUS_M)


def map_fit(loc: Localization, grid: OccupancyGrid, poses: list[Pose2D]) -> float | None:
    """How well the robot's latest scan fits ``grid`` (0..1, ``Amcl.quality``'s measure) at the best of
    ``poses`` (map frame of ``grid``); None without a scan. What activation in simulation checks: a
    map of another world fits nowhere the robot can be."""
    scan = loc.session.last_scan
    if scan is None or not poses:
        return None
    o = loc.amcl_options
    field = sm.LikelihoodField(grid, o.laser_likelihood_max_dist, o.sigma_hit)
    beams = sm.select_beams(scan, o)
    return max(sm.scan_fit(field, p, loc.laser_pose, beams) for p in poses if p.is_finite())


class LocalizationRequestError(ValueError):
    """A pose request the map refuses (off the map, inside a wall); the message says why (422)."""


class NoActiveMapError(LocalizationRequestError):
    """There is no map to localize in (a serial robot before a map was chosen)."""


@dataclass(frozen=True)
class LocalizationOptions:
    """Options of the localization stage (AMCL's own live in ``AmclOptions``)."""

    source: Literal["amcl", "truth"] = "amcl"
    """``amcl``: the particle filter; ``truth``: the simulator's true pose (benchmarks, sim-nav)."""
    initial_std_xy: float = 0.5
    """Standard deviation (m) of x and y of an initial pose from the operator (Nav2 amcl
    ``initial_cov_xx`` = 0.5^2)."""
    initial_std_yaw: float = math.pi / 12.0
    """Standard deviation (rad) of the yaw of an initial pose (Nav2 ``initial_cov_aa`` = (pi/12)^2)."""
    spin_speed: float = 0.6
    """Angular speed (rad/s) of the in-place rotation during global localization (source A)."""
    converged_std_xy: float = 0.15
    """Global localization is done once the estimate's x and y standard deviations are below this (m)..."""
    converged_std_yaw: float = 0.15
    """...its yaw standard deviation below this (rad)..."""
    min_quality: float = 0.5
    """...the scan fits the map at the estimate at least this well (``Amcl.quality``, 0..1)..."""
    matched_std_xy: float = 0.3
    """``match_score`` counts the scan's fit only while the estimate's x and y standard deviations
    are within this (m; 0.04-0.11 while tracking in the scenario sets, up to 0.29 in the greenhouse)."""
    mismatch_quality: float = 0.3
    """A tight cloud (spread within ``matched_std_xy``) whose scan fits the map worse than this (0..1)
    flags ``map_mismatch``: the active map is probably not where the robot is."""
    converged_updates: int = 3
    """...and all of it held for this many consecutive filter updates."""
    fit_tolerance: float = 0.1
    """A beam's endpoint at the estimate is explained by the map when it lies within this (m, two
    cells of a 0.05 m map) of a mapped obstacle; ``fit`` is the fraction of returning beams so
    explained (``sensor_models.scan_inlier_fraction``). See docs/localization.md."""
    localized_fit_on: float = 0.7
    """``localized`` turns true at a filter update whose ``fit`` is at least this (and the spread
    within ``localized_max_spread``): measured over seeded worlds, the right pose after an initial
    pose fits at or above it, wrong poses below (docs/localization.md, bench/loc_criterion.py)."""
    localized_fit_off: float = 0.5
    """...and false again after ``unlocalized_updates`` consecutive updates fitting below this
    (hysteresis: people walking past hide walls for a few scans)."""
    unlocalized_updates: int = 5
    """Consecutive updates below ``localized_fit_off`` that revoke ``localized``."""
    localized_max_spread: float = 1.0
    """Secondary bound: no ``localized`` while the estimate's x or y standard deviation exceeds this
    (m): a cloud spread over the map (global localization, a reinitialize) has no pose to trust."""
    global_timeout: float = 60.0
    """Seconds of rotating before global localization gives up (event, back to IDLE)."""
    occupied_threshold: int = 65
    """Occupancy (0..100) from which a cell is a wall for pose requests (map_server occupied_thresh)."""


class Localization:
    """The localization stage and the active map. Public methods are thread-safe."""

    def __init__(
        self,
        session: Session,
        options: LocalizationOptions | None = None,
        amcl_options: AmclOptions | None = None,
        *,
        seed: int = 0,
        map_id: int | None = None,
    ) -> None:
        self.session = session
        self.options = options or LocalizationOptions()
        robot_model = "omnidirectional" if session.profile.is_omni else "differential"
        self.amcl_options = amcl_options or AmclOptions(robot_model_type=robot_model)
        self._seed = seed
        self._lock = threading.Lock()
        self._listeners: list[MapListener] = []
        self.grid: OccupancyGrid | None = session.grid
        self.map_id = map_id
        self.map_version = 1 if self.grid is not None else 0
        self.amcl: Amcl | None = None
        self._pending: list[tuple[str, Any]] = []
        self.localized = False
        self.global_running = False
        self._global_started = 0.0
        self._good_updates = 0
        self._particles: np.ndarray | None = None
        self._cov = np.zeros((3, 3))
        self._quality = 0.0
        self.updates = 0
        self._applied = threading.Condition()
        self._requests_done = 0  # requests applied by the loop (initial pose / global / map), for waiters
        self._requests_made = 0
        self._awaiting: int | None = None  # requests applied, waiting for the filter's next update
        self.map_mismatch = False  # see _check_map_match
        self._fit = 0.0  # fraction of beams the map explains at the estimate (see _gate_on_fit)
        self._low_fit_updates = 0
        self._judging = False  # an initial pose awaits its first update's verdict
        self._mismatch_updates = 0
        self.resets = 0  # times the estimate was reset (initial pose, global): costmaps clear their marks
        lid = session.profile.lidar
        self.laser_pose = Pose2D(lid.mount_x, lid.mount_y, lid.mount_yaw)
        self._amcl_future: Future | None = None
        self._prepare(self.grid)
        session.set_command_source(Mode.LOCALIZING, self._command)

    def _prepare(self, grid: OccupancyGrid | None) -> None:
        """Build the filter for ``grid`` on a worker: its likelihood field (a distance transform of
        the whole map) takes long enough to stall a control tick."""
        if grid is None or self.options.source == "truth":
            self._amcl_future = None
            return
        opts = replace(self.amcl_options, set_initial_pose=True)
        self._amcl_future = self.session.workers.submit(Amcl, opts, grid, self._seed)

    # ------------------------------------------------------------------ requests (any thread)
    def add_map_listener(self, fn: MapListener) -> None:
        """``fn(grid, map_id)`` runs on the caller's thread whenever the active map changes."""
        self._listeners.append(fn)

    def set_map(self, grid: OccupancyGrid, map_id: int | None = None) -> None:
        """Make ``grid`` the active map: AMCL restarts (not localized), the global costmap follows."""
        with self._lock:
            self.grid = grid
            self.map_id = map_id
            self.map_version += 1
            self.localized = False
            self._pending.append(("map", grid))
            self._prepare(grid)
        self.session.set_grid(grid)
        for fn in self._listeners:
            fn(grid, map_id)
        self.session.add_event("map", map_id=map_id, reason="active map changed: localization reset")

    def check_pose(self, pose: Pose2D) -> None:
        """Raise ``LocalizationRequestError`` naming why ``pose`` cannot be the robot's pose."""
        if not self.session.has_lidar:
            raise LocalizationRequestError(no_lidar_reason("localization (AMCL)"))
        grid = self.grid
        if grid is None:
            raise NoActiveMapError("no active map: choose a map first")
        if not pose.is_finite():
            raise LocalizationRequestError("pose must be finite")
        geo = grid.geometry
        rows, cols = geo.world_to_cell(np.array([pose.x, pose.y]))
        if not geo.in_bounds(rows, cols)[0]:
            w, h = geo.size_m
            o = geo.origin
            raise LocalizationRequestError(
                f"({pose.x:.2f}, {pose.y:.2f}) is off the map "
                f"(x {o.x:.2f}..{o.x + w:.2f}, y {o.y:.2f}..{o.y + h:.2f})"
            )
        value = int(grid.data[rows[0], cols[0]])
        if value >= self.options.occupied_threshold:
            raise LocalizationRequestError(f"({pose.x:.2f}, {pose.y:.2f}) is inside a wall")

    def set_initial_pose(self, pose: Pose2D, cov: np.ndarray | None = None) -> None:
        """Rviz2's "2D Pose Estimate": validate, then reset AMCL around ``pose`` at the next tick.
        Unlike Nav2 the operator's word is not enough: the filter's first update there (no motion
        needed) decides ``localized`` by the scan's fit (``_gate_on_fit``). The simulator's truth
        source is localized at once."""
        self.check_pose(pose)
        o = self.options
        if cov is None:
            cov = np.diag([o.initial_std_xy**2, o.initial_std_xy**2, o.initial_std_yaw**2])
        fit = self._fit_at(pose)
        with self._lock:
            self._pending.append(("initial_pose", (pose, np.asarray(cov, dtype=float))))
            self._requests_made += 1
            # provisional until the filter's first update there judges (_gate_on_fit): a pose the
            # latest scan already fits (or, before any scan, the operator's word as in Nav2) lets a
            # caller that cannot wait for a tick (the synchronous sim stacks) send goals at once
            self.localized = o.source == "truth" or fit is None or fit >= o.localized_fit_on
            self.global_running = False
        self.session.add_event("initial_pose", pose=[pose.x, pose.y, pose.theta])

    def _fit_at(self, pose: Pose2D) -> float | None:
        """``fit`` of the latest scan at ``pose`` on the active map; None without a scan or a filter.
        Reads the filter's likelihood field only (immutable), so any thread may call it."""
        scan, fut = self.session.last_scan, self._amcl_future
        if scan is None or fut is None:
            return None
        field = fut.result(timeout=APPLY_TIMEOUT_S).likelihood_field
        beams = sm.select_beams(scan, self.amcl_options)
        return sm.scan_inlier_fraction(field, pose, self.laser_pose, beams, self.options.fit_tolerance)

    def start_global(self) -> None:
        """Spread the particles over the free space and rotate in place (mode LOCALIZING) until
        converged. Raises ``app.modes.TransitionRefused`` when the mode machine says no."""
        if not self.session.has_lidar:  # the mode machine's lidar refusal, before "no active map"
            self.session.modes.request(Mode.LOCALIZING, "global localization")
        if self.grid is None:
            raise NoActiveMapError("no active map: choose a map first")
        if self.options.source == "truth":
            with self._lock:
                self.localized = True
            return
        self.session.modes.request(Mode.LOCALIZING, "global localization")
        with self._lock:
            self._pending.append(("global", None))
            self.localized = False
            self.global_running = True
            self._global_started = self.session.clock.now()
            self._good_updates = 0
        self.session.add_event("localization", status="global localization started")

    def wait_applied(self, timeout: float) -> bool:
        """Block (a request thread, never the loop) until the loop applied every request made so far
        and ran the filter once after it; False on timeout (the state then says what is known)."""
        with self._applied:
            target = self._requests_made
            return self._applied.wait_for(lambda: self._requests_done >= target, timeout)

    # ------------------------------------------------------------------ the stage (loop thread)
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        with self._lock:
            pending, self._pending = self._pending, []
            made = self._requests_made
        for kind, arg in pending:
            self._apply(kind, arg, now)
        if pending:
            self._awaiting = made
        updates = self.updates
        self._step(session, frame, now)
        # a request counts as applied once the filter weighed a scan after it (or cannot: no filter,
        # or mapping, where AMCL is off), so a waiter reads the estimate it led to, not the one before
        mapping = session.modes.mode == Mode.MAPPING
        if self._awaiting is not None and (self.updates > updates or self.amcl is None or mapping):
            with self._applied:
                self._requests_done, self._awaiting = self._awaiting, None
                self._applied.notify_all()

    def _step(self, session: Session, frame: SensorFrame, now: float) -> None:
        if session.modes.mode == Mode.MAPPING:
            return  # SLAM localizes while mapping, in its own map frame: AMCL stays off
        if self.options.source == "truth":
            self._track_truth(session)
            return
        if self.global_running and session.modes.mode != Mode.LOCALIZING:
            self._end_global(now, "global localization stopped: mode changed", ok=False)
        if self.amcl is None or frame.scan is None:
            return
        if not self.amcl.update(session.odom_pose, frame.scan, self.laser_pose):
            return
        self.updates += 1
        _, cov = self.amcl.estimate()
        self._cov, self._quality = cov, self.amcl.quality
        self._particles = np.array(self.amcl.particles, dtype=np.float32)
        session.map_to_odom = self.amcl.map_to_odom()
        session.pose = session.map_to_odom.compose(session.odom_pose)
        beams = sm.select_beams(frame.scan, self.amcl_options)
        est, _ = self.amcl.estimate()
        self._fit = sm.scan_inlier_fraction(
            self.amcl.likelihood_field, est, self.laser_pose, beams, self.options.fit_tolerance
        )
        self._check_map_match()
        self._gate_on_fit()
        if self.global_running:
            self._check_global(now)

    def _check_map_match(self) -> None:
        """Flag a map that does not match what the lidar sees: the cloud is tight (so the estimate is
        not a spread cloud's mean) yet the scan fits badly. Held for ``converged_updates`` updates it
        revokes ``localized`` (navigation stops trusting the pose) and says so in an event."""
        o = self.options
        tight = self.spread_xy <= o.matched_std_xy
        self._mismatch_updates = (
            self._mismatch_updates + 1 if tight and self._quality < o.mismatch_quality else 0
        )
        was = self.map_mismatch
        self.map_mismatch = self._mismatch_updates >= o.converged_updates
        if self.map_mismatch and not was:
            with self._lock:
                self.localized = False
            self.session.add_event(
                "localization",
                status="map mismatch",
                reason=f"the scan does not fit the active map (score {self._quality:.2f} < "
                f"{o.mismatch_quality:g}): not localized",
                map_id=self.map_id,
            )

    def _gate_on_fit(self) -> None:
        """``localized`` with hysteresis on ``fit``: true at an update fitting at least
        ``localized_fit_on`` with the spread within ``localized_max_spread``; false after
        ``unlocalized_updates`` consecutive updates below ``localized_fit_off``. Global localization
        decides for itself while it runs (``_check_global``)."""
        if self.global_running:
            return
        o = self.options
        good = (
            self._fit >= o.localized_fit_on
            and self.spread_xy <= o.localized_max_spread
            and not self.map_mismatch
        )
        self._low_fit_updates = 0 if self._fit >= o.localized_fit_off else self._low_fit_updates + 1
        judging, self._judging = self._judging, False
        with self._lock:
            was = self.localized
            if good:
                self.localized = True
            elif judging or (was and self._low_fit_updates >= o.unlocalized_updates):
                self.localized = False
            now_localized = self.localized
        if now_localized and not was:
            self.session.add_event("localization", status="localized", reason=self._fit_text())
        elif was and not now_localized:
            self.session.add_event(
                "localization",
                status="lost",
                reason=f"{self._fit_text()} for {self._low_fit_updates} updates: not localized",
            )
        elif judging and not now_localized:
            self.session.add_event(
                "localization", status="initial pose refused", reason=self.not_localized_reason
            )

    def _fit_text(self) -> str:
        return f"the scan fits the map at the estimate: fit {self._fit:.2f}"

    @property
    def not_localized_reason(self) -> str:
        """Why goals are refused while not localized, naming the fit once the filter has one."""
        o = self.options
        base = "not localized: set the initial pose or run global localization"
        if self.amcl is None or self.updates == 0 or self.options.source == "truth":
            return base
        return (
            f"{base} (the scan fits the map at the estimate: fit {self._fit:.2f}, localized from "
            f"{o.localized_fit_on:g}; spread {self.spread_xy:.2f} m)"
        )

    def _apply(self, kind: str, arg: Any, now: float) -> None:
        self.session.restart_trail()  # every request here moves the estimate (or its frame) at once
        self.map_mismatch, self._mismatch_updates = False, 0
        self._low_fit_updates, self._judging = 0, kind == "initial_pose"
        if kind == "map":
            self.amcl = None
            self._particles = None
            self._quality = self._fit = 0.0
            return
        if self.grid is None:
            return
        if self.amcl is None or self.amcl.grid is not self.grid:
            fut = self._amcl_future
            if fut is None:
                return
            self.amcl = fut.result()  # usually long done; a first request right at start waits
        self.resets += 1
        if kind == "initial_pose":
            pose, cov = arg
            self.amcl.set_initial_pose(pose, cov)
            # Until the first filter update the estimate is the operator's pose.
            self.session.map_to_odom = pose.compose(self.session.odom_pose.inverse())
            self.session.pose = pose
        elif kind == "global":
            self.amcl.global_localization()
        self._particles = np.array(self.amcl.particles, dtype=np.float32)

    def _check_global(self, now: float) -> None:
        assert self.amcl is not None
        o = self.options
        sd = np.sqrt(np.clip(np.diag(self._cov), 0.0, None))
        good = (
            self.amcl.converged
            and sd[0] < o.converged_std_xy
            and sd[1] < o.converged_std_xy
            and sd[2] < o.converged_std_yaw
            and self._quality >= o.min_quality
            and self._fit >= o.localized_fit_on
        )
        self._good_updates = self._good_updates + 1 if good else 0
        if self._good_updates >= o.converged_updates:
            self._end_global(now, "localized", ok=True)
        elif now - self._global_started > o.global_timeout:
            self._end_global(now, f"global localization did not converge in {o.global_timeout:g} s", ok=False)

    def _end_global(self, now: float, reason: str, *, ok: bool) -> None:
        with self._lock:
            self.global_running = False
            self.localized = ok
        est = self.session.pose
        self.session.add_event(
            "localization",
            status="localized" if ok else "failed",
            reason=reason,
            pose=[est.x, est.y, est.theta],
            seconds=round(now - self._global_started, 2),
        )
        if self.session.modes.mode == Mode.LOCALIZING:
            self.session.modes.enter(Mode.IDLE, reason)

    def _track_truth(self, session: Session) -> None:
        truth = getattr(session.driver, "truth_pose", None)
        if truth is None:
            return
        session.map_to_odom = truth.compose(session.odom_pose.inverse())
        session.pose = truth
        self._quality = self._fit = 1.0

    def _command(self, now: float) -> Twist2D | None:
        """Command source for LOCALIZING: rotate in place while global localization runs."""
        if not self.global_running:
            return Twist2D()
        return Twist2D(0.0, 0.0, self.options.spin_speed)

    def reinitialize(self) -> None:
        """Spread the particles over the free space at the next tick without changing mode (a
        recovery behaviour of a robot that is lost while navigating turns in place meanwhile);
        Nav2 amcl's ``reinitialize_global_localization`` service."""
        with self._lock:
            self._pending.append(("global", None))
        self.session.add_event("localization", status="reinitialized over the whole map")

    # ------------------------------------------------------------------ outputs
    @property
    def quality(self) -> float:
        return self._quality

    @property
    def fit(self) -> float:
        """Fraction (0..1) of the last scan's returning beams that end within ``fit_tolerance`` of a
        mapped obstacle at the estimate: what ``localized`` is decided on."""
        return self._fit

    @property
    def match_score(self) -> float:
        """The scan's fit to the map at the estimate (``quality``) while the estimate is tight (x
        and y standard deviations within ``matched_std_xy``), else 0: a spread cloud's mean can fit
        by chance. What "spin until matched" and "relocalize" wait for."""
        return self._quality if self.spread_xy <= self.options.matched_std_xy else 0.0

    @property
    def spread_xy(self) -> float:
        """The estimate's larger x / y standard deviation (m)."""
        return float(np.sqrt(max(self._cov[0, 0], self._cov[1, 1], 0.0)))

    @property
    def covariance(self) -> np.ndarray:
        return self._cov.copy()

    def state(self) -> dict[str, Any]:
        """What ``GET /api/localization`` and the telemetry show."""
        pose = self.session.pose
        amcl = self.amcl
        o = self.options
        return {
            "source": o.source,
            "localized": self.localized,
            "converged": self.converged,
            "global_running": self.global_running,
            "pose": {"x": pose.x, "y": pose.y, "theta": pose.theta},
            "covariance": np.round(self._cov, 6).tolist(),
            "spread_m": round(self.spread_xy, 4),
            "particles": 0 if amcl is None else amcl.particle_count,
            "quality": round(float(self._quality), 4),
            "fit": round(float(self._fit), 4),
            "match_score": round(float(self.match_score), 4),
            "map_mismatch": self.map_mismatch,
            "updates": self.updates,
            "map_id": self.map_id,
            "map_version": self.map_version,
            "criterion": {
                "matched_std_xy": o.matched_std_xy,
                "min_quality": o.min_quality,
                "mismatch_quality": o.mismatch_quality,
                "fit_tolerance": o.fit_tolerance,
                "localized_fit_on": o.localized_fit_on,
                "localized_fit_off": o.localized_fit_off,
                "unlocalized_updates": o.unlocalized_updates,
                "localized_max_spread": o.localized_max_spread,
            },
        }

    @property
    def converged(self) -> bool:
        """The filter has converged on the active map: at the last update the cloud was tight
        (``spread_xy <= matched_std_xy``) and the scan fit the map there (``quality >= min_quality``).
        The simulator's truth source always is."""
        if self.options.source == "truth":
            return self.grid is not None
        return self.updates > 0 and self.match_score >= self.options.min_quality

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None:
        info = {
            "quality": round(float(self._quality), 4),
            "covariance": np.round(self._cov, 6).tolist(),
            "particles": 0 if self._particles is None else len(self._particles),
            "localized": self.localized,
            "converged": self.converged,
            "map_mismatch": self.map_mismatch,
            "match_score": round(float(self.match_score), 4),
            "global_running": self.global_running,
        }
        return {"particles": self._particles, "extras": {"localization": info}}

    def close(self) -> None:
        self._listeners.clear()


def setup(runtime: Runtime) -> Localization:
    loc = Localization(runtime.session, seed=runtime.settings.seed, map_id=_stock_map_id(runtime))
    runtime.session.add_stage(loc)
    runtime.pose_input_handlers["initial_pose"] = loc.set_initial_pose

    def _record_map(grid: OccupancyGrid, map_id: int | None) -> None:
        runtime.active_map_id = map_id  # read by the recorder feature

    loc.add_map_listener(_record_map)
    return loc


def _stock_map_id(runtime: Runtime) -> int | None:
    if not runtime.world_name:
        return None
    try:
        info = runtime.maps.find(runtime.world_name, stock=True)
    except Exception:  # the map store is optional for localization
        return None
    return None if info is None else info.id
