"""Run a full navdeck server inside this process on a free port (tests, benchmarks, load tools)."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import uvicorn

from app.main import UVICORN_OPTIONS, create_app
from app.runtime import Runtime
from app.settings import Settings


@dataclass
class EmbeddedServer:
    url: str
    port: int
    app: object
    runtime: Runtime

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://")


@contextlib.contextmanager
def serve_in_thread(
    settings: Settings, runtime: Runtime | None = None, send_buffer: int | None = None
) -> Iterator[EmbeddedServer]:
    """``send_buffer``: SO_SNDBUF for the listening socket, which accepted connections inherit
    (tests of stalled clients: the kernel's autotuned ~2 MB takes ~40 s of telemetry to fill)."""
    runtime = runtime or Runtime.build(settings)
    app = create_app(runtime)
    sock = socket.socket()
    if send_buffer is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, send_buffer)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, lifespan="on", **UVICORN_OPTIONS))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, name="uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("embedded server did not start")
        time.sleep(0.02)
    try:
        yield EmbeddedServer(f"http://127.0.0.1:{port}", port, app, runtime)
    finally:
        server.should_exit = True
        thread.join(timeout=10)
        sock.close()
