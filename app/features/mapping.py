"""Feature: live graph SLAM while the operator drives (replaces Cartographer / slam_toolbox + Rviz2).

In mode MAPPING every new scan and the wheel-odometry pose at the scan's stamp (interpolated in
``session.odom_history``; the tick's own pose is up to a tick later) go to the SLAM front end
(:meth:`nav.slam.GraphSlam.add_scan`, scan-to-submap matching); the back end (loop closure + sparse
pose-graph optimization) and the re-rendering of the global map run on ``session.workers``, and the
map is published with ``session.set_grid`` about once a second (source A's 1 s map update period).

Threads. The front end costs 16 ms mean / 29 ms p95 per scan (``navdeck bench slam.front_end``) on a
50 ms control period, and more when the back end competes for the CPU, so on a real clock it runs on
its own thread fed through a one-slot queue: the control loop only drops the newest scan into the slot
(an older, unprocessed one is replaced; the motion filter would skip most of them anyway) and never
waits. On a :class:`~robot.clock.VirtualClock` (simulated benchmarks and tests, no wall-clock deadline)
everything runs inline in the tick, which makes a simulated mapping session deterministic.

E-stop and faults. Leaving MAPPING by an e-stop or a fault (not by ``stop``) interrupts the session:
its map is finished and kept for saving as after a stop, and the next start (after the reset)
resumes it, the same SLAM and map frame, instead of beginning a new map over it (issue 16: an
operator who hit E-STOP in a tight spot lost the map when mapping again). ``stop`` then ``start``
begins a new map.

Frames (REP-105). A mapping session starts a new ``map`` frame at the robot's pose when it starts, as
slam_toolbox does; ``session.map_to_odom`` follows SLAM while mapping and keeps its last value after.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from app.features.localization import Localization
from app.features.recording import Recording
from app.modes import Mode
from nav.slam.system import GraphSlam, SlamOptions
from nav.types import LaserScan, OccupancyGrid, Pose2D

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session
    from robot.base import SensorFrame

ORDER = 10
log = logging.getLogger("navdeck.mapping")


class NoMapError(RuntimeError):
    """There is no map built by a mapping session to save (the API answers 409)."""


@dataclass(frozen=True)
class MappingOptions:
    """Options of the mapping stage (the SLAM's own live in ``nav.slam.SlamOptions``)."""

    map_update_interval: float = 1.0
    """Seconds between map publications (slam_toolbox ``map_update_interval``, 5 s there; source A
    publishes its map every 1 s)."""
    optimize_interval: float = 5.0
    """Seconds between back-end runs (loop-closure search + optimization) while new nodes arrive;
    the back end also runs whenever ``SlamOptions.optimize_every_n_nodes`` new nodes are waiting."""
    max_trajectory_points: int = 2000
    """The published trajectory is decimated to at most this many points (3D view)."""
    synchronous: bool | None = None
    """Run front end, back end and map rendering inline in the tick. ``None``: only on a virtual
    clock (simulation, benchmarks), where no deadline exists and determinism matters."""


class _OneSlot:
    """A one-element mailbox: ``put`` replaces what is waiting, ``take`` blocks until something is."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._item: Any = None
        self.replaced = 0

    def put(self, item: Any) -> None:
        with self._cond:
            if self._item is not None:
                self.replaced += 1
            self._item = item
            self._cond.notify()

    def take(self, timeout: float) -> Any:
        with self._cond:
            if self._item is None:
                self._cond.wait(timeout)
            item, self._item = self._item, None
            return item


@dataclass
class _Published:
    """What the background job hands back to the loop."""

    grid: OccupancyGrid
    trajectory: np.ndarray  # (K, 2) map-frame positions, decimated
    edges: np.ndarray  # (E, 2, 2) loop-closure segments
    optimized: bool
    optimize_ms: float | None


class Mapping:
    """The mapping stage: start / stop / the map to save. Public methods are thread-safe."""

    def __init__(
        self,
        session: Session,
        options: MappingOptions | None = None,
        slam_options: SlamOptions | None = None,
    ) -> None:
        self.session = session
        self.options = options or MappingOptions()
        # odometry is paired at each scan's stamp (odometry_history), so the prediction is the
        # unbiased pose to choose the unobserved points at (SlamOptions, issue 18)
        self.slam_options = slam_options or SlamOptions(unobserved_points_at_prediction=True)
        sync = self.options.synchronous
        self.synchronous = bool(getattr(session.clock, "is_virtual", False)) if sync is None else sync
        lid = session.profile.lidar
        self.laser_pose = Pose2D(lid.mount_x, lid.mount_y, lid.mount_yaw)
        self._lock = threading.Lock()
        self._mode_lock = threading.Lock()  # start / stop against the tick's mode checks
        self.slam: GraphSlam | None = None
        self.running = False
        self.generation = 0  # bumped by every start: a new map frame
        self.started_pose: Pose2D | None = None  # robot pose (previous frame) when mapping started
        self._last_scan: LaserScan | None = None
        self._last_publish = -math.inf
        self._last_optimize = -math.inf
        self._nodes_at_optimize = 0
        self._job: Future | None = None
        self._m2o: Pose2D | None = None  # latest map -> odom from the front end
        self._final_pending = False
        self._trajectory: np.ndarray | None = None
        self._edges: np.ndarray | None = None
        self._last_optimize_ms: float | None = None
        self._grid: OccupancyGrid | None = None
        self.front_end_ms: float | None = None
        self.scans_older_than_odometry = 0  # scans stamped before the odometry history: oldest pose used
        self.run_id_source: Callable[[], int | None] | None = None  # the recorder's current run
        self.run_id: int | None = None  # the recorded run of the last mapping session
        self.saved_map_id: int | None = None  # stored from this session's map (same map frame)
        self.interrupted = False  # left MAPPING by an e-stop or a fault: the next start resumes
        # Called (on a worker) with the final map when a session ends: the runtime makes it the
        # active map for localization, so the pose stays in the new map frame after mapping.
        self.on_finished: Callable[[OccupancyGrid], None] | None = None
        # Told (grid, generation) of every map published, on the thread that applies it; navigation
        # plans on it while mapping. Listeners must be quick (queue the grid) and never raise.
        self._grid_listeners: list[Callable[[OccupancyGrid, int], None]] = []
        self._slot = _OneSlot()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if not self.synchronous:
            self._thread = threading.Thread(
                target=self._front_end_loop, name="mapping-front-end", daemon=True
            )
            self._thread.start()

    # ------------------------------------------------------------------ requests (any thread)
    def start(self) -> None:
        """Enter MAPPING with a fresh SLAM (a new map frame at the robot's pose).
        Raises ``app.modes.TransitionRefused`` when the mode machine says no."""
        with self._mode_lock:  # the tick must not see MAPPING before the fresh SLAM exists
            self.session.modes.request(Mode.MAPPING, "mapping started")
            self._begin()

    def _begin(self) -> None:
        if self.interrupted and self.slam is not None:
            with self._lock:
                self.interrupted = False
                self.running = True
                self._last_scan = None
            self.session.add_event("mapping", status="resumed", nodes=self.slam.num_nodes)
            return
        with self._lock:
            self.slam = GraphSlam(self.slam_options)
            self.running = True
            self.generation += 1
            self.started_pose = self.session.pose
            self._last_scan = None
            self._last_publish = self._last_optimize = -math.inf
            self._nodes_at_optimize = 0
            self._m2o = None
            self._trajectory = self._edges = None
            self._last_optimize_ms = None
            self._grid = None
            self.run_id = None
            self.saved_map_id = None
        self.session.add_event("mapping", status="started")
        was = self.started_pose
        self.session.add_event(
            "notice",
            text="mapping started: the new map's frame begins where the robot stands, so its pose now "
            f"counts from (0, 0) (it was x {was.x:.2f} y {was.y:.2f} on the previous map); save the map "
            "to keep this frame",
        )

    def stop(self) -> None:
        """Leave MAPPING (to IDLE); the map is kept for saving. Raises ``TransitionRefused``."""
        with self._mode_lock:
            if self.session.modes.mode == Mode.MAPPING:
                self.session.modes.request(Mode.IDLE, "mapping stopped")
            self._finish()
            self.interrupted = False

    def _finish(self) -> None:
        with self._lock:
            if not self.running:
                return
            self.running = False
            slam = self.slam
        self.run_id = self._current_run_id()
        if slam is None:
            return
        # Final loop-closure search + optimization + render, off the loop (the save waits for it).
        if self.synchronous:
            self._apply(self._background(slam, True))
        else:
            self._submit(slam, True)
        self.session.add_event("mapping", status="stopped", nodes=slam.num_nodes)

    def _current_run_id(self) -> int | None:
        try:
            return self.run_id_source() if self.run_id_source is not None else None
        except Exception:  # the recorder is optional
            return None

    def add_grid_listener(self, fn: Callable[[OccupancyGrid, int], None]) -> None:
        """Be told of each map this stage publishes, with its session's ``generation``."""
        self._grid_listeners.append(fn)

    def saved(self, map_id: int) -> None:
        """The API stored this session's map as ``map_id`` (activating it keeps the robot's pose)."""
        with self._lock:
            self.saved_map_id = map_id

    def current_map(self, timeout: float = 30.0) -> OccupancyGrid:
        """The map of the current (or last) mapping session, fully optimized once stopped.
        Raises :class:`NoMapError` when no session has built one."""
        with self._lock:
            slam, job, running, grid = self.slam, self._job, self.running, self._grid
        if slam is None or slam.num_nodes == 0:
            raise NoMapError("no map to save: start mapping and drive first")
        if job is not None:  # the last job submitted; once stopped, the final optimization
            done_slam, pub = job.result(timeout)
            if not running and done_slam is slam:
                return _nonempty(pub.grid)
        elif not running and grid is not None:
            return _nonempty(grid)
        return _nonempty(slam.map())

    # ------------------------------------------------------------------ the stage (loop thread)
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        if self._mode_lock.acquire(blocking=False):  # else start/stop is running: next tick
            try:
                mode = session.modes.mode
                if self.running and mode != Mode.MAPPING:  # e-stop, fault, a plain mode request
                    self._finish()
                    self.interrupted = mode in (Mode.ESTOP, Mode.FAULT)
                elif not self.running and mode == Mode.MAPPING:  # entered through /api/mode
                    self._begin()
            finally:
                self._mode_lock.release()
        self._collect()
        slam = self.slam
        if self._final_pending:
            with self._lock:
                self._final_pending, m2o = False, self._m2o
            if m2o is not None:
                session.map_to_odom = m2o
                session.pose = m2o.compose(session.odom_pose)
        if not self.running or slam is None:
            return
        scan = frame.scan
        if scan is not None and scan is not self._last_scan:
            self._last_scan = scan
            item = (slam, scan, self._odom_at(session, scan.stamp))
            if self.synchronous:
                self._front_end(*item)
            else:
                self._slot.put(item)
        with self._lock:
            m2o = self._m2o
        if m2o is not None:
            session.map_to_odom = m2o
            session.pose = m2o.compose(session.odom_pose)
        due = now - self._last_publish >= self.options.map_update_interval
        if due and slam.num_nodes > 0 and self._job is None:
            self._last_publish = now
            optimize = self._optimize_due(slam, now)
            if self.synchronous:
                self._apply(self._background(slam, optimize))
            else:
                self._submit(slam, optimize)

    def _odom_at(self, session: Session, stamp: float) -> Pose2D:
        """The odometry pose at the scan's stamp (not the tick's, which is later: issue 18)."""
        found = session.odom_history.pose_at(stamp)
        if found is None:  # no odometry update yet
            return session.odom_pose
        pose, older = found
        if older:
            self.scans_older_than_odometry += 1
        return pose

    def _optimize_due(self, slam: GraphSlam, now: float) -> bool:
        new = slam.num_nodes - self._nodes_at_optimize
        due = new >= slam.options.optimize_every_n_nodes or (
            new > 0 and now - self._last_optimize >= self.options.optimize_interval
        )
        if due:
            self._last_optimize = now
            self._nodes_at_optimize = slam.num_nodes
        return due

    def _front_end(self, slam: GraphSlam, scan: LaserScan, odom: Pose2D) -> None:
        if not self.running or slam is not self.slam:  # stopped since the scan was queued
            return
        t0 = time.perf_counter()
        try:
            slam.add_scan(scan, odom, self.laser_pose)
        except Exception:  # a bad scan must not end mapping; the next one is tried
            log.exception("SLAM front end failed on a scan")
            return
        m2o = slam.map_to_odom()
        with self._lock:
            if slam is self.slam:
                self._m2o = m2o
                self.front_end_ms = (time.perf_counter() - t0) * 1e3

    def _front_end_loop(self) -> None:
        while not self._stop.is_set():
            item = self._slot.take(0.2)
            if item is not None:
                self._front_end(*item)

    def _background(self, slam: GraphSlam, optimize: bool) -> tuple[GraphSlam, _Published]:
        """Back end (when due) + map render + display data: runs on a worker (or inline when sync)."""
        ms = None
        optimized = False
        if optimize:
            t0 = time.perf_counter()
            optimized = slam.run_backend()
            ms = (time.perf_counter() - t0) * 1e3
        grid = slam.map()
        traj = slam.trajectory()[:, 1:3]
        k = math.ceil(len(traj) / self.options.max_trajectory_points) if len(traj) else 1
        traj = np.ascontiguousarray(np.vstack((traj[::k], traj[-1:])) if len(traj) else traj)
        return slam, _Published(grid, traj, slam.loop_closure_edges(), optimized, ms)

    def _submit(self, slam: GraphSlam, optimize: bool) -> None:
        """One background job at a time: a new one waits (on the worker, never here) for the last."""

        def run(prev: Future | None) -> tuple[GraphSlam, _Published]:
            if prev is not None:
                try:
                    prev.result()
                except Exception:
                    log.exception("SLAM back end failed")
            return self._background(slam, optimize)

        with self._lock:
            self._job = self.session.workers.submit(run, self._job)

    def _collect(self) -> None:
        """Publish a finished background job (loop thread). The job is cleared only once applied,
        so ``current_map`` never sees neither a pending job nor the final grid."""
        with self._lock:
            job = self._job
        if job is None or not job.done():
            return
        try:
            self._apply(job.result())
        except Exception:
            log.exception("SLAM back end failed")
        with self._lock:
            if self._job is job:
                self._job = None

    def _apply(self, result: tuple[GraphSlam, _Published]) -> None:
        slam, pub = result
        with self._lock:
            if slam is not self.slam:  # a stale job from a previous session
                return
            self._grid = pub.grid
            self._trajectory, self._edges = pub.trajectory, pub.edges
            if pub.optimized:
                self._last_optimize_ms = pub.optimize_ms
            self._m2o = slam.map_to_odom()
            final = self._final_pending = not self.running  # the stop's final optimization
        self.session.set_grid(pub.grid)
        for fn in list(self._grid_listeners):
            try:
                fn(pub.grid, self.generation)
            except Exception:
                log.exception("map listener failed")
        if final and self.on_finished is not None:
            self.session.workers.submit(self._hand_off, pub.grid)

    def _hand_off(self, grid: OccupancyGrid) -> None:
        try:
            assert self.on_finished is not None
            self.on_finished(grid)
        except Exception:
            log.exception("handing the new map to localization failed")

    # ------------------------------------------------------------------ outputs
    def state(self) -> dict[str, Any]:
        slam, grid = self.slam, self._grid
        size = None
        if grid is not None:
            w, h = grid.geometry.size_m
            size = [round(float(w), 2), round(float(h), 2)]
        return {
            "running": self.running,
            "has_map": slam is not None and slam.num_nodes > 0,
            "nodes": 0 if slam is None else slam.num_nodes,
            "loop_closures": 0 if slam is None else slam.num_loop_closures,
            "map_size_m": size,
            "last_optimization_ms": None
            if self._last_optimize_ms is None
            else round(self._last_optimize_ms, 1),
            "front_end_ms": None if self.front_end_ms is None else round(self.front_end_ms, 2),
            "scans_dropped": self._slot.replaced,
            "scans_older_than_odometry": self.scans_older_than_odometry,
        }

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None:
        if self.slam is None:
            return None
        if self.running:
            # Stages after this one (localization on an old map) must not move the new map frame.
            m2o = self._m2o
            if m2o is not None:
                session.map_to_odom = m2o
                session.pose = m2o.compose(session.odom_pose)
        extras: dict[str, Any] = {"mapping": self.state()}
        if self._edges is not None and len(self._edges):
            extras["graph_edges"] = self._edges
        if self._trajectory is not None:
            extras["trajectory"] = self._trajectory
        return {"extras": extras}

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


def setup(runtime: Runtime) -> Mapping:
    mapping = Mapping(runtime.session)

    def run_id() -> int | None:
        rec = runtime.find_feature(Recording)  # set up later (ORDER 900): looked up when needed
        return None if rec is None else rec.recorder.current_run_id

    mapping.run_id_source = run_id

    def hand_off(grid: OccupancyGrid) -> None:
        """The new map becomes the active (unsaved) map; the robot is localized where SLAM left it."""
        loc = runtime.find_feature(Localization)
        if loc is None:
            return
        loc.set_map(grid, None)
        try:
            loc.set_initial_pose(runtime.session.pose)
        except Exception as exc:  # e.g. the pose fell on an occupied cell: the operator sets it
            runtime.session.add_event("mapping", status="not localized on the new map", reason=str(exc))

    mapping.on_finished = hand_off
    runtime.session.add_stage(mapping)
    return mapping


def _nonempty(grid: OccupancyGrid) -> OccupancyGrid:
    """A map with no cells (no scan has been inserted yet) is no map to save or navigate on."""
    if grid.data.size == 0:
        raise NoMapError("no map to save yet: the first scan has not been added; drive a little first")
    return grid
