"""Websockets: ``/ws/teleop`` (geometry_msgs/Twist-shaped JSON in) and ``/ws/telemetry`` (snapshots out)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
import uuid
from dataclasses import replace
from typing import Literal

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse, Response
from pydantic import Field
from starlette.websockets import WebSocketState

from app.api.schemas import ERRORS, Out
from app.api.ws_schema import SCHEMAS, json_schema
from app.auth import Principal, Role
from app.limits import CommandRefused
from app.modes import Mode, TransitionRefused, driving_hint
from app.notices import NoticeTap
from app.runtime import Runtime
from app.security import principal_of
from app.session import TELEOP_REARM_REASON
from app.telemetry import snapshot_dict
from nav.types import Twist2D

router = APIRouter()

WsSchemaName = Literal["telemetry", "teleop-in", "teleop-out"]
assert set(WsSchemaName.__args__) == set(SCHEMAS)  # type: ignore[attr-defined]

UNSUPPORTED_DATA = 1003
MAX_TELEOP_FRAME = 4096  # bytes: a Twist is ~100


class TeleopMessageError(ValueError):
    pass


def parse_twist(msg: object) -> Twist2D:
    """{"linear": {"x", "y"}, "angular": {"z"}} -> Twist2D; missing components are 0."""
    if not isinstance(msg, dict):
        raise TeleopMessageError("expected a JSON object shaped like geometry_msgs/Twist")
    unknown = set(msg) - {"linear", "angular", "type"}
    if unknown:
        raise TeleopMessageError(f"unknown field(s): {', '.join(sorted(map(str, unknown)))}")
    linear = msg.get("linear", {})
    angular = msg.get("angular", {})
    if not isinstance(linear, dict) or not isinstance(angular, dict):
        raise TeleopMessageError("linear and angular must be objects")
    values = []
    for name, part, key in (
        ("linear.x", linear, "x"),
        ("linear.y", linear, "y"),
        ("angular.z", angular, "z"),
    ):
        v = part.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise TeleopMessageError(f"{name} must be a finite number, got {v!r}")
        values.append(float(v))
    return Twist2D(*values)


async def _send(ws: WebSocket, payload: dict) -> None:
    if ws.client_state == WebSocketState.CONNECTED:
        await ws.send_text(json.dumps(payload))


CLOSE_POLICY = 1008  # RFC 6455: policy violation (signed out, session expired)


def _principal(ws: WebSocket) -> Principal:
    """The caller resolved by app.security's middleware; cookie-less clients are told apart per socket
    (``addr:<ip>#<n>``) so two scripts on one machine are still two clients."""
    p = principal_of(ws.scope) or Principal(client_id="addr:local", role=Role.OPERATOR)
    if p.client_id.startswith("addr:"):
        p = replace(p, client_id=f"{p.client_id}#{uuid.uuid4().hex[:8]}")
    return p


async def _expiry_watch(ws: WebSocket, p: Principal, on_expired) -> None:
    """Close the socket with a reason when its sign-in session expires or is ended (re-checked every
    few seconds, so a sign-out elsewhere also closes it)."""
    if p.token_hash is None:
        return
    store = ws.app.state.auth.store
    while True:
        left = (p.expires_at or math.inf) - time.time()
        await asyncio.sleep(max(0.05, min(left, 5.0)))
        valid = not p.expired() and await asyncio.to_thread(store.still_valid, p.token_hash)
        if not valid:
            on_expired()
            with contextlib.suppress(RuntimeError, WebSocketDisconnect):
                await ws.close(CLOSE_POLICY, "session expired: sign in again")
            return


@router.websocket("/ws/teleop")
async def teleop(ws: WebSocket) -> None:
    rt: Runtime = ws.app.state.runtime
    guard = ws.app.state.guard
    session = rt.session
    await ws.accept()
    p = _principal(ws)
    client_id = p.client_id
    name = p.username or (ws.query_params.get("name") or p.display)[:64]
    p = replace(p, username=p.username or name)
    guard.attach(client_id)
    have_lease = p.can_drive and (guard.holds(p) or guard.acquire_for_socket(p))
    await _send(
        ws,
        {
            "type": "hello",
            "client_id": client_id,
            "name": p.display,
            "role": p.role.value,
            "control": guard.as_dict(),
            "driving": have_lease,
        },
    )

    def expired() -> None:
        if guard.holds(p):
            guard.free(client_id, "session expired")

    watch = asyncio.create_task(_expiry_watch(ws, p, expired))
    told_to_rearm = False  # the re-arm refusal is said once per held command, not 10 times a second
    try:
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                break
            text = message.get("text")
            if text is None:
                await ws.close(UNSUPPORTED_DATA, "teleop takes JSON text frames")
                break
            if p.expired():
                expired()
                await ws.close(CLOSE_POLICY, "session expired: sign in again")
                break
            if len(text) > MAX_TELEOP_FRAME:
                session.stop_teleop(client_id)
                await _send(ws, {"type": "error", "error": f"frame larger than {MAX_TELEOP_FRAME} bytes"})
                continue
            try:
                data = json.loads(text)
            except ValueError:
                session.stop_teleop(client_id)
                await ws.close(UNSUPPORTED_DATA, "not JSON")
                break
            kind = data.get("type") if isinstance(data, dict) else None
            if kind in ("take_control", "release_control"):
                if not p.can_drive:
                    await _send(ws, {"type": "error", "error": "viewers cannot drive", "status": 403})
                    continue
                if kind == "take_control":
                    guard.acquire(p, take_over=True)
                else:
                    guard.release(p)
                await _send(ws, {"type": "control", "driving": guard.holds(p), "control": guard.as_dict()})
                continue
            try:
                cmd = parse_twist(data)
            except TeleopMessageError as exc:
                session.stop_teleop(client_id)
                await _send(ws, {"type": "error", "error": str(exc)})
                continue
            if not p.can_drive:
                await _send(
                    ws,
                    {
                        "type": "error",
                        "error": f"{p.display} is a viewer: viewers cannot drive",
                        "status": 403,
                    },
                )
                continue
            guard.touch(client_id)
            if not guard.holds(p):
                await _send(
                    ws, {"type": "error", "error": "another client is driving", "control": guard.as_dict()}
                )
                continue
            try:
                session.check_teleop(cmd, client_id)  # before a mode switch: nothing happens for it
            except CommandRefused as exc:  # beyond the sanity bound: the session stopped the robot
                await _send(ws, {"type": "error", **exc.as_dict()})
                continue
            mode = session.modes.mode
            armed = session.teleop_input(cmd, client_id)  # noted in any mode: a release re-arms
            if not armed and mode in (Mode.IDLE, Mode.TELEOP, Mode.MAPPING):
                if not told_to_rearm:
                    await _send(ws, {"type": "error", "error": TELEOP_REARM_REASON, "mode": mode.value})
                told_to_rearm = True
                continue
            if mode == Mode.IDLE and not cmd.is_zero():
                with contextlib.suppress(TransitionRefused):
                    session.request_mode(Mode.TELEOP)
                mode = session.modes.mode
            if mode not in (Mode.TELEOP, Mode.MAPPING):
                await _send(
                    ws,
                    {
                        "type": "error",
                        "error": f"teleop is not allowed in mode {mode.value}: {driving_hint(mode)}",
                        "mode": mode.value,
                        "allowed": session.modes.allowed(),
                    },
                )
                continue
            if session.set_teleop(cmd, client_id):
                told_to_rearm = False
            elif not told_to_rearm:  # disarmed between the check above and here (an e-stop)
                await _send(ws, {"type": "error", "error": TELEOP_REARM_REASON, "mode": mode.value})
                told_to_rearm = True
    except WebSocketDisconnect:
        pass
    finally:
        watch.cancel()
        if guard.holds(p):
            session.stop_teleop(client_id)
        guard.detach(client_id)


@router.websocket("/ws/telemetry")
async def telemetry(ws: WebSocket) -> None:
    rt: Runtime = ws.app.state.runtime
    await ws.accept()
    try:
        hz = float(ws.query_params.get("hz", rt.settings.telemetry_hz))
    except ValueError:
        hz = rt.settings.telemetry_hz
    period = 1.0 / min(max(hz, 1.0), 20.0)
    include_scan = ws.query_params.get("scan", "1") != "0"
    sub = rt.session.bus.subscribe(asyncio.get_running_loop())
    notices = NoticeTap(rt.session, ws.query_params.get("tab"))
    guard = ws.app.state.guard
    watch = asyncio.create_task(_expiry_watch(ws, _principal(ws), lambda: None))

    async def drain_incoming() -> None:  # we only listen to notice the disconnect
        while True:
            msg = await ws.receive()
            if msg["type"] == "websocket.disconnect":
                return

    reader = asyncio.create_task(drain_incoming())
    try:
        last = 0.0
        while not reader.done():
            snap_task = asyncio.create_task(sub.next())
            done, _ = await asyncio.wait({snap_task, reader}, return_when=asyncio.FIRST_COMPLETED)
            if snap_task not in done:
                snap_task.cancel()
                break
            snap = snap_task.result()
            wait = last + period - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
                snap = sub.take() or snap
            last = time.monotonic()
            payload = snapshot_dict(
                snap, rt.profile.name, include_scan=include_scan, allowed_modes=rt.session.modes.allowed()
            )
            payload["control"] = guard.as_dict()
            payload["notices"] = notices.drain()
            # a client that cannot take a frame within 2 s is dropped, never waited on by the loop
            await asyncio.wait_for(ws.send_text(json.dumps(payload)), timeout=2.0)
    except (WebSocketDisconnect, TimeoutError, RuntimeError):
        pass
    finally:
        sub.close()
        notices.close()
        reader.cancel()
        watch.cancel()
        if ws.client_state == WebSocketState.CONNECTED:
            with contextlib.suppress(Exception):
                await ws.close()


# ---------------------------------------------------------------------------------------------- schemas
class SchemaIndex(Out):
    schemas: dict[str, str] = Field(description="message kind -> URL of its JSON Schema")


@router.get(
    "/api/schemas/ws",
    response_model=SchemaIndex,
    tags=["schemas"],
    summary="The websocket messages' JSON Schemas: telemetry, teleop-in, teleop-out",
)
def ws_schema_index() -> SchemaIndex:
    return SchemaIndex(schemas={name: f"/api/schemas/ws/{name}.json" for name in SCHEMAS})


@router.get(
    "/api/schemas/ws/{name}.json",
    response_class=Response,
    tags=["schemas"],
    summary="One websocket message kind as JSON Schema (2020-12)",
    responses={
        200: {"content": {"application/schema+json": {"schema": {"type": "object"}}}},
        **ERRORS(s404="no such message kind"),
    },
)
def ws_schema(name: WsSchemaName) -> JSONResponse:
    return JSONResponse(json_schema(name), media_type="application/schema+json")
