"""Replay a stored run into the 3D view: stored samples -> Snapshots on a private SnapshotBus.

The replay bus feeds a second ``app.viewer.scene.Viewer`` (its own viser server, relayed at
``/replay/viz``), so the same scene handles as the live view draw the robot pose, scan, plan, goal,
trail and map as they were, while the live view keeps running for everyone else. One player per
server (one replay at a time); play, pause, speed and seek are thread-safe and cheap: a seek is one
binary search in the samples held in memory plus one indexed scan-chunk read.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

import numpy as np

from app.bus import Snapshot, SnapshotBus
from app.runs.codec import MODES
from app.runs.store import RunsStore
from nav.types import LaserScan, OccupancyGrid, Path, Pose2D, Twist2D

log = logging.getLogger("navdeck.replay")


class ReplayError(RuntimeError):
    """Nothing loaded, or the run has no samples to replay."""


@dataclass(frozen=True)
class ReplayOptions:
    rate_hz: float = 15.0
    """Snapshots published per second of wall time while playing (the viewer's update rate)."""
    max_speed: float = 20.0
    """Largest playback speed factor accepted."""
    trail_points: int = 2000
    """Trail drawn behind the robot, decimated to at most this many points."""


class ReplayPlayer:
    def __init__(self, store: RunsStore, options: ReplayOptions | None = None, footprint=None) -> None:
        self.store = store
        self.options = options or ReplayOptions()
        self.bus = SnapshotBus()
        self.viewer = None  # set by whoever starts a Viewer on self.bus
        self._footprint = footprint
        self._lock = threading.Lock()
        self._run_id: int | None = None
        self._samples: np.ndarray | None = None
        self._labels: list[str] = [""]
        self._plans: list[tuple[float, np.ndarray]] = []
        self._plan_times = np.zeros(0)
        self._grids: list[tuple[float, int, OccupancyGrid]] = []
        self._goals: list[dict] = []
        self._laser = Pose2D()
        self._t = 0.0
        self._speed = 1.0
        self._playing = False
        self._seq = 0
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ control
    def load(self, run_id: int) -> dict:
        """Load a run (RunNotFound) and show its first instant, paused."""
        run = self.store.run(run_id)
        samples, labels = self.store.samples(run_id)
        if samples.shape[0] == 0:
            raise ReplayError(f"run {run_id} has no samples to replay")
        plans = self.store.plans(run_id)
        lp = run.get("summary", {}).get("laser_pose") or [0.0, 0.0, 0.0]
        with self._lock:
            self._run_id, self._samples, self._labels = run_id, samples, labels
            self._plans = plans
            self._plan_times = np.array([t for t, _ in plans])
            self._grids = self.store.grids(run_id)
            self._goals = self.store.goals(run_id)
            self._laser = Pose2D(*map(float, lp[:3]))
            self._t, self._playing = float(samples["t"][0]), False
        self._ensure_thread()
        self.publish()
        return self.state()

    def play(self) -> dict:
        self._require()
        with self._lock:
            if self._t >= self.duration:
                self._t = 0.0
            self._playing = True
        self._wake.set()
        return self.state()

    def pause(self) -> dict:
        with self._lock:
            self._playing = False
        return self.state()

    def set_speed(self, speed: float) -> dict:
        if not 0.0 < speed <= self.options.max_speed:
            raise ValueError(f"speed must be in (0, {self.options.max_speed:g}]")
        with self._lock:
            self._speed = float(speed)
        return self.state()

    def seek(self, t: float) -> dict:
        """Jump to run time ``t`` (clamped to the run) and publish that instant at once."""
        self._require()
        with self._lock:
            self._t = float(np.clip(t, 0.0, self.duration))
        self.publish()
        return self.state()

    @property
    def duration(self) -> float:
        s = self._samples
        return 0.0 if s is None else float(s["t"][-1])

    def state(self) -> dict:
        with self._lock:
            return {
                "run_id": self._run_id,
                "t": round(self._t, 3),
                "duration": round(self.duration, 3),
                "playing": self._playing,
                "speed": self._speed,
                "viewer": self.viewer is not None,
            }

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self.viewer is not None:
            try:
                self.viewer.stop()
            except Exception:
                log.exception("replay viewer stop failed")
            self.viewer = None

    # ------------------------------------------------------------------ snapshots
    def _require(self) -> None:
        if self._samples is None:
            raise ReplayError("no run loaded")

    def publish(self) -> Snapshot:
        snap = self.snapshot_at(self._t)
        self.bus.publish(snap)
        return snap

    def snapshot_at(self, t: float) -> Snapshot:
        """The run as it was at run time ``t``: last sample <= t, last scan, plan and map <= t."""
        self._require()
        with self._lock:
            s, labels, run_id = self._samples, self._labels, self._run_id
        assert s is not None and run_id is not None
        i = max(0, int(np.searchsorted(s["t"], t, side="right")) - 1)
        row = s[i]
        scan_hit = self.store.scan_at(run_id, t)
        scan: LaserScan | None = None if scan_hit is None else scan_hit[1]
        j = int(np.searchsorted(self._plan_times, t, side="right")) - 1
        plan = None
        if j >= 0 and self._plans[j][1].shape[0] > 0:
            plan = Path(self._plans[j][1])
        grid, version = None, 0
        for gt, gv, g in self._grids:
            if gt <= t or grid is None:
                grid, version = g, gv
        goal = None
        for g in self._goals:
            if g["t"] <= t and (g["t_end"] is None or g["t_end"] >= t):
                goal = Pose2D(g["x"], g["y"], g["theta"])
        step = max(1, (i + 1) // self.options.trail_points)
        trail = np.column_stack((s["x"][: i + 1 : step], s["y"][: i + 1 : step])).astype(float)
        self._seq += 1
        beh = int(row["behavior"])
        extras = {"replay": {"run_id": run_id, "t": round(float(t), 3)}}
        if self._footprint is not None:
            extras["footprint"] = self._footprint
        return Snapshot(
            stamp=float(t),
            seq=self._seq,
            mode=MODES[int(row["mode"])] if int(row["mode"]) < len(MODES) else "idle",
            pose=Pose2D(float(row["x"]), float(row["y"]), float(row["theta"])),
            odom_pose=Pose2D(float(row["ox"]), float(row["oy"]), float(row["otheta"])),
            velocity=Twist2D(float(row["vx"]), float(row["vy"]), float(row["wz"])),
            command=Twist2D(float(row["cmd_vx"]), float(row["cmd_vy"]), float(row["cmd_wz"])),
            scan=scan,
            laser_pose=self._laser,
            trail=trail,
            grid=grid,
            grid_version=version,
            path=plan,
            goal=goal,
            behavior=labels[beh] if 0 < beh < len(labels) else None,
            extras=extras,
        )

    # ------------------------------------------------------------------ playback thread
    def _ensure_thread(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, name="replay", daemon=True)
            self._thread.start()

    def _loop(self) -> None:
        period = 1.0 / self.options.rate_hz
        last = time.monotonic()
        while not self._stop.is_set():
            if not self._playing:
                self._wake.wait(0.25)
                self._wake.clear()
                last = time.monotonic()
                continue
            time.sleep(period)
            now = time.monotonic()
            with self._lock:
                self._t = min(self._t + (now - last) * self._speed, self.duration)
                if self._t >= self.duration:
                    self._playing = False
            last = now
            try:
                self.publish()
            except Exception:
                log.exception("replay: publish failed")
