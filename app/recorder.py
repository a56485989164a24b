"""The always-on run recorder: every teleop, mapping and navigation session becomes a run.

Threads (nothing here runs on the control loop except two O(1) hand-offs):

* the loop publishes snapshots on ``session.bus`` (this recorder's subscription is a one-slot mailbox)
  and calls the event listener, which only appends to a queue;
* the *capture* thread takes snapshots and events, decides when runs start and end, downsamples
  (``sample_period``, ``scan_period``), and every ``flush_period`` hands the batch to the writer;
* the *writer* thread turns each batch into one database transaction (``RunsStore.write``).

A crash loses at most ``flush_period`` plus one write (default 0.5 s + a few ms, < 1 s). At start-up a
run left ``recording`` is closed as ``interrupted`` with its data kept.

Run rule (docs/runs.md): a run starts when the mode enters teleop, mapping, or localizing / navigating /
recovering (kind ``navigation``); e-stop and fault stay inside the run; it ends when the mode has been
IDLE for ``idle_grace`` seconds (so the pause between two goals stays one mission), when the mode
moves to another kind (a new run starts at once), or when the server shuts down (``stopped``).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import TYPE_CHECKING

import numpy as np

from app.bus import Snapshot, SnapshotBus, Subscription
from app.runs.codec import MODE_CODE
from app.runs.metrics import GOAL_SET, goal_outcome, outcome_for
from app.runs.store import Batch, RunsStore
from nav.types import LaserScan, Pose2D

if TYPE_CHECKING:
    from app.session import Session

log = logging.getLogger("navdeck.recorder")

# Mode -> run kind. Modes not listed (idle, estop, fault) never start a run.
RUN_KIND = {
    "teleop": "teleop",
    "mapping": "mapping",
    "localizing": "navigation",
    "navigating": "navigation",
    "recovering": "navigation",
}
STOP_MODES = frozenset({"estop", "fault"})
PRE_RUN_WINDOW = 1.0  # s: events this long before a run starts (a goal, then the mode switch) join it


@dataclass(frozen=True)
class RecorderOptions:
    """Recording rates and the run rule. Defaults follow the issue's targets (>= 10 Hz, >= 2 Hz)."""

    sample_period: float = 0.1
    """s between trajectory samples (10 Hz; the loop publishes at 20 Hz)."""
    scan_period: float = 0.5
    """s between stored scans (2 Hz; the RPLidar A1 turns at about 5.5 Hz)."""
    flush_period: float = 0.5
    """s between database commits: the most a crash can lose (must be <= 1 s)."""
    idle_grace: float = 10.0
    """s the mode may stay IDLE before the run ends (a pause between goals stays one mission)."""
    grid_period: float = 10.0
    """s between stored copies of a changing map (mapping runs); the last one is stored at the end."""
    plan_tolerance: float = 1e-3
    """m: a published path that differs less than this from the last stored one is not stored again."""
    buffer: int = 40
    """Snapshots the capture mailbox holds (2 s at 20 Hz): a descheduled capture thread loses none."""

    def __post_init__(self) -> None:
        if not 0.0 < self.flush_period <= 1.0:
            raise ValueError("flush_period must be in (0, 1] s: a crash may lose at most 1 s")
        if self.sample_period <= 0.0 or self.scan_period <= 0.0 or self.idle_grace < 0.0:
            raise ValueError("recorder periods must be positive")


class RingSubscription(Subscription):
    """A bus subscription that keeps the last ``maxlen`` snapshots instead of only the newest.

    The viewer may skip frames; the recorder must not, or a busy machine turns 10 Hz samples into
    less. The loop's cost is the same O(1) locked append; when full, the oldest snapshot is dropped."""

    def __init__(self, bus: SnapshotBus, maxlen: int) -> None:
        super().__init__(bus, None)
        self._ring: deque[Snapshot] = deque(maxlen=max(1, maxlen))

    def _put(self, snap: Snapshot) -> None:
        with self._lock:
            if len(self._ring) == self._ring.maxlen:
                self.dropped += 1
            self._ring.append(snap)
            self._latest = snap
        self._thread_event.set()

    def take_all(self) -> list[Snapshot]:
        with self._lock:
            out = list(self._ring)
            self._ring.clear()
            self._latest = None
            self._thread_event.clear()
            return out

    def wait_all(self, timeout: float | None = None) -> list[Snapshot]:
        self._thread_event.wait(timeout)
        return self.take_all()


def footprint_clearance(points: np.ndarray, polygon: np.ndarray) -> float:
    """Smallest distance (m) from (N, 2) points in base_link to the footprint polygon (0 if inside).

    Vectorised point-to-segment distance over every edge, plus an even-odd inside test."""
    if points.shape[0] == 0 or polygon.shape[0] < 3:
        return math.nan
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    ab = b - a  # (M, 2)
    ap = points[:, None, :] - a[None, :, :]  # (N, M, 2)
    denom = np.maximum((ab * ab).sum(axis=1), 1e-12)
    u = np.clip((ap * ab[None]).sum(axis=2) / denom, 0.0, 1.0)
    d = np.hypot(*(ap - u[..., None] * ab[None]).transpose(2, 0, 1))
    py = points[:, 1:2]
    crosses = ((a[None, :, 1] > py) != (b[None, :, 1] > py)) & (
        points[:, 0:1]
        < (b[:, 0] - a[:, 0]) * (py - a[:, 1]) / np.where(ab[:, 1] == 0, 1e-12, ab[:, 1]) + a[:, 0]
    )
    inside = (crosses.sum(axis=1) % 2).astype(bool)
    if inside.any():
        return 0.0
    return float(d.min())


def covariance_diag(extras: dict) -> tuple[float, float, float]:
    """(var x, var y, var yaw) from ``extras["localization"]``: a 3x3 (x, y, yaw) or 6x6 ROS
    PoseWithCovariance matrix under ``covariance``, or NaN when no estimate is published."""
    loc = extras.get("localization") if isinstance(extras, dict) else None
    cov = loc.get("covariance") if isinstance(loc, dict) else None
    if cov is None:
        return math.nan, math.nan, math.nan
    c = np.asarray(cov, dtype=float).ravel()
    if c.size == 9:
        return float(c[0]), float(c[4]), float(c[8])
    if c.size == 36:
        return float(c[0]), float(c[7]), float(c[35])
    if c.size == 3:
        return float(c[0]), float(c[1]), float(c[2])
    return math.nan, math.nan, math.nan


@dataclass
class _OpenRun:
    """The capture thread's state for the run being recorded."""

    key: int
    kind: str
    t0: float  # session clock time of t = 0
    batch: Batch
    next_sample: float = -math.inf
    last_scan_t: float = -math.inf
    last_scan_stamp: float | None = None
    last_plan: np.ndarray | None = None
    last_plan_obj: object = None
    goals: list[dict] = field(default_factory=list)
    grid_version: int = -1
    grid_t: float = -math.inf
    grid_obj: object = None
    last_odom: Pose2D | None = None
    distance: float = 0.0
    idle_since: float | None = None
    last_active: str = ""
    last_behavior: str | None = None
    clearance: float = math.nan
    last_snap_goal: Pose2D | None = None


class Recorder:
    """Records runs from ``session`` into ``store``. ``start()`` / ``close()``; ``sync()`` for tests."""

    def __init__(
        self,
        session: Session,
        store: RunsStore,
        options: RecorderOptions | None = None,
        *,
        profile_name: str = "",
        map_id: Callable[[], int | None] | None = None,
    ) -> None:
        self.session = session
        self.store = store
        self.options = options or RecorderOptions()
        self.profile_name = profile_name or getattr(session.profile, "name", "")
        self.map_id = map_id or (lambda: None)
        self._events: queue.SimpleQueue[dict] = queue.SimpleQueue()
        self._ops: queue.SimpleQueue[tuple] = queue.SimpleQueue()
        self._sub: RingSubscription | None = None
        self._stop = threading.Event()
        self._capture: threading.Thread | None = None
        self._writer: threading.Thread | None = None
        self._run: _OpenRun | None = None
        self._keys = 0
        self._ids: dict[int, int] = {}  # capture key -> database id
        self._processed_seq = 0
        self._seq_cond = threading.Condition()
        self._flush_request = threading.Event()
        self._footprint = np.asarray(session.profile.footprint_polygon(), dtype=float)
        self._pending: list[dict] = []  # events stamped after the snapshot being handled
        self._prerun: deque[dict] = deque(maxlen=32)  # recent events while no run is open
        self._barrier: threading.Event | None = None
        self.errors = 0
        self.closed_on_start: list[dict] = []

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Close runs a crash left open, then start the threads (call before the control loop)."""
        if self._capture is not None:
            return
        self.closed_on_start = self.store.close_unfinished()
        for res in self.closed_on_start:
            s = res["summary"]
            log.warning(
                "run %d was still recording at start-up: closed as interrupted (%.1f s, %d samples kept)",
                res["id"],
                s.get("duration_s") or 0.0,
                s.get("samples", 0),
            )
        self._stop.clear()
        self.session.event_listeners.append(self._on_event)
        self._sub = self.session.bus.attach(RingSubscription(self.session.bus, self.options.buffer))
        self._writer = threading.Thread(target=self._write_loop, name="recorder-writer", daemon=True)
        self._capture = threading.Thread(target=self._capture_loop, name="recorder-capture", daemon=True)
        self._writer.start()
        self._capture.start()

    def close(self) -> None:
        """Finish the open run as ``stopped``, write everything and stop the threads."""
        if self._capture is None:
            return
        if self._on_event in self.session.event_listeners:
            self.session.event_listeners.remove(self._on_event)
        self._stop.set()
        self._capture.join(timeout=10.0)
        self._ops.put(("quit",))
        assert self._writer is not None
        self._writer.join(timeout=30.0)
        if self._sub is not None:
            self._sub.close()
        self._capture = self._writer = self._sub = None

    @property
    def recording(self) -> bool:
        return self._run is not None

    @property
    def current_run_id(self) -> int | None:
        run = self._run
        return None if run is None else self._ids.get(run.key)

    def sync(self, timeout: float = 10.0, *, flush: bool = True) -> None:
        """Wait until every snapshot published so far is captured and (``flush``) written to the
        database (tests, benchmarks)."""
        latest = self.session.bus.latest
        deadline = time.monotonic() + timeout
        if latest is not None:
            with self._seq_cond:
                while self._processed_seq < latest.seq:
                    left = deadline - time.monotonic()
                    if left <= 0 or not self._seq_cond.wait(left):
                        raise TimeoutError("recorder did not catch up")
        if not flush:
            return
        done = threading.Event()
        self._barrier = done
        self._flush_request.set()
        if not done.wait(max(0.0, deadline - time.monotonic())):
            raise TimeoutError("recorder did not flush")

    # ------------------------------------------------------------------ loop thread (O(1) only)
    def _on_event(self, ev: dict) -> None:
        self._events.put(ev)

    # ------------------------------------------------------------------ capture thread
    def _capture_loop(self) -> None:
        assert self._sub is not None
        next_flush = time.monotonic() + self.options.flush_period
        while True:
            stopping = self._stop.is_set()
            snaps = self._sub.wait_all(timeout=0.05) if not stopping else self._sub.take_all()
            try:
                for snap in snaps:
                    self._drain_events(snap.stamp)
                    self._on_snapshot(snap)
                    with self._seq_cond:
                        self._processed_seq = snap.seq
                        self._seq_cond.notify_all()
                self._drain_events(None)
            except Exception:
                self.errors += 1
                log.exception("recorder: capture failed")
            now = time.monotonic()
            barrier = None
            if self._flush_request.is_set():
                self._flush_request.clear()
                barrier, self._barrier = self._barrier, None
            if now >= next_flush or barrier is not None or stopping:
                self._flush()
                next_flush = now + self.options.flush_period
            if barrier is not None:
                self._ops.put(("barrier", barrier))
            if stopping:
                if self._run is not None:
                    self._end_run("stopped", "server shut down", aborted=False)
                return

    def _event_clock(self, ev: dict) -> float:
        return float(ev.get("t", 0.0)) + self.session.started_at

    def _drain_events(self, until: float | None) -> None:
        """Handle queued events stamped at or before ``until`` (all if None), in order."""
        pending = self._pending
        while True:
            try:
                pending.append(self._events.get_nowait())
            except queue.Empty:
                break
        keep = []
        for ev in pending:
            if until is None or self._event_clock(ev) <= until + 1e-9:
                self._on_session_event(ev)
            else:
                keep.append(ev)
        self._pending = keep

    def _on_session_event(self, ev: dict) -> None:
        te = self._event_clock(ev)
        etype = str(ev.get("type", ""))
        if etype == "mode":
            self._on_mode(str(ev.get("to", "")), te, str(ev.get("reason", "")))
        run = self._run
        if run is None:
            if etype != "mode":
                self._prerun.append(ev)  # e.g. a goal set just before the mode switch it causes
            return
        t = max(0.0, te - run.t0)
        run.batch.events.append({**ev, "t": round(t, 3)})
        if etype in GOAL_SET and isinstance(ev.get("pose"), list | tuple) and len(ev["pose"]) >= 2:
            p = [*ev["pose"], 0.0]
            self._new_goal(run, t, Pose2D(float(p[0]), float(p[1]), float(p[2])))
        outcome = goal_outcome(etype)
        if outcome is not None:
            pending = [g for g in run.goals if g["outcome"] == "pending"]
            if pending:
                g = pending[0]
                g.update(outcome=outcome, t_end=round(t, 3), reason=str(ev.get("reason", ""))[:500])
                run.batch.goals.append(dict(g))

    def _on_mode(self, to: str, te: float, reason: str) -> None:
        kind = RUN_KIND.get(to)
        run = self._run
        if kind is not None:
            if run is not None and run.kind != kind:
                self._end_run(None, f"mode changed to {to}", aborted=run.last_active in STOP_MODES)
                run = None
            if run is None:
                self._start_run(kind, te)
            else:
                run.idle_since = None
            assert self._run is not None
            self._run.last_active = to
        elif run is not None:
            if to == "idle":
                run.idle_since = te
            elif to in STOP_MODES:
                run.last_active = to
                run.idle_since = None

    def _start_run(self, kind: str, t0: float) -> None:
        self._keys += 1
        key = self._keys
        lag = max(0.0, self.session.clock.now() - t0) if not self.session.clock.is_virtual else 0.0
        started = datetime.now(UTC) - timedelta(seconds=lag)
        self._run = _OpenRun(key=key, kind=kind, t0=t0, batch=Batch(run_id=-1))
        self._ops.put(("create", key, kind, started))
        early = [ev for ev in self._prerun if self._event_clock(ev) >= t0 - PRE_RUN_WINDOW]
        self._prerun.clear()
        for ev in early:  # stamped t = 0: they belong to this run's start
            self._on_session_event(ev)

    def _end_run(self, outcome: str | None, reason: str, *, aborted: bool) -> None:
        run = self._run
        assert run is not None
        latest = self.session.bus.latest
        if latest is not None and latest.grid is not None and latest.grid is not run.grid_obj:
            run.batch.grids.append((max(0.0, latest.stamp - run.t0), latest.grid_version, latest.grid))
        self._flush()
        self._ops.put(("finish", run.key, outcome, reason, aborted))
        self._run = None

    def _on_snapshot(self, snap: Snapshot) -> None:
        run = self._run
        o = self.options
        if run is not None and run.idle_since is not None and snap.stamp - run.idle_since >= o.idle_grace:
            self._end_run(None, f"idle for {o.idle_grace:g} s", aborted=run.last_active in STOP_MODES)
            run = None
        if run is None and snap.mode in RUN_KIND and self._events.empty() and not self._pending:
            self._start_run(RUN_KIND[snap.mode], snap.stamp)  # e.g. the recorder started mid-session
            run = self._run
            assert run is not None
            run.last_active = snap.mode
        if run is None:
            return
        t = max(0.0, snap.stamp - run.t0)
        self._capture_grid(run, snap, t)
        self._capture_scan(run, snap, t)
        if snap.goal is not None and snap.goal != run.last_snap_goal and snap.goal.is_finite():
            run.last_snap_goal = snap.goal  # a goal still shown after its outcome is not a new goal
            if not _listed(run.goals, snap.goal):  # waypoints announced by ``goal`` events are listed
                self._new_goal(run, t, snap.goal)
        self._capture_plan(run, snap, t)
        if snap.behavior != run.last_behavior:
            run.batch.events.append({"t": round(t, 3), "type": "behavior", "behavior": snap.behavior})
            run.last_behavior = snap.behavior
        if run.last_odom is not None:
            run.distance += run.last_odom.distance_to(snap.odom_pose)
        run.last_odom = snap.odom_pose
        # On a schedule (not "period since the last sample"), with half a loop period of tolerance, so
        # loop jitter cannot turn 10 Hz into 6.7 Hz.
        if snap.stamp >= run.next_sample - 0.5 * self.session.period:
            due = run.next_sample + o.sample_period
            run.next_sample = due if due > snap.stamp else snap.stamp + o.sample_period
            run.batch.samples.append(self._sample_row(run, snap, t))
            run.batch.duration_s = t
            run.batch.distance_m = run.distance

    def _sample_row(self, run: _OpenRun, snap: Snapshot, t: float) -> tuple:
        labels = run.batch.labels
        beh = 0
        if snap.behavior:
            if snap.behavior not in labels:
                labels.append(snap.behavior)
            beh = labels.index(snap.behavior)
        cx, cy, ct = covariance_diag(snap.extras)
        p, q, v, c = snap.pose, snap.odom_pose, snap.velocity, snap.command
        return (
            t, p.x, p.y, p.theta, q.x, q.y, q.theta, v.vx, v.vy, v.wz, c.vx, c.vy, c.wz,
            cx, cy, ct, run.clearance, MODE_CODE.get(snap.mode, 0), min(beh, 255),
        )  # fmt: skip

    def _capture_scan(self, run: _OpenRun, snap: Snapshot, t: float) -> None:
        scan: LaserScan | None = snap.scan
        if scan is None or scan.stamp == run.last_scan_stamp:
            return
        run.last_scan_stamp = scan.stamp
        pts = snap.laser_pose.transform_points(scan.points()) if scan.ranges.size else np.zeros((0, 2))
        run.clearance = footprint_clearance(pts, self._footprint)
        if snap.stamp - run.last_scan_t >= self.options.scan_period - 1e-6:
            run.last_scan_t = snap.stamp
            run.batch.scan_times.append(t)
            run.batch.scans.append(scan)

    def _capture_plan(self, run: _OpenRun, snap: Snapshot, t: float) -> None:
        path = snap.path
        if path is run.last_plan_obj:
            return
        run.last_plan_obj = path
        poses = np.zeros((0, 3)) if path is None else np.asarray(path.poses, dtype=float).reshape(-1, 3)
        last = run.last_plan
        if last is None and poses.shape[0] == 0:
            return
        same = (
            last is not None
            and last.shape == poses.shape
            and (poses.size == 0 or float(np.abs(last - poses).max()) < self.options.plan_tolerance)
        )
        if not same:
            run.last_plan = poses
            run.batch.plans.append((t, poses))

    def _capture_grid(self, run: _OpenRun, snap: Snapshot, t: float) -> None:
        if snap.grid is None or snap.grid is run.grid_obj:
            return
        if run.grid_obj is None or snap.stamp - run.grid_t >= self.options.grid_period:
            run.grid_obj, run.grid_t, run.grid_version = snap.grid, snap.stamp, snap.grid_version
            run.batch.grids.append((t, snap.grid_version, snap.grid))

    def _new_goal(self, run: _OpenRun, t: float, pose: Pose2D) -> None:
        if run.goals and _same_pose(run.goals[-1], pose):
            return
        g = {"t": round(t, 3), "x": pose.x, "y": pose.y, "theta": pose.theta, "outcome": "pending"}
        run.goals.append(g)
        run.batch.goals.append(dict(g))

    def _flush(self) -> None:
        run = self._run
        if run is None or run.batch.empty():
            return
        batch, run.batch = run.batch, Batch(run_id=-1)
        self._ops.put(("batch", run.key, batch))

    # ------------------------------------------------------------------ writer thread
    def _write_loop(self) -> None:
        while True:
            op = self._ops.get()
            try:
                if op[0] == "quit":
                    return
                self._write_op(op)
            except Exception:
                self.errors += 1
                log.exception("recorder: write failed (%s)", op[0])
                if op[0] == "barrier":
                    op[1].set()

    def _write_op(self, op: tuple) -> None:
        kind = op[0]
        if kind == "create":
            _, key, run_kind, started = op
            self._ids[key] = self.store.create_run(
                run_kind,
                robot_name=self.session.robot_name,
                profile=self.profile_name,
                map_id=self.map_id(),
                started_at=started,
                summary={"laser_pose": list(self._laser_pose()), "footprint": self._footprint.tolist()},
            )
            log.info("run %d started (%s)", self._ids[key], run_kind)
        elif kind == "batch":
            _, key, batch = op
            batch.run_id = self._ids[key]
            self.store.write(batch)
        elif kind == "finish":
            _, key, outcome, reason, aborted = op
            rid = self._ids.pop(key)
            res = self.store.finish(
                rid,
                outcome or "completed",
                end_reason=reason,
                outcome_fn=None if outcome else (lambda k, s: outcome_for(k, s, aborted)),
            )
            log.info("run %d ended: %s (%s)", rid, res["outcome"], reason)
        elif kind == "barrier":
            op[1].set()

    def _laser_pose(self) -> tuple[float, float, float]:
        lid = self.session.profile.lidar
        return lid.mount_x, lid.mount_y, lid.mount_yaw


def _same_pose(g: dict, pose: Pose2D) -> bool:
    return math.hypot(g["x"] - pose.x, g["y"] - pose.y) < 1e-3 and abs(g["theta"] - pose.theta) < 1e-3


def _listed(goals: list[dict], pose: Pose2D) -> bool:
    """Whether the run's goal list has ``pose`` already (the goal the robot drives to now is one of
    the waypoints its request announced, not a new goal: issue 22 item 6)."""
    return any(_same_pose(g, pose) for g in goals)
