"""Hostile HTTP: size limits, security headers, websocket Origin checks (issue 9 part 5, app/hardening.py)."""

from __future__ import annotations

import json
import socket

import pytest
from conftest import make_settings
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from app.hardening import DASHBOARD_CSP, MAX_BODY_BYTES, VIZ_CSP, csp_for, origin_allowed

EXPECTED = {
    "x-content-type-options": "nosniff",
    "x-frame-options": "SAMEORIGIN",
    "referrer-policy": "same-origin",
}


def test_security_headers_on_pages_api_and_refusals(client) -> None:
    for path in ("/", "/index.html", "/api/health", "/api/maps/999999", "/js/main.js"):
        r = client.get(path)
        for k, v in EXPECTED.items():
            assert r.headers.get(k) == v, (path, k, r.headers.get(k))
        assert r.headers["content-security-policy"] == DASHBOARD_CSP
    r = client.get("/viz/")
    assert r.status_code == 200 and r.headers["content-security-policy"] == VIZ_CSP
    assert "script-src 'self';" in DASHBOARD_CSP and "frame-ancestors 'self'" in DASHBOARD_CSP
    assert csp_for("/replay/viz/") == VIZ_CSP


def test_oversized_json_body_is_413_before_the_route(client) -> None:
    big = b'{"mode": "' + b"x" * (MAX_BODY_BYTES + 10) + b'"}'
    r = client.post("/api/robot/mode", content=big, headers={"content-type": "application/json"})
    assert r.status_code == 413 and "larger than" in r.json()["detail"]
    assert r.headers["x-content-type-options"] == "nosniff"
    r = client.post("/api/robot/mode", content=b"{}", headers={"content-length": "nope"})
    assert r.status_code in (400, 413)
    assert client.get("/api/health").status_code == 200


def test_streamed_body_without_length_is_cut_at_the_limit(live_server) -> None:
    """Chunked transfer (no Content-Length): counted as it arrives, refused once past the limit.
    The server may answer and close while we are still sending (that is the point), so the client
    is a raw socket that stops sending on a broken pipe and then reads the answer."""
    piece = b"x" * 65536
    chunk = b"%x\r\n" % len(piece) + piece + b"\r\n"
    with socket.create_connection(("127.0.0.1", live_server.port), timeout=30) as sock:
        sock.sendall(
            b"POST /api/robot/mode HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            b"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n"
        )
        try:
            for _ in range(MAX_BODY_BYTES // len(piece) + 4):
                sock.sendall(chunk)
            sock.sendall(b"0\r\n\r\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # refused mid-stream: the answer is already on its way
        answer = b""
        try:
            while b"\r\n" not in answer:
                data = sock.recv(4096)
                if not data:
                    break
                answer += data
        except ConnectionResetError:
            pass
    status_line = answer.split(b"\r\n", 1)[0]
    assert status_line.split()[1:2] == [b"413"], answer[:200]


def test_multipart_uploads_get_the_upload_limit(tmp_path) -> None:
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.runtime import Runtime

    runtime = Runtime.build(make_settings(tmp_path, max_upload_bytes=200_000))
    with TestClient(create_app(runtime)) as c:
        files = {"file": ("map.pgm", b"P5\n" + b"\x00" * 300_000, "application/octet-stream")}
        r = c.post("/api/maps/import", files=files)
        assert r.status_code == 413
        small = {"file": ("map.pgm", b"P5\n" + b"\x00" * 10_000, "application/octet-stream")}
        r = c.post("/api/maps/import", files=small)
        assert r.status_code != 413  # under the limit: up to the route (404/405 if there is none yet)


@pytest.mark.parametrize(
    ("origin", "host", "ok"),
    [
        (None, "127.0.0.1:8000", True),
        ("http://127.0.0.1:8000", "127.0.0.1:8000", True),
        ("https://robot.example.com", "robot.example.com", True),  # TLS ended at the proxy
        ("https://evil.example", "127.0.0.1:8000", False),
        ("http://127.0.0.1:8001", "127.0.0.1:8000", False),
        ("null", "127.0.0.1:8000", False),
    ],
)
def test_origin_rule(origin, host, ok) -> None:
    assert origin_allowed(origin, host) is ok
    assert origin_allowed("https://ops.example.com", "127.0.0.1", {"https://ops.example.com"})


def test_cross_origin_websocket_upgrades_are_refused(live_server) -> None:
    for path in ("/ws/telemetry", "/ws/teleop", "/viz"):
        with pytest.raises(InvalidStatus) as info:
            connect(live_server.ws_url + path, origin="https://evil.example", open_timeout=10).close()
        assert info.value.response.status_code == 403
    same = f"http://127.0.0.1:{live_server.port}"
    with connect(live_server.ws_url + "/ws/telemetry?hz=5", origin=same, open_timeout=10) as ws:
        assert json.loads(ws.recv(timeout=10))["mode"]
    with connect(live_server.ws_url + "/ws/telemetry?hz=5", open_timeout=10) as ws:  # no Origin: a script
        assert json.loads(ws.recv(timeout=10))["mode"]
