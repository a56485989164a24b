"""Recorded bags as runs: a ROS bag (ROS1, ROS 2 ``.db3`` / ``.mcap`` or a zipped/tarred rosbag2
directory) becomes a finished run like a live one, reviewable on the Runs page and in the 3D replay.

The bag is read by :func:`robot.logs.reader.load_raw_log` (topics, typestore and laser mount found
by themselves), its map built by offline SLAM (``nav.slam.offline.run_offline``, the same code as
``navdeck slam``), then stored as the recorder stores a live run: 10 Hz samples (map pose from the
SLAM trajectory, odom pose, measured velocity from the odometry twist or else differentiated odometry,
velocity commands from ``*cmd_vel*`` held 0.5 s), scans at 2 Hz, WARN+ ``/rosout`` lines as ``log``
events, and the final map. Run time ``t`` counts from the first scan; ``started_at`` is that
scan's stamp. Imports run one at a time on a worker thread; :class:`BagImports` tracks them.
"""

from __future__ import annotations

import logging
import shutil
import tarfile
import tempfile
import threading
import time
import zipfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from itertools import count
from pathlib import Path
from typing import BinaryIO, Literal

import numpy as np

from app.runs import codec
from app.runs.store import Batch, RunsStore
from nav.slam.offline import run_offline
from nav.slam.system import SlamError, SlamOptions
from nav.slam.time_offset import interpolate_poses
from nav.types import OccupancyGrid, wrap_angle
from robot.logs.errors import LogError
from robot.logs.reader import LogRecord, RawLog, load_raw_log
from robot.logs.rosbag import BagExtras

log = logging.getLogger("navdeck.runs.import")

SAMPLE_PERIOD = 0.1  # s, as the live recorder (RecorderOptions.sample_period)
SCAN_PERIOD = 0.5  # s, as the live recorder (RecorderOptions.scan_period)
CHUNK_SECONDS = 10.0  # one stored chunk per 10 s of samples (a live run flushes every 0.5 s)
COMMAND_TIMEOUT = 0.5  # s a velocity command is held (a robot base stops after it)
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
ARCHIVE_SUFFIXES = (".zip", ".tar", ".tar.gz", ".tgz")
MAGIC = {b"#ROSBAG": ".bag", b"\x89MCAP": ".mcap", b"SQLite format 3\x00": ".db3"}

State = Literal["queued", "reading", "mapping", "storing", "done", "failed"]


class ImportInputError(ValueError):
    """An upload that is not a bag (checked before any work starts)."""


class ImportCanceled(RuntimeError):
    """The server is shutting down: the import stops and stores nothing."""


@dataclass
class ImportJob:
    id: int
    file: str
    size_bytes: int
    state: State = "queued"
    scans_done: int = 0
    scans_total: int = 0
    run_id: int | None = None
    notes: list[str] = field(default_factory=list)
    error: str = ""
    started: float = field(default_factory=time.monotonic)
    elapsed_s: float = 0.0
    cpu_s: float = 0.0  # the worker thread's CPU time (benchmarks)


# --------------------------------------------------------------------------------------- the upload
def _suffix(name: str) -> str:
    low = name.lower()
    for s in (*ARCHIVE_SUFFIXES, *BAG_SUFFIXES):
        if low.endswith(s):
            return s
    return ""


def stage_upload(stream: BinaryIO, filename: str, workdir: Path) -> Path:
    """Copy an upload into ``workdir`` and return the bag path to read: the file itself, or the
    rosbag2 directory (or single bag file) inside an archive. Raises :class:`ImportInputError`."""
    name = Path(filename or "upload").name
    kind = _suffix(name)
    dest = workdir / (name if kind else "upload")
    with dest.open("wb") as f:
        shutil.copyfileobj(stream, f, 1 << 20)
    if dest.stat().st_size == 0:
        raise ImportInputError(f"{name}: the upload is empty")
    with dest.open("rb") as f:
        head = f.read(16)
    sniffed = next((ext for magic, ext in MAGIC.items() if head.startswith(magic)), "")
    if kind in BAG_SUFFIXES or (not kind and sniffed):
        if sniffed != (kind or sniffed):
            raise ImportInputError(f"{name}: not a {kind} file (its first bytes say otherwise)")
        if not kind:
            dest = dest.rename(dest.with_suffix(sniffed))
        return dest
    if kind in ARCHIVE_SUFFIXES:
        return _unpack(dest, workdir / "unpacked", name)
    raise ImportInputError(
        f"{name}: not a bag: upload a ROS1 .bag, a ROS 2 .db3 or .mcap file, or a rosbag2 directory "
        "as .zip / .tar.gz"
    )


def _unpack(archive: Path, out: Path, name: str) -> Path:
    out.mkdir()
    try:
        if zipfile.is_zipfile(archive):
            with zipfile.ZipFile(archive) as z:
                for m in z.namelist():
                    if Path(m).is_absolute() or ".." in Path(m).parts:
                        raise ImportInputError(f"{name}: archive member {m!r} points outside the archive")
                z.extractall(out)
        else:
            with tarfile.open(archive) as t:
                t.extractall(out, filter="data")
    except (zipfile.BadZipFile, tarfile.TarError, OSError) as exc:
        raise ImportInputError(f"{name}: not a readable archive ({exc})") from None
    metas = sorted(out.rglob("metadata.yaml"))
    if metas:
        return metas[0].parent
    files = sorted(p for s in BAG_SUFFIXES for p in out.rglob(f"*{s}"))
    if len(files) == 1:
        return files[0]
    raise ImportInputError(
        f"{name}: the archive holds no rosbag2 directory (metadata.yaml) and "
        f"{'several' if files else 'no'} bag files"
    )


# ------------------------------------------------------------------------------------ bag -> samples
def body_velocity(t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, 3) body-frame (vx, vy, wz) from poses sampled at times ``t`` (central differences)."""
    if t.shape[0] < 2:
        return np.zeros((t.shape[0], 3))
    dt = np.gradient(t)
    dx, dy = np.gradient(poses[:, 0]), np.gradient(poses[:, 1])
    dth = np.gradient(np.unwrap(poses[:, 2]))
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    dt = np.where(dt > 0, dt, np.inf)
    return np.column_stack(((c * dx + s * dy) / dt, (-s * dx + c * dy) / dt, dth / dt))


def held(t_query: np.ndarray, t: np.ndarray, values: np.ndarray, timeout: float) -> np.ndarray:
    """Zero-order hold of ``values`` (M, 3) at ``t_query``; zero before the first and after ``timeout``."""
    out = np.zeros((t_query.shape[0], 3))
    if t.shape[0] == 0:
        return out
    order = np.argsort(t, kind="stable")
    t, values = t[order], values[order]
    i = np.searchsorted(t, t_query, side="right") - 1
    ok = (i >= 0) & (t_query - t[np.maximum(i, 0)] <= timeout)
    out[ok] = values[i[ok]]
    return out


def build_samples(raw: RawLog, t_corr: np.ndarray, corr: np.ndarray, t0: float, t_end: float) -> np.ndarray:
    """10 Hz SAMPLE_DTYPE rows from ``t0`` to ``t_end`` (seconds on the bag's clock). The map pose is
    map -> odom (``corr`` at ``t_corr``, interpolated) composed with the odometry at each sample, as
    a live robot's is: smooth between scans, exact at them."""
    t_run = np.arange(0.0, t_end - t0 + 1e-9, SAMPLE_PERIOD)
    ts = t_run + t0
    odom = interpolate_poses(ts, raw.t_odom, raw.odom)
    pose = compose_poses(interpolate_poses(ts, t_corr, corr), odom)
    ex = raw.extras or BagExtras()
    twist = np.asarray(ex.twist, float).reshape(-1, 3)
    if twist.size and np.abs(twist).max() > 0:  # converters often leave the twist zero
        vel = np.column_stack([np.interp(ts, np.asarray(ex.t_twist), twist[:, k]) for k in range(3)])
    else:
        vel = body_velocity(ts, odom)
    cmd = held(ts, np.asarray(ex.t_cmd, float), np.asarray(ex.cmd, float).reshape(-1, 3), COMMAND_TIMEOUT)
    out = np.zeros(t_run.shape[0], dtype=codec.SAMPLE_DTYPE)
    out["t"] = t_run
    out["x"], out["y"], out["theta"] = pose[:, 0], pose[:, 1], wrap_angle(pose[:, 2])
    out["ox"], out["oy"], out["otheta"] = odom[:, 0], odom[:, 1], wrap_angle(odom[:, 2])
    out["vx"], out["vy"], out["wz"] = vel[:, 0], vel[:, 1], vel[:, 2]
    out["cmd_vx"], out["cmd_vy"], out["cmd_wz"] = cmd[:, 0], cmd[:, 1], cmd[:, 2]
    for k in ("cov_x", "cov_y", "cov_theta", "clearance"):  # no localization estimate, no footprint
        out[k] = np.nan
    out["mode"] = codec.MODE_CODE["mapping"]
    return out


def scan_picks(stamps: np.ndarray, t0: float) -> np.ndarray:
    """Indices of the scans kept: the first of every ``SCAN_PERIOD`` slot, as the recorder keeps them."""
    _, first = np.unique(np.floor((stamps - t0) / SCAN_PERIOD).astype(np.int64), return_index=True)
    return first


def compose_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a (+) b for (N, 3) poses (b expressed in a's frame)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack(
        (
            a[:, 0] + c * b[:, 0] - s * b[:, 1],
            a[:, 1] + s * b[:, 0] + c * b[:, 1],
            wrap_angle(a[:, 2] + b[:, 2]),
        )
    )


def inverse_poses(p: np.ndarray) -> np.ndarray:
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    return np.column_stack((-c * p[:, 0] - s * p[:, 1], s * p[:, 0] - c * p[:, 1], -p[:, 2]))


def map_correction(traj: np.ndarray, raw: RawLog) -> np.ndarray:
    """map -> odom at each SLAM pose: ``traj`` (N, 4: t, x, y, theta of base_link in map) composed
    with the inverse of the odometry at the same stamps."""
    odom = interpolate_poses(traj[:, 0], raw.t_odom, raw.odom)
    return compose_poses(traj[:, 1:], inverse_poses(odom))


def bag_to_run(
    store: RunsStore,
    bag: Path,
    name: str,
    *,
    options: SlamOptions | None = None,
    on_state: Callable[[State], None] = lambda s: None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[int, list[str]]:
    """Read ``bag``, map it (or take its recorded map and localization), store it as a finished run;
    returns (run id, notes). Raises ``LogError`` / ``SlamError`` with one line saying what is wrong."""
    on_state("reading")
    raw = load_raw_log(bag, extras=True)
    records = raw.records()
    ex = raw.extras or BagExtras()
    notes = list(raw.notes)
    stamps = np.array([float(r.stamp) for r in records])
    info: dict = {"file": name, "scans": len(records), "commands": bool(ex.cmd)}
    if ex.grid is not None and ex.map_odom:
        # the robot mapped or localized itself: its map and its map-frame poses, as it saw them
        notes.append(f"map: the bag's own ({ex.map_topic} and /tf map -> odom); no SLAM run")
        t_corr, corr = np.asarray(ex.t_map_odom), np.asarray(ex.map_odom).reshape(-1, 3)
        grid = ex.grid
        info["map"] = f"recorded {ex.map_topic}"
    else:
        if ex.grid is not None:
            notes.append(f"map: {ex.map_topic} recorded but no /tf map -> odom; built by offline SLAM")
        else:
            notes.append("map: none in the bag; built by offline SLAM")
        on_state("mapping")
        odometry = (raw.t_odom, raw.odom)
        slam = run_offline(records, raw.laser, options or SlamOptions(), progress, odometry=odometry)
        traj, grid = slam.trajectory(), slam.map()
        t_corr, corr = traj[:, 0], map_correction(traj, raw)
        info.update(
            map="offline SLAM",
            nodes=slam.num_nodes,
            loop_closures=slam.num_loop_closures,
            odometry_lag_ms=round(slam.odometry_lag * 1e3, 1),
        )
    on_state("storing")
    t0 = float(stamps[0])
    samples = build_samples(raw, t_corr, corr, t0, float(stamps[-1]))
    laser = raw.laser
    summary = {"laser_pose": [laser.x, laser.y, laser.theta], "imported": {**info, "notes": notes}}
    run_id = store.create_run(
        "mapping", robot_name="", started_at=datetime.fromtimestamp(t0, UTC), summary=summary
    )
    try:
        _store_run(store, run_id, name, samples, stamps, t0, records, raw, grid)
    except BaseException:
        store.delete(run_id)  # no half-stored run left behind
        raise
    return run_id, notes


def _store_run(
    store: RunsStore,
    run_id: int,
    name: str,
    samples: np.ndarray,
    stamps: np.ndarray,
    t0: float,
    records: list[LogRecord],
    raw: RawLog,
    grid: OccupancyGrid,
) -> None:
    events = [{"t": 0.0, "type": "imported", "file": name}] + [
        {**e, "t": round(max(0.0, e["t"] - t0), 3)} for e in (raw.extras.events if raw.extras else [])
    ]
    picks = scan_picks(stamps, t0)
    scan_t = stamps[picks] - t0
    edges = np.arange(0.0, samples["t"][-1] + CHUNK_SECONDS, CHUNK_SECONDS)
    for k, lo in enumerate(edges):
        hi = lo + CHUNK_SECONDS
        last = k == len(edges) - 1
        s_sel = (samples["t"] >= lo) & ((samples["t"] < hi) | last)
        c_sel = np.flatnonzero((scan_t >= lo) & ((scan_t < hi) | last))
        batch = Batch(
            run_id=run_id,
            samples=samples[s_sel].tolist(),
            scan_times=[float(scan_t[i]) for i in c_sel],
            scans=[records[int(picks[i])].scan for i in c_sel],
            events=[e for e in events if lo <= e["t"] < hi or (last and e["t"] >= hi)],
        )
        if not batch.empty():
            store.write(batch)
    store.write(Batch(run_id=run_id, grids=[(0.0, 1, grid)]))
    store.finish(run_id, "completed", end_reason=f"imported from {name}")


# --------------------------------------------------------------------------------------------- jobs
class BagImports:
    """Imports queued on one worker thread (SLAM is CPU-bound: two at once would only halve both)."""

    def __init__(self, store: RunsStore, options: SlamOptions | None = None) -> None:
        self.store = store
        self.options = options
        self._jobs: dict[int, ImportJob] = {}
        self._ids = count(1)
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="bag-import")
        self._closing = threading.Event()

    def submit(self, stream: BinaryIO, filename: str) -> ImportJob:
        """Stage the upload (ImportInputError at once for what is not a bag) and queue the import."""
        workdir = Path(tempfile.mkdtemp(prefix="navdeck-import-"))
        try:
            bag = stage_upload(stream, filename, workdir)
        except BaseException:
            shutil.rmtree(workdir, ignore_errors=True)
            raise
        size = sum(p.stat().st_size for p in workdir.iterdir() if p.is_file())
        with self._lock:
            job = ImportJob(id=next(self._ids), file=Path(filename or "upload").name, size_bytes=size)
            self._jobs[job.id] = job
        self._pool.submit(self._run, job, bag, workdir)
        return job

    def get(self, job_id: int) -> ImportJob | None:
        with self._lock:
            job = self._jobs.get(job_id)
            if job is not None and job.state not in ("done", "failed"):
                job.elapsed_s = time.monotonic() - job.started
            return job

    def _run(self, job: ImportJob, bag: Path, workdir: Path) -> None:
        def state(s: State) -> None:
            job.state = s

        def progress(done: int, total: int) -> None:
            if self._closing.is_set():
                raise ImportCanceled("the server is shutting down")
            job.scans_done, job.scans_total = done, total

        job.started = time.monotonic()
        cpu0 = time.thread_time()
        try:
            job.run_id, job.notes = bag_to_run(
                self.store, bag, job.file, options=self.options, on_state=state, progress=progress
            )
            job.state = "done"
        except (LogError, SlamError, ImportCanceled) as exc:
            job.error, job.state = str(exc), "failed"
        except Exception as exc:  # a worker must report, never die silently
            log.exception("import of %s failed", job.file)
            job.error, job.state = f"{job.file}: import failed ({type(exc).__name__}: {exc})", "failed"
        finally:
            job.elapsed_s = time.monotonic() - job.started
            job.cpu_s = time.thread_time() - cpu0
            shutil.rmtree(workdir, ignore_errors=True)

    def close(self) -> None:
        """Drop queued imports and stop the running one at its next scan (a server shutting down
        must not wait minutes for a SLAM run)."""
        self._closing.set()
        self._pool.shutdown(wait=False, cancel_futures=True)
