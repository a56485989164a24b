"""A real ``navdeck serve`` process killed with SIGKILL mid-run: after a restart the run is closed as
``interrupted``, with its samples kept up to at most 1 s before the kill, and a log line names it."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parent.parent
NAVDECK = Path(sys.executable).parent / "navdeck"

pytestmark = pytest.mark.skipif(os.name != "posix", reason="needs SIGKILL")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(db: Path, port: int, log: Path) -> subprocess.Popen:
    cmd = [str(NAVDECK), "serve", "--port", str(port), "--db", f"sqlite:///{db}", "--no-viewer"]
    env = {**os.environ, "NAVDECK_DATA_DIR": str(db.parent)}
    with log.open("ab") as f:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"navdeck serve exited: {log.read_text()[-2000:]}")
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1.0).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("navdeck serve did not come up")


def test_kill_9_mid_run_leaves_interrupted_run_with_data_up_to_the_last_second(tmp_path: Path) -> None:
    db, log = tmp_path / "navdeck.db", tmp_path / "serve.log"
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    proc = serve(db, port, log)
    try:
        assert httpx.post(f"{url}/api/robot/mode", json={"mode": "teleop"}).status_code == 200
        time.sleep(3.0)
        live = httpx.get(f"{url}/api/runs", params={"outcome": "recording"}).json()
        assert live["total"] == 1
        run_id = live["items"][0]["id"]
        time.sleep(0.7)  # not aligned with a flush
        killed_at = datetime.now().astimezone()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    port2 = free_port()
    proc2 = serve(db, port2, log)
    try:
        run = httpx.get(f"http://127.0.0.1:{port2}/api/runs/{run_id}").json()
        traj = httpx.get(f"http://127.0.0.1:{port2}/api/runs/{run_id}/trajectory").json()
    finally:
        proc2.send_signal(signal.SIGTERM)
        proc2.wait(timeout=20)
    assert run["outcome"] == "interrupted" and "crash" in run["end_reason"]
    assert [e["to"] for e in run["events"] if e["type"] == "mode"] == ["teleop"]
    started = datetime.fromisoformat(run["started_at"].replace("Z", "+00:00"))
    last_t = traj["samples"]["t"][-1]
    lost = (killed_at - started).total_seconds() - last_t
    assert -0.05 < lost <= 1.0, f"lost {lost:.3f} s of samples"
    assert traj["count"] >= 10 * (last_t - 0.5)  # 10 Hz all along
    assert run["summary"]["duration_s"] == pytest.approx(last_t, abs=1e-3)
    assert f"run {run_id} was still recording at start-up: closed as interrupted" in log.read_text()
