"""A real navdeck server in a child process (``python -m app.cli serve``), for load runs and crash tests.

A child process, not a thread: it has its own GIL (so the load generator cannot slow the server's
control loop, and the measured CPU and RSS are the server's alone) and it can be killed with SIGKILL
like a power loss.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class ServerFailed(RuntimeError):
    """The server process exited or did not answer /api/health in time."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class ServerProcess:
    proc: subprocess.Popen
    port: int
    log_path: Path
    args: list[str] = field(default_factory=list)

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def pid(self) -> int:
        return self.proc.pid

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    # 30 s: a server starved by a loaded machine (tests under two busy loops) answering slowly is
    # not what its callers test (a 5 s default timed out its first /openapi.json once)
    def get_json(self, path: str, timeout: float = 30.0):
        with urllib.request.urlopen(self.base + path, timeout=timeout) as r:
            return json.loads(r.read())

    def post_json(self, path: str, body: dict | None = None, timeout: float = 30.0):
        req = urllib.request.Request(
            self.base + path,
            data=json.dumps(body or {}).encode(),
            headers={"content-type": "application/json"},
            method="POST",
        )
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return json.loads(r.read() or b"null")

    def wait_ready(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise ServerFailed(f"server exited with {self.proc.returncode}:\n{self.log()[-2000:]}")
            with contextlib.suppress(OSError, ValueError):
                if self.get_json("/api/health", timeout=1.0):
                    return
            time.sleep(0.1)
        raise ServerFailed(f"server not ready after {timeout:.0f} s:\n{self.log()[-2000:]}")

    def kill9(self) -> None:
        """SIGKILL: no shutdown handler, no flush, no atexit: what a power loss leaves."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)

    def stop(self, timeout: float = 15.0) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill9()


def spawn_server(
    db_url: str,
    data_dir: Path,
    *,
    port: int | None = None,
    robot_name: str = "navdeck",
    world: str = "apartment",
    extra_args: tuple[str, ...] = (),
    env: dict[str, str] | None = None,
    ready_timeout: float = 60.0,
) -> ServerProcess:
    """Start ``navdeck serve`` (simulated robot, no 3D view) and wait until /api/health answers."""
    data_dir.mkdir(parents=True, exist_ok=True)
    port = port or free_port()
    args = [
        sys.executable,
        "-m",
        "app.cli",
        "serve",
        "--port",
        str(port),
        "--db",
        db_url,
        "--world",
        world,
        "--no-viewer",
        *extra_args,
    ]
    full_env = {
        **os.environ,
        "NAVDECK_DATA_DIR": str(data_dir),
        "NAVDECK_ROBOT_NAME": robot_name,
        "PYTHONUNBUFFERED": "1",
        **(env or {}),
    }
    log_path = data_dir / f"server-{port}.log"
    with open(log_path, "ab") as log:
        proc = subprocess.Popen(args, cwd=ROOT, env=full_env, stdout=log, stderr=subprocess.STDOUT)
    server = ServerProcess(proc, port, log_path, args)
    try:
        server.wait_ready(ready_timeout)
    except ServerFailed:
        server.stop()
        raise
    return server
