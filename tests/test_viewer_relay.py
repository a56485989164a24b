"""The viewer through the FastAPI relay, spoken to with a raw viser websocket client (viser.md §9b)."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
import urllib.request
from collections.abc import Iterator

import msgspec
import numpy as np
import pytest
import uvicorn
import viser
import websockets
import zstandard
from fastapi import FastAPI
from test_viewer_scene import FOOTPRINT, make_scan, office_grid, snap

from app.bus import SnapshotBus
from app.viewer.relay import SUBPROTOCOL, make_router
from app.viewer.scene import Viewer
from nav.types import Pose2D


def decode_frame(raw: bytes) -> list[dict]:
    usize, csize = int.from_bytes(raw[:8], "little"), int.from_bytes(raw[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[16 : 16 + csize], max_output_size=usize)
    return msgspec.msgpack.decode(inner)["messages"]


def enc(type_: str, **fields: object) -> bytes:
    return msgspec.msgpack.encode({"type": type_, **fields})


CAMERA = dict(
    wxyz=(1.0, 0.0, 0.0, 0.0),
    position=(0.0, -6.0, 8.0),
    fov=1.0,
    near=0.01,
    far=1000.0,
    image_height=800,
    image_width=1280,
    look_at=(0.0, 0.0, 0.0),
    up_direction=(0.0, 0.0, 1.0),
)


class Served:
    def __init__(self, viewer: Viewer | None, authorize=None) -> None:
        self.viewer = viewer
        app = FastAPI()
        kw = {} if authorize is None else {"authorize": authorize}
        app.include_router(make_router(lambda: self.viewer, **kw))
        self.app = app
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self) -> Served:
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started and time.monotonic() < deadline:
            time.sleep(0.02)
        assert self.server.started
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
        self.sock.close()


@pytest.fixture
def viewer() -> Iterator[Viewer]:
    v = Viewer(SnapshotBus(), footprint=FOOTPRINT)
    v.start()
    try:
        yield v
    finally:
        v.stop()


async def drain(ws: websockets.ClientConnection, seconds: float) -> list[dict]:
    out: list[dict] = []
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        try:
            raw = await asyncio.wait_for(ws.recv(), timeout=left)
        except TimeoutError:
            break
        if isinstance(raw, bytes):
            out.extend(decode_frame(raw))
    return out


def test_relay_streams_scene_and_click_reaches_callback(viewer: Viewer) -> None:
    got: list[tuple[str, Pose2D]] = []
    viewer.on_pose_input = lambda kind, pose, _tab: got.append((kind, pose))
    viewer.apply(snap(pose=Pose2D(0.0, 0.0, 0.0), grid=office_grid(), grid_version=1, scan=make_scan()))

    async def session() -> tuple[list[dict], list[dict]]:
        url = f"ws://127.0.0.1:{served.port}/viz"
        async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            first = await drain(ws, 1.5)
            await ws.send(enc("ViewerCameraMessage", **CAMERA))
            await ws.send(
                enc(
                    "ScenePointerMessage",
                    event_type="click",
                    ray_origin=(0.0, 0.0, 5.0),
                    ray_direction=(0.6, 0.0, -0.8),
                    screen_pos=((0.5, 0.5),),
                    modifier=None,
                )
            )
            viewer.apply(snap(1, pose=Pose2D(0.7, -0.2, 1.0), grid=office_grid(), grid_version=1))
            # Shift+drag on a map tile (Rviz "2D Goal Pose"): press at (1, 0.5), release over (2, 1.5).
            # end_position lies on the camera-facing drag plane, on the ray camera -> (2, 1.5, 0).
            cam, ground = np.array(CAMERA["position"]), np.array([2.0, 1.5, 0.0])
            end = tuple(float(x) for x in cam + 0.5 * (ground - cam))
            for phase in ("start", "update", "end"):
                await ws.send(
                    enc(
                        "SceneNodeDragMessage",
                        phase=phase,
                        name="/map/tile_0_0",
                        instance_index=None,
                        start_position=(1.0, 0.5, 0.0),
                        start_screen_pos=(0.5, 0.5),
                        end_position=end,
                        end_screen_pos=(0.6, 0.4),
                        button="left",
                        modifier="shift",
                        owner="",
                    )
                )
            later = await drain(ws, 1.0)
            return first, later

    with Served(viewer) as served:
        first, later = asyncio.run(session())
        names = {m.get("name") for m in first}
        assert "/robot" in names and "/scan" in names
        assert {f"/map/tile_{r}_{c}" for r in range(4) for c in range(5)} <= names
        assert any(m["type"] == "ReplayDoneMessage" for m in first)
        assert any(m["type"] == "ImageMessage" and m["name"] == "/map/tile_0_0" for m in first)
        moved = [m for m in later if m.get("name") == "/robot" and m["type"] == "SetPositionMessage"]
        assert moved and np.allclose(moved[-1]["position"], (0.7, -0.2, 0.0))
        deadline = time.monotonic() + 30
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert got, "click did not reach on_pose_input"
        assert len(got) == 2, "shift+drag did not reach on_pose_input"
        # viser runs sync callbacks on a thread pool: the two may arrive in either order
        click, drag = sorted(got, key=lambda kp: -kp[1].x)
        assert click[0] == "goal" and (click[1].x, click[1].y) == pytest.approx((3.75, 0.0))
        assert drag[0] == "goal" and (drag[1].x, drag[1].y) == pytest.approx((1.0, 0.5))
        assert drag[1].theta == pytest.approx(np.pi / 4, abs=1e-6)

        with urllib.request.urlopen(f"http://127.0.0.1:{served.port}/viz/") as page:
            assert page.status == 200 and b"<html" in page.read(4096).lower()
        with urllib.request.urlopen(f"http://127.0.0.1:{served.port}/viz") as page:  # follows the redirect
            assert page.url.endswith("/viz/") and page.status == 200


def test_relay_closes_cleanly_on_both_sides(viewer: Viewer) -> None:
    async def session() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{served.port}/viz", subprotocols=[SUBPROTOCOL]) as ws:
            await drain(ws, 0.3)
            await ws.send(enc("ViewerCameraMessage", **CAMERA))
            deadline = time.monotonic() + 3
            while not viewer.server.get_clients() and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            assert len(viewer.server.get_clients()) == 1
        deadline = time.monotonic() + 3  # client closed: the relay must drop its viser connection
        while viewer.server.get_clients() and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        assert not viewer.server.get_clients()

    with Served(viewer) as served:
        asyncio.run(session())


def test_relay_refuses_when_unauthorized_or_no_viewer(viewer: Viewer) -> None:
    async def refused(port: int) -> int | None:
        try:
            async with websockets.connect(f"ws://127.0.0.1:{port}/viz", subprotocols=[SUBPROTOCOL]) as ws:
                await ws.recv()
        except websockets.InvalidStatus as exc:
            return exc.response.status_code
        except websockets.ConnectionClosed as exc:
            return exc.rcvd.code if exc.rcvd else None
        return None

    with Served(viewer, authorize=lambda _ws: False) as served:
        assert asyncio.run(refused(served.port)) == 403
    with Served(None) as served:
        assert asyncio.run(refused(served.port)) == 403


def test_viser_version_is_pinned() -> None:
    assert SUBPROTOCOL == f"viser-v{viser.__version__}" == "viser-v1.1.1"


def test_client_page_is_unpacked_into_cacheable_files() -> None:
    """``/viz/`` is viser's page with its packed bundle split out: the page names each file by content
    hash, the files carry exactly what viser's own loader would produce, and they are cached for good."""
    import re

    from app.viewer.client import CLIENT_HTML, client_files, unpack

    original = CLIENT_HTML.read_text(encoding="utf-8")
    m = re.search(r'data-ss="(\d+)" data-cs="(\d+)"', original)
    assert m is not None
    files = client_files()
    assert files is not None
    with Served(None) as served:
        base = f"http://127.0.0.1:{served.port}/viz/"
        with urllib.request.urlopen(base) as r:
            page = r.read().decode()
            assert r.headers["cache-control"] == "no-cache"
        assert 'id="root"' in page and "data-p=" not in page and len(page) < 10_000
        refs = re.findall(r'(?:href|src)="(assets/[^"]+)"', page)
        assert len(refs) == 4  # modulepreload bundle, preload wasm, stylesheet, boot module
        got = {}
        for ref in refs:
            with urllib.request.urlopen(base + ref) as r:
                assert r.headers["cache-control"] == "private, max-age=31536000, immutable"
                got[ref.rsplit(".", 1)[1], ref.split("/")[1].split("-")[0]] = (
                    r.read(),
                    r.headers["content-type"],
                )
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(base + "assets/nope.js")
        assert err.value.code == 404
    css, js = got["css", "viser"], got["js", "viser"]
    assert (len(css[0]), len(js[0])) == (int(m.group(1)), int(m.group(2)))  # the sizes viser's loader expects
    assert css[1].startswith("text/css") and js[1].startswith("text/javascript")
    wasm, boot = got["wasm", "zstd"], got["js", "boot"]
    assert wasm[0].startswith(b"\0asm") and wasm[1] == "application/wasm"  # compileStreaming needs this type
    # the contract with the bundle: it reads the decoder from this global, published before it runs
    assert b"__viserZstdWasm" in js[0] and b"globalThis.__viserZstdWasm = await" in boot[0]
    assert unpack("<html><script>viser changed its loader</script></html>") is None  # -> original page


def test_client_page_falls_back_to_viser_single_file(monkeypatch: pytest.MonkeyPatch) -> None:
    import app.viewer.relay as relay

    monkeypatch.setattr(relay, "client_files", lambda: None)
    with Served(None) as served, urllib.request.urlopen(f"http://127.0.0.1:{served.port}/viz/") as r:
        assert len(r.read()) == relay.CLIENT_HTML.stat().st_size
