"""The control lease at the API level: two clients, take-over, disconnect, idle REST holders, e-stop."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from conftest import make_settings
from websockets.sync.client import connect

from app.embedded import EmbeddedServer, serve_in_thread
from app.security import Need, required


@pytest.fixture
def server(tmp_path: Path) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path, lease_idle_s=0.6)) as s:
        yield s


def browser(server: EmbeddedServer) -> httpx.Client:
    """A client with its own cookie jar that loaded the dashboard page (which hands out the client id)."""
    c = httpx.Client(base_url=server.url, timeout=10)
    assert c.get("/").status_code == 200
    assert c.cookies.get("navdeck_client")
    return c


def twist(vx: float) -> str:
    return json.dumps({"linear": {"x": vx, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})


def wait_for(pred, timeout: float = 5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return pred()


def test_policy_table_covers_motion_routes_and_defaults_to_operator() -> None:
    assert required("POST", "/api/robot/estop") == Need.SIGNED_IN
    for path in (
        "/api/robot/mode",
        "/api/mapping/start",
        "/api/navigation/goals",
        "/api/localization/global",
    ):
        assert required("POST", path) == Need.DRIVE, path
    assert required("PATCH", "/api/maps/3") == Need.OPERATOR
    assert required("DELETE", "/api/runs/1") == Need.OPERATOR
    assert required("POST", "/api/some/new/route") == Need.OPERATOR  # deny by default
    assert required("POST", "/api/mappingx") == Need.OPERATOR  # prefixes match whole path segments
    assert required("GET", "/api/robot") == Need.SIGNED_IN
    assert required("GET", "/js/core.js") == Need.PUBLIC


def test_two_clients_acquire_refuse_take_over_release(server: EmbeddedServer) -> None:
    a, b = browser(server), browser(server)
    assert a.get("/api/control").json()["holder"] is None
    r = a.post("/api/control/acquire", json={})
    assert r.status_code == 200 and r.json()["you"]["holder"] is True
    r = b.post("/api/control/acquire", json={})
    assert r.status_code == 409 and "holds control" in r.json()["detail"]
    # b cannot move the robot while a holds control; the robot stays idle
    r = b.post("/api/robot/mode", json={"mode": "teleop"})
    assert r.status_code == 409 and r.json()["control"]["holder"] is not None
    assert server.runtime.session.modes.mode.value == "idle"
    assert a.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
    # everyone sees who; b takes over, a is refused now
    assert b.get("/api/control").json()["you"]["holder"] is False
    r = b.post("/api/control/acquire", json={"take_over": True})
    assert r.status_code == 200 and r.json()["you"]["holder"] is True
    assert a.post("/api/robot/mode", json={"mode": "idle"}).status_code == 409
    # e-stop is always allowed, for anyone
    assert a.post("/api/robot/estop").status_code == 200
    assert server.runtime.session.modes.mode.value == "estop"
    assert a.post("/api/control/release").status_code == 409  # not a's to release
    assert b.post("/api/control/release").status_code == 200
    assert a.get("/api/control").json()["holder"] is None


def test_holder_disconnect_stops_robot_and_frees_lease(server: EmbeddedServer) -> None:
    a, b = browser(server), browser(server)
    session = server.runtime.session
    cookie = f"navdeck_client={a.cookies['navdeck_client']}"
    with connect(f"{server.ws_url}/ws/teleop", additional_headers={"Cookie": cookie}) as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello["driving"] is True
        # the websocket and the REST calls of one browser are one station
        assert a.get("/api/control").json()["you"]["holder"] is True
        assert b.get("/api/control").json()["holder"]["connected"] is True
        end = time.monotonic() + 0.8
        while time.monotonic() < end:
            ws.send(twist(0.2))
            time.sleep(0.05)
        assert session.modes.mode.value == "teleop" and session.last_command.vx > 0.05
    assert wait_for(lambda: server.runtime.lease.holder is None)
    assert wait_for(lambda: abs(session.last_command.vx) < 1e-9)
    assert session.modes.mode.value == "idle"
    assert b.post("/api/control/acquire", json={}).status_code == 200


def test_second_socket_is_not_driving_and_can_take_control(server: EmbeddedServer) -> None:
    a, b = browser(server), browser(server)
    session = server.runtime.session
    ha = {"Cookie": f"navdeck_client={a.cookies['navdeck_client']}"}
    hb = {"Cookie": f"navdeck_client={b.cookies['navdeck_client']}"}
    with (
        connect(f"{server.ws_url}/ws/teleop", additional_headers=ha) as wa,
        connect(f"{server.ws_url}/ws/teleop", additional_headers=hb) as wb,
    ):
        assert json.loads(wa.recv(timeout=5))["driving"] is True
        assert json.loads(wb.recv(timeout=5))["driving"] is False
        wb.send(twist(0.2))
        assert json.loads(wb.recv(timeout=5))["error"] == "another client is driving"
        assert abs(session.last_command.vx) < 1e-9
        wb.send(json.dumps({"type": "take_control"}))
        msg = json.loads(wb.recv(timeout=5))
        assert msg["type"] == "control" and msg["driving"] is True
        wa.send(twist(0.2))
        assert json.loads(wa.recv(timeout=5))["error"] == "another client is driving"
        wb.send(json.dumps({"type": "release_control"}))
        assert json.loads(wb.recv(timeout=5))["driving"] is False


def test_rest_only_holder_frees_after_idle(server: EmbeddedServer) -> None:
    a = browser(server)
    assert a.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200  # takes the free lease
    assert server.runtime.lease.holder is not None
    assert wait_for(lambda: server.runtime.lease.holder is None, timeout=5.0)
    assert server.runtime.session.modes.mode.value == "idle"  # and the robot was stopped


def test_cookieless_scripts_are_one_station(server: EmbeddedServer) -> None:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        assert c.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
        assert c.post("/api/robot/mode", json={"mode": "idle"}).status_code == 200
        assert "navdeck_client" not in c.cookies  # API calls never get a cookie


def test_lease_never_exposes_the_client_cookie(server: EmbeddedServer) -> None:
    a, b = browser(server), browser(server)
    assert a.post("/api/control/acquire", json={}).status_code == 200
    secret = a.cookies["navdeck_client"]
    shown = json.dumps(b.get("/api/robot").json()) + json.dumps(b.get("/api/control").json())
    assert secret not in shown and "guest-" in shown
    b.cookies.set("navdeck_client", "c-" + "0" * 20)  # guessing the public id does not make b the holder
    assert b.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 409
