"""REST API against the real app (simulated robot, temporary SQLite)."""

from __future__ import annotations


def test_health_and_robot(client) -> None:
    r = client.get("/api/health")
    assert r.status_code == 200
    assert r.json()["mode"] == "idle"
    robot = client.get("/api/robot").json()
    assert set(robot["pose"]) == {"x", "y", "theta"}
    assert robot["profile"]["name"] == "skid4"
    assert robot["allowed_modes"] == ["localizing", "mapping", "navigating", "teleop"]
    assert robot["velocity"]["linear"]["x"] == 0.0


def test_mode_changes_and_refusals(client) -> None:
    r = client.post("/api/robot/mode", json={"mode": "teleop"})
    assert r.status_code == 200 and r.json()["mode"] == "teleop"
    # an unknown or not requestable mode is a bad request (422, the schema's enum), not a refusal
    for bad in ("flying", "fault"):
        r = client.post("/api/robot/mode", json={"mode": bad})
        assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
        body = r.json()
        assert body["type"].endswith("/invalid-request") and body["errors"][0]["field"] == "mode"
        assert "'idle'" in body["errors"][0]["message"], body
    assert client.get("/api/robot").json()["mode"] == "teleop"  # nothing changed
    r = client.post("/api/robot/mode", json={"mode": "mapping"})
    r = client.post("/api/robot/mode", json={"mode": "localizing"})  # MAPPING -> LOCALIZING: refused
    assert r.status_code == 409 and r.json()["type"].endswith("/mode-refused")
    assert r.json()["mode"] == "mapping" and "idle" in r.json()["allowed"]


def test_estop_latches_until_reset(client) -> None:
    client.post("/api/robot/mode", json={"mode": "teleop"})
    r = client.post("/api/robot/estop")
    assert r.status_code == 200 and r.json()["mode"] == "estop" and r.json()["estop"] is True
    r = client.post("/api/robot/mode", json={"mode": "teleop"})
    assert r.status_code == 409 and "reset first" in r.json()["detail"]
    assert r.json()["allowed"] == []
    r = client.post("/api/robot/reset")
    assert r.status_code == 200 and r.json()["mode"] == "idle" and r.json()["estop"] is False
    r = client.post("/api/robot/reset")
    assert r.status_code == 409


def test_bad_bodies_are_422_with_field(client) -> None:
    r = client.post("/api/robot/mode", json={"mode": "teleop", "speed": 3})
    assert r.status_code == 422 and "speed" in r.json()["detail"]
    r = client.post("/api/robot/mode", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 422  # reported against the body, not against a character offset
    assert [e["field"] for e in r.json()["errors"]] == ["body"] and "not valid JSON" in r.json()["detail"]
    r = client.post("/api/robot/mode", json={})
    assert r.status_code == 422 and "mode" in r.json()["detail"]


def test_stock_maps_registered_with_thumbnails(client) -> None:
    page = client.get("/api/maps").json()
    maps = page["items"]
    assert page["total"] == len(maps) and page["offset"] == 0
    names = {m["name"] for m in maps}
    assert {"apartment", "office", "greenhouse"} <= names
    first = maps[0]
    one = client.get(f"/api/maps/{first['id']}").json()
    assert one["width"] > 0 and one["resolution"] > 0
    png = client.get(first["thumbnail_url"])
    assert png.status_code == 200 and png.content.startswith(b"\x89PNG")
    assert client.get("/api/maps/999999").status_code == 404
    assert client.get("/api/maps/notanumber").status_code == 422


def test_openapi_and_dashboard(client) -> None:
    spec = client.get("/openapi.json").json()
    for path in (
        "/api/health",
        "/api/robot",
        "/api/robot/mode",
        "/api/robot/estop",
        "/api/robot/reset",
        "/api/maps",
        "/api/maps/{map_id}",
    ):
        assert path in spec["paths"]
    assert client.get("/docs").status_code == 200
    page = client.get("/")
    assert page.status_code == 200 and "E-STOP" in page.text
    assert client.get("/js/main.js").status_code == 200
