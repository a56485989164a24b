"""Runs in the database: one writer (the recorder thread) appends batches, any thread reads.

Every write is one short transaction (SQLite WAL: readers never block it, it never blocks them).
Reads decode the compact chunks of ``app.runs.codec`` back into numpy arrays and ``LaserScan``s.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np
from sqlalchemy import delete, func
from sqlalchemy.engine import Engine
from sqlmodel import Session, col, select

from app.models import Run, RunEvent, RunGoal, RunGrid, RunPlan, RunSampleChunk, RunScanChunk
from app.runs import codec
from app.runs.metrics import summarize
from nav.types import GridGeometry, LaserScan, OccupancyGrid, Pose2D

log = logging.getLogger("navdeck.runs")

KINDS = ("teleop", "mapping", "navigation")
OUTCOMES = ("recording", "completed", "succeeded", "failed", "aborted", "stopped", "interrupted")
CHILD_TABLES = (RunEvent, RunSampleChunk, RunScanChunk, RunPlan, RunGoal, RunGrid)


class RunNotFound(LookupError):
    """No run with that id."""


def utc_aware(dt: datetime | None = None) -> datetime:
    """A timezone-aware UTC datetime (naive input is taken as UTC)."""
    dt = dt or datetime.now(UTC)
    return dt.replace(tzinfo=UTC) if dt.tzinfo is None else dt.astimezone(UTC)


def iso(dt: datetime | None) -> str | None:
    return None if dt is None else utc_aware(dt).isoformat().replace("+00:00", "Z")


@dataclass(frozen=True)
class RunFilters:
    """List filters (all optional, combined with AND). Dates compare with ``started_at`` (UTC)."""

    kind: str | None = None
    outcome: str | None = None
    map_id: int | None = None
    robot: str | None = None
    since: datetime | None = None
    until: datetime | None = None


@dataclass
class Batch:
    """What the recorder gathered for one run since its last flush (<= 1 s)."""

    run_id: int
    samples: list[tuple] = field(default_factory=list)  # SAMPLE_DTYPE rows
    labels: list[str] = field(default_factory=lambda: [""])  # behaviour codes of this batch
    scan_times: list[float] = field(default_factory=list)
    scans: list[LaserScan] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)  # {"t", "type", ...payload}
    plans: list[tuple[float, np.ndarray]] = field(default_factory=list)
    goals: list[dict] = field(default_factory=list)  # {"t","x","y","theta","outcome",...}: new or outcome
    grids: list[tuple[float, int, OccupancyGrid]] = field(default_factory=list)
    duration_s: float | None = None
    distance_m: float | None = None

    def empty(self) -> bool:
        return not (self.samples or self.scans or self.events or self.plans or self.goals or self.grids)


def run_dict(r: Run) -> dict:
    return {
        "id": r.id,
        "kind": r.kind,
        "robot": r.robot_name,
        "robot_id": r.robot_id,
        "profile": r.profile,
        "map_id": r.map_id,
        "started_at": iso(r.started_at),
        "ended_at": iso(r.ended_at),
        "outcome": r.outcome,
        "end_reason": r.end_reason,
        "duration_s": round(r.duration_s, 3),
        "distance_m": round(r.distance_m, 3),
        "summary": r.summary,
    }


def event_dict(e: RunEvent) -> dict:
    return {"t": e.t, "type": e.type, **(e.payload or {})}


def goal_dict(g: RunGoal) -> dict:
    return {
        "t": g.t,
        "t_end": g.t_end,
        "x": g.x,
        "y": g.y,
        "theta": g.theta,
        "outcome": g.outcome,
        "reason": g.reason,
    }


def _grid(rec: RunGrid) -> OccupancyGrid:
    geom = GridGeometry(
        rec.resolution, rec.width, rec.height, Pose2D(rec.origin_x, rec.origin_y, rec.origin_yaw)
    )
    return OccupancyGrid(geom, codec.unpack_grid(rec.data, rec.height, rec.width))


class RunsStore:
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    # ------------------------------------------------------------------ writing (recorder thread)
    def create_run(
        self,
        kind: str,
        *,
        robot_name: str = "",
        profile: str = "",
        map_id: int | None = None,
        started_at: datetime | None = None,
        summary: dict | None = None,
    ) -> int:
        run = Run(
            kind=kind,
            robot_name=robot_name,
            profile=profile,
            map_id=map_id,
            started_at=utc_aware(started_at),
            outcome="recording",
            summary=summary or {},
        )
        with Session(self.engine, expire_on_commit=False) as s:
            s.add(run)
            s.commit()
            assert run.id is not None
            return run.id

    def write(self, batch: Batch) -> None:
        """Append one batch in one transaction."""
        rid = batch.run_id
        with Session(self.engine) as s:
            if batch.samples:
                arr = np.array(batch.samples, dtype=codec.SAMPLE_DTYPE)
                s.add(
                    RunSampleChunk(
                        run_id=rid,
                        t0=float(arr["t"][0]),
                        t1=float(arr["t"][-1]),
                        n=arr.shape[0],
                        labels=list(batch.labels),
                        data=codec.pack_samples(arr),
                    )
                )
            if batch.scans:
                s.add(
                    RunScanChunk(
                        run_id=rid,
                        t0=batch.scan_times[0],
                        t1=batch.scan_times[-1],
                        n=len(batch.scans),
                        data=codec.pack_scans(batch.scan_times, batch.scans),
                    )
                )
            for ev in batch.events:
                payload = {k: v for k, v in ev.items() if k not in ("t", "type")}
                s.add(RunEvent(run_id=rid, t=float(ev["t"]), type=str(ev["type"])[:50], payload=payload))
            for t, poses in batch.plans:
                p = np.asarray(poses, dtype=float).reshape(-1, 3)
                length = float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum()) if len(p) > 1 else 0.0
                s.add(RunPlan(run_id=rid, t=t, n=len(p), length_m=length, data=codec.pack_path(p)))
            for g in batch.goals:
                # A new goal is a new row; an outcome updates the oldest pending row set at that t: the
                # waypoints of one request share a t, and the recorder resolves goals in order (keyed
                # by t alone, they collapsed into one row: issue 22 item 6).
                rec = None
                if g.get("outcome", "pending") != "pending":
                    q = select(RunGoal).where(
                        RunGoal.run_id == rid, RunGoal.t == g["t"], RunGoal.outcome == "pending"
                    )
                    rec = s.exec(q.order_by(RunGoal.id)).first()
                rec = rec or RunGoal(run_id=rid, t=g["t"], x=g["x"], y=g["y"], theta=g["theta"])
                rec.outcome, rec.reason, rec.t_end = (
                    g.get("outcome", "pending"),
                    g.get("reason", ""),
                    g.get("t_end"),
                )
                s.add(rec)
            for t, version, grid in batch.grids:
                geo = grid.geometry
                s.add(
                    RunGrid(
                        run_id=rid,
                        t=t,
                        version=version,
                        resolution=geo.resolution,
                        origin_x=geo.origin.x,
                        origin_y=geo.origin.y,
                        origin_yaw=geo.origin.theta,
                        width=geo.width,
                        height=geo.height,
                        data=codec.pack_grid(grid.data),
                    )
                )
            if batch.duration_s is not None or batch.distance_m is not None:
                run = s.get(Run, rid)
                if run is not None:
                    if batch.duration_s is not None:
                        run.duration_s = max(run.duration_s, batch.duration_s)
                    if batch.distance_m is not None:
                        run.distance_m = batch.distance_m
                    s.add(run)
            s.commit()

    def finish(self, run_id: int, outcome: str, *, end_reason: str = "", outcome_fn=None) -> dict:
        """Close a run: summary from its stored data, ``ended_at`` = start + recorded duration.

        ``outcome_fn(kind, summary) -> str`` may pick the outcome from the summary instead."""
        samples, _ = self.samples(run_id)
        events = self.events(run_id)
        goals = self.goals(run_id)
        summary = summarize(samples, events, goals)
        with Session(self.engine) as s:
            run = s.get(Run, run_id)
            if run is None:
                raise RunNotFound(run_id)
            for g in s.exec(select(RunGoal).where(RunGoal.run_id == run_id, RunGoal.outcome == "pending")):
                g.outcome = "canceled" if outcome != "interrupted" else "interrupted"
                g.reason = g.reason or f"run {outcome}"
                s.add(g)
            duration = float(summary.get("duration_s") or run.duration_s or 0.0)
            run.duration_s = duration
            run.distance_m = float(summary.get("distance_m") or 0.0)
            run.ended_at = run.started_at + timedelta(seconds=duration)
            run.outcome = outcome_fn(run.kind, summary) if outcome_fn else outcome
            run.end_reason = end_reason[:200]
            # what the run was created with (laser_pose, import details) stays beside the metrics
            run.summary = {**(run.summary or {}), **summary}
            s.add(run)
            s.commit()
            return {"id": run_id, "outcome": run.outcome, "summary": summary}

    def close_unfinished(self) -> list[dict]:
        """Close runs left ``recording`` by a crash as ``interrupted``, keeping their data."""
        with Session(self.engine) as s:
            ids = list(s.exec(select(Run.id).where(Run.outcome == "recording")))
        closed = []
        for rid in ids:
            res = self.finish(rid, "interrupted", end_reason="server stopped while recording (crash or kill)")
            closed.append(res)
        return closed

    # ------------------------------------------------------------------ reading
    def list(self, filters: RunFilters, limit: int = 50, offset: int = 0) -> tuple[int, list[dict]]:
        """(total matching, one page newest first)."""
        conds = []
        if filters.kind:
            conds.append(Run.kind == filters.kind)
        if filters.outcome:
            conds.append(Run.outcome == filters.outcome)
        if filters.map_id is not None:
            conds.append(Run.map_id == filters.map_id)
        if filters.robot:
            conds.append(Run.robot_name == filters.robot)
        if filters.since is not None:
            conds.append(Run.started_at >= utc_aware(filters.since))
        if filters.until is not None:
            conds.append(Run.started_at < utc_aware(filters.until))
        with Session(self.engine) as s:
            total = s.exec(select(func.count()).select_from(Run).where(*conds)).one()
            q = (
                select(Run)
                .where(*conds)
                .order_by(col(Run.started_at).desc(), col(Run.id).desc())
                .offset(offset)
                .limit(limit)
            )
            return int(total), [run_dict(r) for r in s.exec(q)]

    def run(self, run_id: int) -> dict:
        with Session(self.engine) as s:
            r = s.get(Run, run_id)
            if r is None:
                raise RunNotFound(run_id)
            return run_dict(r)

    def detail(self, run_id: int) -> dict:
        """The run with its events, goals, plan count and (while recording) a live summary."""
        out = self.run(run_id)
        out["events"] = self.events(run_id)
        out["goals"] = self.goals(run_id)
        if out["outcome"] == "recording":
            samples, _ = self.samples(run_id)
            out["summary"] = summarize(samples, out["events"], out["goals"])
        with Session(self.engine) as s:
            out["plans"] = int(s.exec(select(func.count()).where(RunPlan.run_id == run_id)).one())
            out["scans"] = int(
                s.exec(
                    select(func.coalesce(func.sum(RunScanChunk.n), 0)).where(RunScanChunk.run_id == run_id)
                ).one()
            )
            out["maps"] = int(s.exec(select(func.count()).where(RunGrid.run_id == run_id)).one())
        return out

    def events(self, run_id: int) -> list[dict]:
        with Session(self.engine) as s:
            q = select(RunEvent).where(RunEvent.run_id == run_id).order_by(RunEvent.t, RunEvent.id)
            return [event_dict(e) for e in s.exec(q)]

    def goals(self, run_id: int) -> list[dict]:
        with Session(self.engine) as s:
            q = select(RunGoal).where(RunGoal.run_id == run_id).order_by(RunGoal.t, RunGoal.id)
            return [goal_dict(g) for g in s.exec(q)]

    def samples(
        self, run_id: int, t0: float | None = None, t1: float | None = None
    ) -> tuple[np.ndarray, list[str]]:
        """Samples with t0 <= t <= t1 and the behaviour labels their ``behavior`` codes index."""
        q = select(RunSampleChunk.labels, RunSampleChunk.data).where(RunSampleChunk.run_id == run_id)
        if t0 is not None:
            q = q.where(RunSampleChunk.t1 >= t0)
        if t1 is not None:
            q = q.where(RunSampleChunk.t0 <= t1)
        with Session(self.engine) as s:
            rows = list(s.exec(q.order_by(RunSampleChunk.t0)))
        labels: list[str] = [""]
        index = {"": 0}
        parts = []
        for chunk_labels, blob in rows:
            arr = codec.unpack_samples(blob)
            remap = np.array(
                [index.setdefault(lb, len(index)) for lb in (chunk_labels or [""])], dtype=np.uint8
            )
            arr["behavior"] = remap[np.minimum(arr["behavior"], len(remap) - 1)]
            parts.append(arr)
        labels = sorted(index, key=index.__getitem__)
        arr = np.concatenate(parts) if parts else np.zeros(0, dtype=codec.SAMPLE_DTYPE)
        if t0 is not None:
            arr = arr[arr["t"] >= t0]
        if t1 is not None:
            arr = arr[arr["t"] <= t1]
        return arr, labels

    def sample_at(self, run_id: int, t: float) -> tuple[np.ndarray | None, list[str]]:
        """The last sample at or before ``t`` (one indexed probe and one chunk decode)."""
        with Session(self.engine) as s:
            row = s.exec(
                select(RunSampleChunk.labels, RunSampleChunk.data)
                .where(RunSampleChunk.run_id == run_id, RunSampleChunk.t0 <= t)
                .order_by(col(RunSampleChunk.t0).desc())
                .limit(1)
            ).first()
        if row is None:
            return None, [""]
        arr = codec.unpack_samples(row[1])
        i = max(0, int(np.searchsorted(arr["t"], t, side="right")) - 1)
        return arr[i], list(row[0] or [""])

    def scans(
        self, run_id: int, t0: float | None = None, t1: float | None = None
    ) -> list[tuple[float, LaserScan]]:
        q = select(RunScanChunk.data).where(RunScanChunk.run_id == run_id)
        if t0 is not None:
            q = q.where(RunScanChunk.t1 >= t0)
        if t1 is not None:
            q = q.where(RunScanChunk.t0 <= t1)
        with Session(self.engine) as s:
            blobs = list(s.exec(q.order_by(RunScanChunk.t0)))
        out = [ts for b in blobs for ts in codec.unpack_scans(b)]
        return [(t, sc) for t, sc in out if (t0 is None or t >= t0) and (t1 is None or t <= t1)]

    def scan_at(self, run_id: int, t: float) -> tuple[float, LaserScan] | None:
        with Session(self.engine) as s:
            blob = s.exec(
                select(RunScanChunk.data)
                .where(RunScanChunk.run_id == run_id, RunScanChunk.t0 <= t)
                .order_by(col(RunScanChunk.t0).desc())
                .limit(1)
            ).first()
        if blob is None:
            return None
        scans = codec.unpack_scans(blob)
        times = np.array([ts for ts, _ in scans])
        i = max(0, int(np.searchsorted(times, t, side="right")) - 1)
        return scans[i]

    def plans(self, run_id: int) -> list[tuple[float, np.ndarray]]:
        with Session(self.engine) as s:
            rows = s.exec(select(RunPlan.t, RunPlan.data).where(RunPlan.run_id == run_id).order_by(RunPlan.t))
            return [(t, codec.unpack_path(d)) for t, d in rows]

    def plan_at(self, run_id: int, t: float) -> tuple[float, np.ndarray] | None:
        with Session(self.engine) as s:
            row = s.exec(
                select(RunPlan.t, RunPlan.data)
                .where(RunPlan.run_id == run_id, RunPlan.t <= t)
                .order_by(col(RunPlan.t).desc())
                .limit(1)
            ).first()
        return None if row is None else (row[0], codec.unpack_path(row[1]))

    def grids(self, run_id: int) -> list[tuple[float, int, OccupancyGrid]]:
        with Session(self.engine) as s:
            rows = s.exec(select(RunGrid).where(RunGrid.run_id == run_id).order_by(RunGrid.t))
            return [(r.t, r.version, _grid(r)) for r in rows]

    def grid_at(self, run_id: int, t: float | None = None) -> tuple[float, int, OccupancyGrid] | None:
        """The map as it was at ``t`` (default: the last one; the first one if ``t`` precedes all)."""
        with Session(self.engine) as s:
            q = select(RunGrid).where(RunGrid.run_id == run_id)
            if t is not None:
                rec = s.exec(q.where(RunGrid.t <= t).order_by(col(RunGrid.t).desc()).limit(1)).first()
                rec = rec or s.exec(q.order_by(RunGrid.t).limit(1)).first()
            else:
                rec = s.exec(q.order_by(col(RunGrid.t).desc()).limit(1)).first()
            return None if rec is None else (rec.t, rec.version, _grid(rec))

    def delete(self, run_id: int) -> None:
        with Session(self.engine) as s:
            if s.get(Run, run_id) is None:
                raise RunNotFound(run_id)
            for table in CHILD_TABLES:
                s.exec(delete(table).where(table.run_id == run_id))  # type: ignore[attr-defined]
            s.exec(delete(Run).where(Run.id == run_id))
            s.commit()

    def storage_bytes(self, run_id: int) -> int:
        """Bytes of stored blobs for one run (samples, scans, plans, grids)."""
        total = 0
        with Session(self.engine) as s:
            for table in (RunSampleChunk, RunScanChunk, RunPlan, RunGrid):
                total += int(
                    s.exec(
                        select(func.coalesce(func.sum(func.length(table.data)), 0)).where(
                            table.run_id == run_id
                        )
                    ).one()
                )
        return total
