"""The control lease at the API level: two clients, take-over, disconnect, idle REST holders, e-stop."""

from __future__ import annotations

import json
import math
import threading
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


@pytest.fixture
def steady_server(tmp_path: Path) -> Iterator[EmbeddedServer]:
    """For tests where an idle lapse is not what is tested: with 0.6 s, a loaded machine let the
    holder's lease lapse between two of its own calls."""
    with serve_in_thread(make_settings(tmp_path, lease_idle_s=30.0)) as s:
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


def drive_until_moving(ws, session, timeout: float = 10.0) -> bool:
    """Send 0.2 m/s every 50 ms until the commanded speed shows it (a loaded machine may be slow)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ws.send(twist(0.2))
        if session.last_command.vx > 0.05:
            return True
        time.sleep(0.05)
    return False


def test_policy_table_covers_motion_routes_and_defaults_to_operator() -> None:
    assert required("POST", "/api/robot/estop") == Need.SIGNED_IN
    for path in ("/api/robot/mode", "/api/mapping/start"):
        assert required("POST", path) == Need.UNCONTESTED, path  # a mode request is not driving
    for path in (
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


def test_two_clients_acquire_refuse_take_over_release(steady_server: EmbeddedServer) -> None:
    server = steady_server
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
    assert a.post("/api/control/acquire", json={}).status_code == 200
    assert a.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
    assert server.runtime.lease.holder is not None
    assert wait_for(lambda: server.runtime.lease.holder is None, timeout=5.0)
    assert server.runtime.session.modes.mode.value == "idle"  # and teleop was stopped (the deadman)


# ------------------------------------------------------------------------------ issue 17 item 10
@pytest.mark.parametrize(
    "path, body", [("/api/robot/mode", {"mode": "teleop"}), ("/api/mapping/start", None)]
)
def test_mode_request_takes_no_lease_and_a_socket_script_drives(server: EmbeddedServer, path, body) -> None:
    """curl's mode request, then a websocket script on the same machine: the script drives at once
    (it was refused for the whole idle time-out while the cookie-less REST caller held the lease)."""
    session = server.runtime.session
    with httpx.Client(base_url=server.url, timeout=10) as curl:
        r = curl.post(path, json=body) if body is not None else curl.post(path)
        assert r.status_code == 200, r.text
    assert server.runtime.lease.holder is None  # a mode request is not driving
    with connect(f"{server.ws_url}/ws/teleop") as ws:
        assert json.loads(ws.recv(timeout=5))["driving"] is True
        assert drive_until_moving(ws, session)
        ws.send(twist(0.0))
    assert wait_for(lambda: server.runtime.lease.holder is None)


def test_rest_holder_yields_to_a_socket_from_its_own_station(server: EmbeddedServer) -> None:
    session = server.runtime.session
    with httpx.Client(base_url=server.url, timeout=10) as script:
        assert script.post("/api/control/acquire", json={}).status_code == 200
        assert script.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
        with connect(f"{server.ws_url}/ws/teleop") as ws:
            hello = json.loads(ws.recv(timeout=5))
            assert hello["driving"] is True and hello["control"]["holder"]["connected"] is True
            assert drive_until_moving(ws, session)
            # the script's REST calls still count as the holder (one station)
            assert script.get("/api/control").json()["you"]["holder"] is True
            ws.send(twist(0.0))


def test_protection_between_two_drivers_is_kept(steady_server: EmbeddedServer) -> None:
    """A browser holding control (REST or socket) is not displaced by a script's socket or mode request
    from another station; a mode request is refused while someone else holds the lease."""
    server = steady_server
    a = browser(server)
    session = server.runtime.session
    assert a.post("/api/control/acquire", json={}).status_code == 200
    with httpx.Client(base_url=server.url, timeout=10) as script:
        r = script.post("/api/robot/mode", json={"mode": "teleop"})
        assert r.status_code == 409 and r.json()["control"]["holder"] is not None
        with connect(f"{server.ws_url}/ws/teleop") as ws:
            assert json.loads(ws.recv(timeout=5))["driving"] is False
            ws.send(twist(0.2))
            assert json.loads(ws.recv(timeout=5))["error"] == "another client is driving"
        assert abs(session.last_command.vx) < 1e-9 and session.modes.mode.value == "idle"
    assert a.get("/api/control").json()["you"]["holder"] is True
    cookie = {"Cookie": f"navdeck_client={a.cookies['navdeck_client']}"}
    with connect(f"{server.ws_url}/ws/teleop", additional_headers=cookie) as wa:
        assert json.loads(wa.recv(timeout=5))["driving"] is True
        with httpx.Client(base_url=server.url, timeout=10) as script:
            assert script.post("/api/mapping/start").status_code == 409
            with connect(f"{server.ws_url}/ws/teleop") as ws:
                assert json.loads(ws.recv(timeout=5))["driving"] is False


# ------------------------------------------------------------------------------ issue 22 item 1
START = {"x": 3.0, "y": 3.5, "theta": 0.0}  # the apartment world's start pose


def test_mission_survives_its_client_going_quiet(server: EmbeddedServer) -> None:
    """Post goals, then only listen on /ws/telemetry, then disconnect entirely: the lease lapses (only
    teleop has a deadman), a teleop socket closing frees it again, and the mission still reaches its
    goal (it was cancelled 15 s after the last REST call)."""
    rt = server.runtime
    nav = rt.features["navigation"]
    with httpx.Client(base_url=server.url, timeout=10) as script:
        assert script.post("/api/localization/initial_pose", json=START).status_code == 200
        r = script.post("/api/navigation/goals", json={"x": 3.0, "y": 1.2, "theta": -1.5708})
        assert r.status_code == 200, r.text
    goal_t = max(e["t"] for e in rt.session.events if e["type"] == "goal")
    holders: list[object] = []
    done = threading.Event()

    def listen() -> None:  # the client now only reads telemetry, as a dashboard-less script would
        with connect(f"{server.ws_url}/ws/telemetry?scan=0&hz=5") as tel:
            while not done.is_set():
                holders.append(json.loads(tel.recv(timeout=10))["control"]["holder"])

    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    try:
        # no REST call from here on: the REST-only holder (the goal took the lease) lapses after
        # lease_idle_s (0.6 s)
        assert wait_for(
            lambda: any(
                e["type"] == "control" and "idle" in e["reason"] and e["t"] >= goal_t
                for e in rt.session.events
            ),
            timeout=10.0,
        ), "the lease never lapsed after the goal"
        assert wait_for(lambda: bool(holders) and holders[-1] is None, timeout=10.0), holders[-5:]
        assert nav.state()["active"] is True and rt.session.modes.mode.value in ("navigating", "recovering")
        # a driving socket that takes the lease and goes away ends the lease the other way (detach)
        with connect(f"{server.ws_url}/ws/teleop") as ws:
            assert json.loads(ws.recv(timeout=5))["driving"] is True
        assert wait_for(lambda: rt.lease.holder is None)
        assert any(e["type"] == "control" and "disconnected" in e["reason"] for e in rt.session.events)
        assert nav.state()["active"] is True and rt.session.modes.mode.value in ("navigating", "recovering")
    finally:
        done.set()
        listener.join(timeout=15)
    # nobody connected at all now
    assert wait_for(lambda: nav.state()["outcome"] is not None, timeout=120.0), nav.state()
    assert nav.state()["outcome"]["kind"] == "reached", nav.state()
    truth = rt.session.driver.truth_pose
    assert math.hypot(truth.x - 3.0, truth.y - 1.2) < 0.35


def test_cookieless_scripts_are_one_station(server: EmbeddedServer) -> None:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        assert c.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
        assert c.post("/api/robot/mode", json={"mode": "idle"}).status_code == 200
        assert "navdeck_client" not in c.cookies  # API calls never get a cookie


def test_lease_never_exposes_the_client_cookie(steady_server: EmbeddedServer) -> None:
    server = steady_server  # a loaded CI machine let a's 0.6 s lease lapse before b's refused call
    a, b = browser(server), browser(server)
    assert a.post("/api/control/acquire", json={}).status_code == 200
    secret = a.cookies["navdeck_client"]
    shown = json.dumps(b.get("/api/robot").json()) + json.dumps(b.get("/api/control").json())
    assert secret not in shown and "guest-" in shown
    b.cookies.set("navdeck_client", "c-" + "0" * 20)  # guessing the public id does not make b the holder
    assert b.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 409
