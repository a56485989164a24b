"""Websockets: ``/ws/teleop`` (geometry_msgs/Twist-shaped JSON in) and ``/ws/telemetry`` (snapshots out)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
import uuid

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from app.modes import Mode, TransitionRefused
from app.runtime import Runtime
from app.telemetry import snapshot_dict
from nav.types import Twist2D

router = APIRouter()

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


@router.websocket("/ws/teleop")
async def teleop(ws: WebSocket) -> None:
    rt: Runtime = ws.app.state.runtime
    session = rt.session
    await ws.accept()
    client_id = f"teleop-{uuid.uuid4().hex[:8]}"
    name = ws.query_params.get("name", client_id)[:64]
    have_lease = rt.lease.acquire(client_id, name)
    await _send(
        ws, {"type": "hello", "client_id": client_id, "control": rt.lease.as_dict(), "driving": have_lease}
    )
    try:
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                break
            text = message.get("text")
            if text is None:
                await ws.close(UNSUPPORTED_DATA, "teleop takes JSON text frames")
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
            if isinstance(data, dict) and data.get("type") == "take_control":
                have_lease = rt.lease.acquire(client_id, name, take_over=True)
                session.stop_teleop()
                await _send(ws, {"type": "control", "driving": have_lease, "control": rt.lease.as_dict()})
                continue
            try:
                cmd = parse_twist(data)
            except TeleopMessageError as exc:
                session.stop_teleop(client_id)
                await _send(ws, {"type": "error", "error": str(exc)})
                continue
            if not rt.lease.holds(client_id):
                await _send(
                    ws, {"type": "error", "error": "another client is driving", "control": rt.lease.as_dict()}
                )
                continue
            mode = session.modes.mode
            if mode == Mode.IDLE and not cmd.is_zero():
                with contextlib.suppress(TransitionRefused):
                    session.request_mode(Mode.TELEOP)
                mode = session.modes.mode
            if mode not in (Mode.TELEOP, Mode.MAPPING):
                await _send(
                    ws,
                    {
                        "type": "error",
                        "error": f"teleop is not allowed in mode {mode.value}",
                        "mode": mode.value,
                        "allowed": session.modes.allowed(),
                    },
                )
                continue
            session.set_teleop(cmd, client_id)
    except WebSocketDisconnect:
        pass
    finally:
        if rt.lease.holds(client_id):
            session.stop_teleop(client_id)
            rt.lease.release(client_id)


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
            payload["control"] = rt.lease.as_dict()
            # a client that cannot take a frame within 2 s is dropped, never waited on by the loop
            await asyncio.wait_for(ws.send_text(json.dumps(payload)), timeout=2.0)
    except (WebSocketDisconnect, TimeoutError, RuntimeError):
        pass
    finally:
        sub.close()
        reader.cancel()
        if ws.client_state == WebSocketState.CONNECTED:
            with contextlib.suppress(Exception):
                await ws.close()
