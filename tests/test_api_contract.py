"""The API's contract (issue 22): every operation declares what it answers (a model for success, a
problem for each error), one error shape, one time format, one list shape, and the write calls that
used to surprise an integrator."""

from __future__ import annotations

import re

import pytest

PROBLEM_REFS = {"#/components/schemas/Problem", "#/components/schemas/ValidationProblem"}
Z_TIME = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?Z$")


@pytest.fixture
def spec(client) -> dict:
    return client.get("/openapi.json").json()


def operations(spec: dict):
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            yield f"{method.upper()} {path}", op


def test_every_operation_declares_a_typed_answer_and_problem_errors(spec: dict) -> None:
    untyped, bad_errors = [], []
    for label, op in operations(spec):
        for code, resp in op["responses"].items():
            content = resp.get("content", {})
            if code.startswith("2"):
                json_schema = content.get("application/json", {}).get("schema")
                if json_schema is not None and not json_schema:  # `{}`: anything goes
                    untyped.append(f"{label} {code}")
            elif code.startswith(("4", "5")):
                refs = {c.get("schema", {}).get("$ref") for c in content.values()}
                if set(content) != {"application/problem+json"} or not refs <= PROBLEM_REFS:
                    bad_errors.append(f"{label} {code}: {content}")
    assert len(list(operations(spec))) >= 45
    assert not untyped, untyped
    assert not bad_errors, bad_errors


def test_every_error_is_a_problem_with_field_paths(client) -> None:
    r = client.post("/api/missions", json={"goals": [{"x": 1.0, "y": "left"}]})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["type"].endswith("/invalid-request") and body["status"] == 422
    assert [e["field"] for e in body["errors"]] == ["goals.0.y"] and "'left'" in body["errors"][0]["message"]
    r = client.get("/api/maps/424242")  # an HTTPException
    assert r.status_code == 404 and r.json()["type"].endswith("/not-found") and r.json()["instance"]
    r = client.get("/api/runs", params={"limit": 0})
    assert [e["field"] for e in r.json()["errors"]] == ["limit"]


def test_initial_pose_in_a_wall_suggests_the_nearest_free_pose(client) -> None:
    r = client.post("/api/localization/initial_pose", json={"x": 0.02, "y": 0.02, "theta": 0.5})
    assert r.status_code == 422 and r.json()["type"].endswith("/pose-rejected"), r.text
    nf = r.json()["nearest_free"]
    assert nf is not None and nf["theta"] == 0.5
    ok = client.post("/api/localization/initial_pose", json=nf)  # the suggestion is accepted
    assert ok.status_code == 200, ok.text


def test_acquire_without_a_body_and_the_lease_since_in_utc(client) -> None:
    r = client.post("/api/control/acquire")  # no body: every field has a default
    assert r.status_code == 200, r.text
    holder = r.json()["holder"]
    assert holder is not None and Z_TIME.match(holder["since"]) and r.json()["you"]["holder"] is True
    assert client.post("/api/control/release").status_code == 200


def test_maps_are_a_page_saying_which_is_active(client) -> None:
    page = client.get("/api/maps", params={"limit": 2}).json()
    assert set(page) == {"total", "limit", "offset", "items", "active_map_id"}
    assert page["limit"] == 2 and len(page["items"]) <= 2 and page["total"] >= 3
    everything = client.get("/api/maps", params={"limit": 500}).json()["items"]
    assert [m["id"] for m in everything if m["active"]] == [page["active_map_id"]]
    assert all(Z_TIME.match(m["created_at"]) and Z_TIME.match(m["updated_at"]) for m in everything)
    active = next(m for m in everything if m["active"])
    r = client.delete(f"/api/maps/{active['id']}")
    assert r.status_code == 409  # stock (the world) and active: either way it stays


def test_write_calls_answer_the_new_state(client) -> None:
    r = client.post("/api/navigation/cancel")  # nothing running: the state says so
    assert r.status_code == 200 and r.json()["canceled"] is False and r.json()["active"] is False
    robot = client.post("/api/robot/estop").json()
    assert robot["mode"] == "estop" and robot["estop"] is True
    robot = client.post("/api/robot/reset").json()
    assert robot["mode"] == "idle" and robot["estop"] is False
    assert isinstance(robot["profile"], dict) and "profile" not in client.get("/api/health").json()
