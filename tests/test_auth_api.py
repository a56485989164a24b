"""Sign-in: password hashing, sessions, the login throttle, roles, and websockets with auth required."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from conftest import make_settings
from sqlmodel import Session, select
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from app.auth import (
    LoginThrottle,
    ScryptOptions,
    ThrottleOptions,
    UserStore,
    hash_password,
    verify_password,
)
from app.embedded import EmbeddedServer, serve_in_thread
from app.models import UserSession

OPERATOR = ("olga", "operator-pass-1")
VIEWER = ("victor", "viewer-pass-1")


def twist(vx: float) -> str:
    return json.dumps({"linear": {"x": vx, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    tmp = tmp_path_factory.mktemp("auth")
    with serve_in_thread(make_settings(tmp, require_auth=True, session_ttl_s=600)) as s:
        store = UserStore(s.runtime.engine)
        store.add_user(*OPERATOR, role="operator")
        store.add_user(*VIEWER, role="viewer")
        s.app.state.auth.throttle = LoginThrottle(ThrottleOptions(base_delay_s=0.05, max_delay_s=0.4))
        yield s


@contextlib.contextmanager
def signed_in(server: EmbeddedServer, who: tuple[str, str]) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        r = c.post("/api/auth/login", json={"username": who[0], "password": who[1]})
        assert r.status_code == 200, r.text
        yield c


def cookie_header(c: httpx.Client) -> dict[str, str]:
    return {"Cookie": "; ".join(f"{k}={v}" for k, v in c.cookies.items())}


def test_password_hash_roundtrip_and_salt() -> None:
    fast = ScryptOptions(n=2**10)
    h1, h2 = hash_password("correct horse", fast), hash_password("correct horse", fast)
    assert h1 != h2 and h1.startswith("scrypt$1024$8$1$")  # salted, parameters stored
    assert verify_password("correct horse", h1) and verify_password("correct horse", h2)
    assert not verify_password("correct hors", h1)
    assert not verify_password("x", "garbage") and not verify_password("x", "md5$1$2$3$00$00")


def test_throttle_delay_grows_and_resets() -> None:
    t = LoginThrottle(ThrottleOptions(base_delay_s=1.0, max_delay_s=8.0, forget_after_s=100.0))
    keys = ["ip:1.2.3.4", "user:bob"]
    delays = [t.failed(keys, now=float(i * 50)) for i in range(5)]
    assert delays == [1.0, 2.0, 4.0, 8.0, 8.0]
    assert t.retry_after(keys, now=200.0) == pytest.approx(8.0)
    assert t.retry_after(["user:bob"], now=209.0) == 0.0
    assert t.failed(["ip:9"], now=0.0) == 1.0 and t.failed(["ip:9"], now=500.0) == 1.0  # forgotten
    t.succeeded(keys)
    assert t.failed(keys, now=300.0) == 1.0


def test_pages_and_api_need_sign_in(server: EmbeddedServer) -> None:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        r = c.get("/maps.html?x=1")
        assert r.status_code == 303 and r.headers["location"] == "/login.html?next=%2Fmaps.html%3Fx%3D1"
        assert c.get("/login.html").status_code == 200 and c.get("/js/login.js").status_code == 200
        assert c.get("/api/robot").status_code == 401
        assert c.post("/api/robot/estop").status_code == 401
        me = c.get("/api/auth/me").json()
        assert me["auth_required"] is True and me["signed_in"] is False
    assert server.runtime.session.modes.mode.value == "idle"


def test_wrong_password_401_without_hint_then_429_while_locked(server: EmbeddedServer) -> None:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        wrong_pw = c.post("/api/auth/login", json={"username": OPERATOR[0], "password": "nope-nope"})
        no_user = c.post("/api/auth/login", json={"username": "mallory", "password": "nope-nope"})
        assert wrong_pw.status_code == no_user.status_code == 401
        assert wrong_pw.json() == no_user.json()  # no hint which of the two was wrong
        assert wrong_pw.json()["detail"] == "wrong username or password"
        assert wrong_pw.headers["content-type"] == "application/problem+json"
        assert "navdeck_session" not in c.cookies
        # a failure locks the address (and the user) for a growing time: a parallel attempt is refused
        server.app.state.auth.throttle.failed(["user:olga"], now=time.monotonic() + 5.0)
        r = c.post("/api/auth/login", json={"username": OPERATOR[0], "password": OPERATOR[1]})
        assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1
    server.app.state.auth.throttle.succeeded(["user:olga", "ip:127.0.0.1"])


def test_session_cookie_flags_and_token_stored_hashed(server: EmbeddedServer) -> None:
    with httpx.Client(base_url=server.url, timeout=10) as c:
        r = c.post("/api/auth/login", json={"username": OPERATOR[0], "password": OPERATOR[1]})
        assert r.status_code == 200 and r.json()["role"] == "operator"
        set_cookie = ",".join(r.headers.get_list("set-cookie")).lower()
        assert (
            "navdeck_session=" in set_cookie and "httponly" in set_cookie and "samesite=strict" in set_cookie
        )
        token = c.cookies["navdeck_session"]
        with Session(server.runtime.engine) as db:
            stored = [s.token_hash for s in db.exec(select(UserSession))]
        assert token not in stored and len(stored) >= 1 and all(len(h) == 64 for h in stored)
        me = c.get("/api/auth/me").json()
        assert me["signed_in"] and me["username"] == "olga" and me["can_drive"]
        assert c.get("/api/robot").status_code == 200
        assert c.post("/api/auth/logout").status_code == 200
        c.cookies.set("navdeck_session", token)  # a stolen copy of the ended session is worthless
        assert c.get("/api/robot").status_code == 401


def test_viewer_cannot_drive_but_can_estop(server: EmbeddedServer) -> None:
    session = server.runtime.session
    start = session.pose
    with signed_in(server, VIEWER) as v:
        r = v.post("/api/robot/mode", json={"mode": "teleop"})
        assert r.status_code == 403 and "viewer" in r.json()["detail"]
        assert v.post("/api/navigation/goals", json={"x": 1.0, "y": 0.0, "theta": 0.0}).status_code == 403
        assert v.post("/api/control/acquire", json={"take_over": True}).status_code == 403
        with connect(f"{server.ws_url}/ws/teleop", additional_headers=cookie_header(v)) as ws:
            hello = json.loads(ws.recv(timeout=5))
            assert hello["role"] == "viewer" and hello["driving"] is False
            for _ in range(6):
                ws.send(twist(0.2))
                time.sleep(0.05)
            err = json.loads(ws.recv(timeout=5))
            assert err["type"] == "error" and err["status"] == 403
        assert session.modes.mode.value == "idle" and session.pose.distance_to(start) < 1e-3
        assert v.post("/api/robot/estop").status_code == 200
        assert session.modes.mode.value == "estop"
    with signed_in(server, OPERATOR) as o:
        assert o.post("/api/robot/reset").status_code == 200


def test_websocket_without_sign_in_is_refused(server: EmbeddedServer) -> None:
    for path in ("/ws/teleop", "/ws/telemetry"):
        with pytest.raises(InvalidStatus) as info, connect(f"{server.ws_url}{path}"):
            pass
        assert info.value.response.status_code == 403


def test_expired_session_closes_websocket_and_stops_robot(tmp_path: Path) -> None:
    with serve_in_thread(make_settings(tmp_path, require_auth=True, session_ttl_s=2.0)) as s:
        UserStore(s.runtime.engine).add_user(*OPERATOR, role="operator")
        session = s.runtime.session
        with (
            signed_in(s, OPERATOR) as o,
            connect(f"{s.ws_url}/ws/teleop", additional_headers=cookie_header(o)) as ws,
        ):
            assert json.loads(ws.recv(timeout=5))["driving"] is True
            with pytest.raises(ConnectionClosed) as info:
                end = time.monotonic() + 6.0
                while time.monotonic() < end:
                    ws.send(twist(0.2))
                    with_msg = None
                    with contextlib.suppress(TimeoutError):
                        with_msg = ws.recv(timeout=0.05)
                    assert with_msg is None or "error" not in with_msg
            assert info.value.rcvd is not None and info.value.rcvd.code == 1008
            assert "expired" in info.value.rcvd.reason
            assert s.runtime.lease.holder is None
            time.sleep(0.3)
            assert abs(session.last_command.vx) < 1e-9 and session.modes.mode.value == "idle"
            assert o.get("/api/robot").status_code == 401


def test_user_cli(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    import io

    from app.cli import main

    db = f"sqlite:///{tmp_path / 'u.db'}"
    monkeypatch.setattr("sys.stdin", io.StringIO("pw-for-ann-1\n"))
    assert main(["user", "add", "ann", "--role", "operator", "--password-stdin", "--db", db]) == 0
    monkeypatch.setattr("sys.stdin", io.StringIO("short\n"))
    assert main(["user", "add", "bob", "--password-stdin", "--db", db]) == 2
    assert main(["user", "list", "--db", db]) == 0
    out = capsys.readouterr()
    assert "ann\toperator" in out.out and "at least 8" in out.err
    from app.db import make_engine

    user = UserStore(make_engine(db)).authenticate("ann", "pw-for-ann-1")
    assert user.role == "operator"


def test_users_migration_down_and_up(tmp_path: Path) -> None:
    from sqlalchemy import inspect

    from app.db import downgrade, make_engine, migrate

    engine = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate(engine)
    assert {"users", "user_sessions"} <= set(inspect(engine).get_table_names())
    downgrade(engine, "0002")
    assert not {"users", "user_sessions"} & set(inspect(engine).get_table_names())
    migrate(engine)
    UserStore(engine).add_user("zed", "zed-password", "viewer")
    engine.dispose()


def test_signed_in_scripts_without_client_cookie_are_separate_stations(server: EmbeddedServer) -> None:
    with signed_in(server, OPERATOR) as a, signed_in(server, OPERATOR) as b:
        for c in (a, b):
            c.cookies.delete("navdeck_client")
        assert a.post("/api/control/acquire", json={}).status_code == 200
        assert a.get("/api/control").json()["you"]["holder"] is True
        assert b.post("/api/control/acquire", json={}).status_code == 409
        assert a.post("/api/control/release").status_code == 200
