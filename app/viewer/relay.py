"""Serve the viser client through the dashboard's own port (viser.md option C).

viser binds its own socket (127.0.0.1, ephemeral port) and has no ASGI hook, so FastAPI serves the
client page at ``GET /viz/`` and relays the websocket ``/viz`` byte-for-byte to viser, forwarding the
``viser-v<version>`` subprotocol (any other version is refused by viser with close code 1002) and the
page's ``?tab=`` token (per-tab view state, ``tabs.py``). One
origin and one port: sign-in can sit in front through ``authorize``, and no iframe reconnect trouble.
The relay only copies bytes on uvicorn's loop; no decoding, no numpy. The client page itself is viser's,
unpacked into separate files (``client.py``) so the browser fetches and compiles the bundle sooner.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import threading
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING

import viser
import websockets
from fastapi import APIRouter, HTTPException, Request, WebSocket
from fastapi.responses import FileResponse, RedirectResponse, Response
from starlette.websockets import WebSocketDisconnect

from app.viewer.client import CLIENT_HTML, client_files
from app.viewer.tabs import valid_tab

if TYPE_CHECKING:
    from app.viewer.scene import Viewer

log = logging.getLogger(__name__)

SUBPROTOCOL = f"viser-v{viser.__version__}"

Authorize = Callable[[WebSocket], bool | Awaitable[bool]]

# Close codes (RFC 6455 §7.4.1): 1008 policy violation (not signed in), 1013 try again later.
CLOSE_POLICY = 1008
CLOSE_TRY_AGAIN = 1013


def _allow_all(_ws: WebSocket) -> bool:
    return True


VIEWER_OFF_HTML = """<!doctype html><html><head><meta charset="utf-8"><title>3D view off</title>
<style>body{font:14px system-ui,sans-serif;color:#8a93a0;background:#101418;display:flex;
align-items:center;justify-content:center;height:100vh;margin:0;text-align:center}</style></head>
<body><p id="viewer-off">The 3D view is off: the server was started with <code>--no-viewer</code>.</p>
</body></html>"""
"""``GET /viz/`` when the server runs without the 3D view: viser's page would say "Connecting..."
forever, since its websocket is refused each time."""


def make_router(
    get_viewer: Callable[[], Viewer | None], authorize: Authorize = _allow_all, enabled: bool = True
) -> APIRouter:
    """Routes ``GET /viz`` (redirect), ``GET /viz/`` (viser client page, or a note that the view is
    off when not ``enabled``) and ``WS /viz`` (relay)."""
    router = APIRouter()
    # unpack the client now, off the caller's thread, so the first page load does not wait for it
    threading.Thread(target=client_files, name="viser-client-unpack", daemon=True).start()

    @router.get("/viz", include_in_schema=False)
    async def viz_redirect(request: Request) -> RedirectResponse:
        return RedirectResponse(request.url.path + "/", status_code=307)  # keeps any mount prefix

    @router.get("/viz/", include_in_schema=False)
    def viz_index() -> Response:
        if not enabled:
            return Response(VIEWER_OFF_HTML, media_type="text/html", headers={"cache-control": "no-cache"})
        files = client_files()
        if files is None:
            return FileResponse(CLIENT_HTML, media_type="text/html")
        # the page names its files by content hash: it must not outlive a viser upgrade
        return Response(files.page, media_type="text/html", headers={"cache-control": "no-cache"})

    @router.get("/viz/assets/{name}", include_in_schema=False)
    def viz_asset(name: str) -> Response:
        files = client_files()
        asset = None if files is None else files.assets.get(name)
        if asset is None:
            raise HTTPException(404, "no such file")
        # content-hashed names: cache for good (private: behind sign-in when that is on)
        immutable = {"cache-control": "private, max-age=31536000, immutable"}
        return Response(asset.body, media_type=asset.media_type, headers=immutable)

    @router.websocket("/viz")
    async def viz_ws(ws: WebSocket) -> None:
        ok = authorize(ws)
        if inspect.isawaitable(ok):
            ok = await ok
        if not ok:
            await ws.close(code=CLOSE_POLICY)
            return
        await relay_to_viewer(ws, get_viewer())

    return router


async def relay_to_viewer(ws: WebSocket, viewer: Viewer | None) -> None:
    """Accept ``ws`` and relay it to ``viewer``'s viser server, forwarding the client's subprotocol;
    close with 1013 (try again later) when the viewer is not running or does not answer."""
    if viewer is None or not viewer.running:
        await ws.close(code=CLOSE_TRY_AGAIN)
        return
    protos = list(ws.scope.get("subprotocols", []))
    tab = valid_tab(ws.query_params.get("tab"))  # the browser tab's token: its own view state (tabs.py)
    try:
        upstream = await websockets.connect(
            f"ws://127.0.0.1:{viewer.port}/" + (f"?tab={tab}" if tab else ""),
            subprotocols=protos or None,  # type: ignore[arg-type]
            max_size=None,
            compression=None,
            open_timeout=5.0,
        )
    except (OSError, RuntimeError, websockets.InvalidHandshake, TimeoutError) as exc:
        log.warning("viz relay: viser upstream unavailable: %s", exc)
        await ws.close(code=CLOSE_TRY_AGAIN)
        return
    await ws.accept(subprotocol=upstream.subprotocol)
    await relay(ws, upstream)


async def relay(ws: WebSocket, upstream: websockets.ClientConnection) -> None:
    """Copy frames both ways until either side closes, then close the other side."""

    async def down() -> None:
        async for msg in upstream:
            if isinstance(msg, bytes):
                await ws.send_bytes(msg)
            else:
                await ws.send_text(msg)

    async def up() -> None:
        while True:
            msg = await ws.receive()
            if msg["type"] == "websocket.disconnect":
                return
            if msg.get("bytes") is not None:
                await upstream.send(msg["bytes"])
            elif msg.get("text") is not None:
                await upstream.send(msg["text"])

    tasks = [asyncio.create_task(down()), asyncio.create_task(up())]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
        await upstream.close()
        code = upstream.close_code
        if code is None or code in (1005, 1006, 1015):  # reserved codes that must not be sent
            code = 1000
        with contextlib.suppress(RuntimeError, WebSocketDisconnect):
            await ws.close(code=code)
