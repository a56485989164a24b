"""The 3D view's websocket behind sign-in: refused when signed out; a viewer's clicks never set a goal."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import websockets
from conftest import make_settings
from test_viewer_relay import CAMERA, drain, enc

from app.auth import UserStore
from app.embedded import EmbeddedServer, serve_in_thread
from app.viewer.relay import SUBPROTOCOL
from nav.types import Pose2D


@pytest.fixture
def server(tmp_path: Path) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path, require_auth=True, viewer=True)) as s:
        store = UserStore(s.runtime.engine)
        store.add_user("olga", "operator-pass-1", role="operator")
        store.add_user("victor", "viewer-pass-1", role="viewer")
        yield s


def cookie_for(server: EmbeddedServer, user: str, password: str) -> str:
    with httpx.Client(base_url=server.url) as c:
        assert c.post("/api/auth/login", json={"username": user, "password": password}).status_code == 200
        return "; ".join(f"{k}={v}" for k, v in c.cookies.items())


CLICK = dict(
    event_type="click",
    ray_origin=(0.0, 0.0, 5.0),
    ray_direction=(0.6, 0.0, -0.8),
    screen_pos=((0.5, 0.5),),
    modifier=None,
)


async def click_as(port: int, cookie: str | None) -> None:
    headers = {"Cookie": cookie} if cookie else None
    async with websockets.connect(
        f"ws://127.0.0.1:{port}/viz", subprotocols=[SUBPROTOCOL], max_size=None, additional_headers=headers
    ) as ws:
        await drain(ws, 1.0)
        await ws.send(enc("ViewerCameraMessage", **CAMERA))
        await ws.send(enc("ScenePointerMessage", **CLICK))
        await drain(ws, 1.0)


def test_viz_socket_needs_sign_in_and_drops_viewer_clicks(server: EmbeddedServer) -> None:
    got: list[Pose2D] = []
    server.runtime.pose_input_handlers["goal"] = got.append  # what a goal click reaches
    with pytest.raises(websockets.InvalidStatus):
        asyncio.run(click_as(server.port, None))
    asyncio.run(click_as(server.port, cookie_for(server, "victor", "viewer-pass-1")))
    time.sleep(0.5)
    assert got == [], "a viewer's click in the 3D view reached the goal handler"
    asyncio.run(click_as(server.port, cookie_for(server, "olga", "operator-pass-1")))
    deadline = time.monotonic() + 3
    while not got and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(got) == 1 and got[0].x == pytest.approx(3.75)
