"""Issue 17 item 1: refusals decided on the server (a click in a tab's 3D view) reach that tab's
dashboard through its telemetry socket (``notices``), and only that tab's."""

from __future__ import annotations

import json
import time

from websockets.sync.client import connect

from nav.types import Pose2D


def notices_until(ws, pred, seconds: float = 15.0) -> list[dict]:
    """Every notice received until ``pred(notices)`` holds or ``seconds`` of messages have passed."""
    got: list[dict] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end and not pred(got):
        got += json.loads(ws.recv(timeout=5.0)).get("notices", [])
    return got


def test_refused_view_click_reaches_only_its_tab(live_server) -> None:
    rt = live_server.runtime
    url = f"{live_server.ws_url}/ws/telemetry?hz=20"
    with connect(f"{url}&tab=tab-a") as a, connect(f"{url}&tab=tab-b") as b, connect(url) as plain:
        for ws in (a, b, plain):
            json.loads(ws.recv(timeout=10.0))  # subscribed
        reason = rt.on_pose_input("goal", Pose2D(1.0, 1.0, 0.0), "tab-a")  # fresh server: not localized
        assert reason and "not localized" in reason
        got = notices_until(a, lambda n: any(x["type"] == "refused" for x in n))
        refused = [x for x in got if x["type"] == "refused"]
        assert refused and refused[0]["what"] == "goal" and refused[0]["via"] == "3d view"
        assert "set the initial pose" in refused[0]["reason"]  # what to do, not only what went wrong
        for other in (b, plain):  # another tab's click is not this tab's business
            assert not any(x["type"] == "refused" for x in notices_until(other, lambda n: False, 1.0))


def test_notice_without_tab_reaches_every_dashboard(live_server) -> None:
    rt = live_server.runtime
    url = f"{live_server.ws_url}/ws/telemetry?hz=20"
    with connect(f"{url}&tab=tab-a") as a, connect(url) as plain:
        for ws in (a, plain):
            json.loads(ws.recv(timeout=10.0))
        rt.session.add_event("notice", text="the new map's frame begins where the robot stands")
        for ws in (a, plain):
            got = notices_until(ws, lambda n: any(x.get("type") == "notice" for x in n))
            assert any("new map's frame" in x.get("text", "") for x in got)
