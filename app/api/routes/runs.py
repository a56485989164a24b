"""Recorded runs: list, detail, trajectory, map image, exports, delete, and replay control."""

from __future__ import annotations

import contextlib
from datetime import date, datetime, time, timedelta
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, File, HTTPException, Query, UploadFile, WebSocket
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel, feature_dependency, get_runtime_ws
from app.api.problems import ProblemError
from app.api.schemas import ERRORS, DbId, OpenOut, Out, Page, Pair, Timestamp, Triple
from app.export.data import RunData, load_run
from app.export.mcap import mcap_bytes
from app.export.tabular import run_json, samples_columns, samples_csv
from app.features.recording import Recording
from app.runs.codec import MODES
from app.runs.importer import BagImports, ImportInputError, ImportJob
from app.runs.replay import ReplayError
from app.runs.store import KINDS, OUTCOMES, RunFilters, RunNotFound, RunsStore, utc_aware
from app.runtime import Runtime
from app.viewer.relay import CLIENT_HTML, relay_to_viewer
from maps.png import encode_png
from maps.render import grid_to_grey
from nav.types import Pose2D

router = APIRouter(tags=["runs"])

Kind = Literal["teleop", "mapping", "navigation"]
Outcome = Literal["recording", "completed", "succeeded", "failed", "aborted", "stopped", "interrupted"]
assert set(Kind.__args__) == set(KINDS) and set(Outcome.__args__) == set(OUTCOMES)  # type: ignore[attr-defined]

NOT_FOUND = ERRORS(s404="no such run")
RECORDING = ERRORS(s409="the run is still recording")
NO_RECORDING = ERRORS(s503="run recording is not enabled on this server")


class RunOut(Out):
    """A recorded run. Times inside a run (``t`` of events, goals, samples) are seconds since it started."""

    id: int
    kind: Kind
    robot: str
    robot_id: int | None
    profile_name: str = Field(description="the robot profile it ran with")
    map_id: int | None
    started_at: Timestamp
    ended_at: Timestamp | None
    outcome: Outcome
    end_reason: str
    duration_s: float
    distance_m: float
    summary: dict[str, Any] = Field(description="metrics of the run (distance, goals reached...)")


class RunEventOut(OpenOut):
    """One event; its other fields depend on ``type``."""

    t: float = Field(description="s since the run started")
    type: str


class RunGoalOut(Out):
    t: float = Field(description="s since the run started")
    t_end: float | None = Field(description="s since the run started, when it ended")
    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(description="rad")
    outcome: str = Field(description="`pending`, `succeeded`, `failed` or `canceled`")
    reason: str


class RunDetail(RunOut):
    events: list[RunEventOut]
    goals: list[RunGoalOut]
    plans: int
    scans: int
    maps: int


class RunMapGeometry(Out):
    resolution: float = Field(description="m per cell")
    width: int
    height: int
    origin: Triple = Field(description="x (m), y (m), yaw (rad)")
    image_url: str


class TrajectoryOut(Out):
    run_id: int
    count: int = Field(description="samples in the range, before decimation")
    step: int = Field(description="every step-th sample is returned")
    samples: dict[str, list[Any]] = Field(description="columns: t (s since the run started), x, y...")
    map: RunMapGeometry | None = None


class ScanAt(Out):
    t: float = Field(description="s since the run started")
    points: list[Pair] = Field(description="map frame, m")


class PlanAt(Out):
    t: float = Field(description="s since the run started")
    poses: list[Pair] = Field(description="map frame, m")


class RunStateOut(Out):
    t: float = Field(description="s since the run started")
    pose: Triple = Field(description="x (m), y (m), theta (rad), map frame")
    velocity: Triple = Field(description="vx, vy (m/s), wz (rad/s)")
    command: Triple = Field(description="vx, vy (m/s), wz (rad/s)")
    mode: str
    behavior: str | None
    scan: ScanAt | None = None
    plan: PlanAt | None = None


class ReplayOut(Out):
    run_id: int | None
    t: float = Field(description="s since the run started")
    duration: float = Field(description="s")
    playing: bool
    speed: float = Field(description="playback speed factor")
    viewer: bool


def run_out(d: dict[str, Any]) -> dict[str, Any]:
    """The store's run dict under the API's names (``profile`` is the profile object elsewhere)."""
    out = dict(d)
    out["profile_name"] = out.pop("profile", "")
    return out


PARTIAL_HEADER = "X-Run-Partial"
PARTIAL = {
    PARTIAL_HEADER: {
        "description": "`true` when the run is still recording: the file holds what was recorded up to "
        "the request (MCAP metadata `navdeck_run.partial`, JSON `partial`); `false` for an ended run",
        "schema": {"type": "string", "enum": ["true", "false"]},
    }
}
EXPORT_NOTE = (
    "A run still recording is exported as recorded so far (flushed first), flagged partial in the "
    f"`{PARTIAL_HEADER}` header; export again after it ends for the whole run."
)


RecordingDep = Annotated[Recording, Depends(feature_dependency(Recording))]


def get_store(rt: RuntimeDep) -> RunsStore:
    """The recorder's store, or one over the server's database when recording is off (runs can
    still be listed, imported and exported)."""
    rec = rt.find_feature(Recording)
    return rec.store if rec is not None else RunsStore(rt.engine)


StoreDep = Annotated[RunsStore, Depends(get_store)]


def _bad(field: str, msg: str) -> RequestValidationError:
    return RequestValidationError([{"loc": ("query", field), "msg": msg, "type": "value_error"}])


def parse_when(value: str | None, field: str, *, end: bool = False) -> datetime | None:
    """ISO date or datetime (UTC if no zone). A plain date as ``until`` includes that whole day."""
    if value is None or value == "":
        return None
    try:
        if len(value) == 10:
            d = date.fromisoformat(value)
            return utc_aware(datetime.combine(d + timedelta(days=1 if end else 0), time()))
        return utc_aware(datetime.fromisoformat(value.replace("Z", "+00:00")))
    except ValueError:
        raise _bad(field, f"not an ISO date or datetime: {value!r}") from None


def _found(fn, *args):
    try:
        return fn(*args)
    except RunNotFound:
        raise HTTPException(404, f"no run with id {args[0]}") from None


# ------------------------------------------------------------------------------------- bag import
def get_imports(rt: RuntimeDep, store: StoreDep) -> BagImports:
    """The server's import queue (one per runtime, closed with it: Runtime.close closes features)."""
    if rt.find_feature(BagImports) is None:
        rt.features.setdefault("bag_imports", BagImports(store))
    return rt.feature(BagImports)


ImportsDep = Annotated[BagImports, Depends(get_imports)]


class ImportJobOut(Out):
    """A bag import: queued, then reading the bag, mapping it (offline SLAM), storing the run."""

    id: int
    file: str = Field(description="the uploaded file's name")
    size_bytes: int
    state: Literal["queued", "reading", "mapping", "storing", "done", "failed"]
    scans_done: int = Field(description="scans mapped so far (state `mapping`)")
    scans_total: int
    run_id: int | None = Field(description="the run created (state `done`)")
    notes: list[str] = Field(description="what was found in the bag: typestore, topics, laser mount")
    error: str = Field(description="one line saying what is wrong (state `failed`)")
    elapsed_s: float

    @classmethod
    def of(cls, job: ImportJob) -> ImportJobOut:
        return cls(**{k: getattr(job, k) for k in cls.model_fields})


@router.post(
    "/api/runs/import",
    summary="Import a recorded ROS bag as a run (ROS1 .bag, ROS 2 .db3 / .mcap, zipped rosbag2 folder)",
    description="Answers 202 at once with the import job; poll `GET /api/runs/import/{id}` until "
    "`state` is `done` (then `run_id` is the new run) or `failed` (`error`). Topics, frames and the "
    "message typestore are found in the bag; its map is built by offline SLAM.",
    status_code=202,
    responses={
        **ERRORS(s422="not a bag (wrong extension or contents, empty, unreadable archive)"),
        413: {"description": "larger than the server's max_upload_bytes"},
    },
)
async def import_bag(
    imports: ImportsDep,
    file: Annotated[UploadFile, File(description="the bag, or a rosbag2 directory as .zip / .tar.gz")],
) -> ImportJobOut:
    try:
        job = await run_in_threadpool(imports.submit, file.file, file.filename or "")
    except ImportInputError as exc:
        raise ProblemError(422, str(exc), kind="not-a-bag") from None
    return ImportJobOut.of(job)


@router.get(
    "/api/runs/import/{job_id}",
    summary="A bag import's progress and result",
    responses=ERRORS(s404="no such import job (jobs live until the server restarts)"),
)
def import_status(job_id: int, imports: ImportsDep) -> ImportJobOut:
    job = imports.get(job_id)
    if job is None:
        raise ProblemError(404, f"no import job {job_id}", kind="not-found")
    return ImportJobOut.of(job)


@router.get(
    "/api/runs",
    response_model=Page[RunOut],
    summary="Recorded runs, newest first, with filters and pagination",
)
def list_runs(
    store: StoreDep,
    kind: Kind | None = None,
    outcome: Outcome | None = None,
    map_id: Annotated[int | None, Query(ge=1)] = None,
    robot: Annotated[str | None, Query(max_length=100)] = None,
    since: Annotated[str | None, Query(description="ISO date/datetime, UTC if no zone")] = None,
    until: Annotated[str | None, Query(description="ISO date (inclusive) or datetime (exclusive)")] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> dict:
    t0, t1 = parse_when(since, "since"), parse_when(until, "until", end=True)
    if t0 is not None and t1 is not None and t1 <= t0:
        raise _bad("until", "must be after since")
    total, items = store.list(RunFilters(kind, outcome, map_id, robot, t0, t1), limit, offset)
    return {"total": total, "limit": limit, "offset": offset, "items": [run_out(r) for r in items]}


@router.get(
    "/api/runs/{run_id}",
    response_model=RunDetail,
    summary="One run: summary metrics, events, goals",
    responses=NOT_FOUND,
)
def get_run(run_id: DbId, store: StoreDep) -> dict:
    return run_out(_found(store.detail, run_id))


@router.get(
    "/api/runs/{run_id}/trajectory",
    summary="Trajectory samples as columns (decimated to max_points), with the run's map geometry",
    response_model=TrajectoryOut,
    responses=NOT_FOUND,
)
def trajectory(
    run_id: DbId,
    store: StoreDep,
    t0: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    t1: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    max_points: Annotated[int, Query(ge=2, le=100_000)] = 5000,
) -> dict:
    _found(store.run, run_id)
    samples, labels = store.samples(run_id, t0, t1)
    step = max(1, -(-samples.shape[0] // max_points))
    out = {"run_id": run_id, "count": int(samples.shape[0]), "step": step}
    out["samples"] = samples_columns(samples[::step], labels)
    grid = store.grid_at(run_id)
    if grid is not None:
        g = grid[2].geometry
        out["map"] = {
            "resolution": g.resolution,
            "width": g.width,
            "height": g.height,
            "origin": [g.origin.x, g.origin.y, g.origin.theta],
            "image_url": f"/api/runs/{run_id}/map.png",
        }
    return out


@router.get(
    "/api/runs/{run_id}/map.png",
    response_class=Response,
    summary="The map as the run last saw it, full size (map_saver grey levels, top row first)",
    responses={**NOT_FOUND, 200: {"content": {"image/png": {}}}},
)
def run_map_png(run_id: DbId, store: StoreDep) -> Response:
    _found(store.run, run_id)
    hit = store.grid_at(run_id)
    if hit is None:
        raise HTTPException(404, f"run {run_id} has no map")
    return Response(encode_png(grid_to_grey(hit[2])), media_type="image/png")


@router.get(
    "/api/runs/{run_id}/state",
    summary="Replay seek: the run as it was at time t (pose, speeds, scan points, plan, goal)",
    response_model=RunStateOut,
    responses=NOT_FOUND,
)
def state_at(
    run_id: DbId, store: StoreDep, t: Annotated[float, Query(ge=0, allow_inf_nan=False)] = 0.0
) -> dict:
    _found(store.run, run_id)
    row, labels = store.sample_at(run_id, t)
    if row is None:
        raise HTTPException(404, f"run {run_id} has no samples")
    out: dict = {
        "t": float(row["t"]),
        "pose": [float(row["x"]), float(row["y"]), float(row["theta"])],
        "velocity": [float(row["vx"]), float(row["vy"]), float(row["wz"])],
        "command": [float(row["cmd_vx"]), float(row["cmd_vy"]), float(row["cmd_wz"])],
        "mode": MODES[int(row["mode"])],
        "behavior": labels[int(row["behavior"])] or None if int(row["behavior"]) < len(labels) else None,
    }
    scan = store.scan_at(run_id, t)
    if scan is not None:
        pose = Pose2D(*out["pose"])
        summary = store.run(run_id)["summary"]
        laser = Pose2D(*(summary.get("laser_pose") or [0.0, 0.0, 0.0])[:3])
        pts = pose.compose(laser).transform_points(scan[1].points())
        out["scan"] = {"t": scan[0], "points": [[round(x, 3), round(y, 3)] for x, y in pts.tolist()]}
    plan = store.plan_at(run_id, t)
    if plan is not None:
        out["plan"] = {"t": plan[0], "poses": [[round(v, 3) for v in p] for p in plan[1][:, :2].tolist()]}
    return out


@router.get(
    "/api/runs/{run_id}/export.mcap",
    response_class=Response,
    summary="Download as MCAP with ROS 2 messages (Foxglove, ros2 bag)",
    description=EXPORT_NOTE,
    responses={**NOT_FOUND, 200: {"content": {"application/octet-stream": {}}, "headers": PARTIAL}},
)
def export_mcap(run_id: DbId, store: StoreDep, rt: RuntimeDep) -> Response:
    data = _load(store, run_id, rt)
    return Response(mcap_bytes(data), media_type="application/octet-stream", headers=_headers(data, "mcap"))


@router.get(
    "/api/runs/{run_id}/export.json",
    summary="Download everything as JSON (samples as columns; scans with ?scans=true)",
    description=EXPORT_NOTE,
    responses={
        **NOT_FOUND,
        200: {
            "headers": PARTIAL,
            "content": {
                "application/json": {
                    "schema": {
                        "type": "object",
                        "required": ["run"],
                        "description": "the run (`run`: as `GET /api/runs/{id}`), its events, goals, "
                        "plans, maps and samples as columns; `partial` while it records",
                    }
                }
            },
        },
    },
)
def export_json(run_id: DbId, store: StoreDep, rt: RuntimeDep, scans: bool = False) -> JSONResponse:
    data = _load(store, run_id, rt)
    return JSONResponse(run_json(data, with_scans=scans), headers=_headers(data, "json"))


@router.get(
    "/api/runs/{run_id}/export.csv",
    response_class=Response,
    summary="Download the trajectory samples as CSV",
    description=EXPORT_NOTE,
    responses={**NOT_FOUND, 200: {"content": {"text/csv": {}}, "headers": PARTIAL}},
)
def export_csv(run_id: DbId, store: StoreDep, rt: RuntimeDep) -> Response:
    data = _load(store, run_id, rt)
    return Response(samples_csv(data), media_type="text/csv", headers=_headers(data, "csv"))


@router.delete("/api/runs/{run_id}", status_code=204, responses={**NOT_FOUND, **RECORDING})
def delete_run(run_id: DbId, store: StoreDep) -> Response:
    run = _found(store.run, run_id)
    if run["outcome"] == "recording":
        raise HTTPException(409, f"run {run_id} is still recording")
    store.delete(run_id)
    return Response(status_code=204)


def _load(store: RunsStore, run_id: int, rt: Runtime) -> RunData:
    """The run's data for an exporter; the run being recorded is flushed first, so a partial export
    holds everything up to this request (a starved recorder: what is stored, still flagged partial)."""
    rec = rt.find_feature(Recording)
    if rec is not None and rec.recorder.current_run_id == run_id:
        with contextlib.suppress(TimeoutError):
            rec.recorder.sync(timeout=5.0)
    try:
        return load_run(store, run_id)
    except RunNotFound:
        raise HTTPException(404, f"no run with id {run_id}") from None


def _headers(data: RunData, ext: str) -> dict[str, str]:
    name = f"navdeck-run-{data.run['id']}{'-partial' if data.partial else ''}.{ext}"
    return {
        "Content-Disposition": f'attachment; filename="{name}"',
        PARTIAL_HEADER: str(data.partial).lower(),
    }


# ---------------------------------------------------------------------------------------------- replay
class ReplayCommand(StrictModel):
    """Replay control: load a run, then play / pause / seek (t, s) / speed (factor)."""

    action: Literal["load", "play", "pause", "seek", "speed"]
    run_id: int | None = Field(None, ge=1, le=2**63 - 1)
    t: float | None = None
    speed: float | None = None


@router.get("/api/replay", response_model=ReplayOut, summary="Replay player state", responses=NO_RECORDING)
def replay_state(rec: RecordingDep) -> dict:
    return rec.replay.state()


@router.post(
    "/api/replay",
    response_model=ReplayOut,
    summary="Control the replay in the 3D view (served at /replay/viz/)",
    responses={**NOT_FOUND, **ERRORS(s409="the player refused (no run loaded...)"), **NO_RECORDING},
)
def replay_control(cmd: ReplayCommand, rec: RecordingDep) -> dict:
    player = rec.replay
    try:
        if cmd.action == "load":
            if cmd.run_id is None:
                raise _body_error("run_id", "required to load a run")
            state = _found(player.load, cmd.run_id)
            return player.seek(cmd.t) if cmd.t is not None else state
        if cmd.action == "play":
            return player.play()
        if cmd.action == "pause":
            return player.pause()
        if cmd.action == "seek":
            if cmd.t is None:
                raise _body_error("t", "required to seek")
            return player.seek(cmd.t)
        if cmd.speed is None:
            raise _body_error("speed", "required to set the speed")
        try:
            return player.set_speed(cmd.speed)
        except ValueError as exc:
            raise _body_error("speed", str(exc)) from None
    except ReplayError as exc:
        raise HTTPException(409, str(exc)) from None


def _body_error(field: str, msg: str) -> RequestValidationError:
    return RequestValidationError([{"loc": ("body", field), "msg": msg, "type": "value_error"}])


@router.get("/replay/viz/", include_in_schema=False)
async def replay_viz_index() -> FileResponse:
    return FileResponse(CLIENT_HTML, media_type="text/html")


@router.websocket("/replay/viz")
async def replay_viz_ws(ws: WebSocket) -> None:
    """The replay viewer's viser websocket, relayed like the live one (app/viewer/relay.py)."""
    rec = get_runtime_ws(ws).find_feature(Recording)
    player = None if rec is None else rec.replay_if_started
    await relay_to_viewer(ws, None if player is None else player.viewer)
