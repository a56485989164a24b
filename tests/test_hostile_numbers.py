"""NaN and infinity in requests (issue 9 part 5): every number the OpenAPI schema takes, in every JSON
body and numeric query parameter, is posted as NaN / Infinity / -Infinity / 1e999 and as the strings
pydantic would coerce; each must be a 422 naming the field. A non-finite number anywhere else in a body
is refused too (app/hardening.py), and strings that merely spell "NaN" stay strings."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator

import pytest
from conftest import make_settings

from app.hardening import non_finite_field
from app.ratelimit import RateLimiter

LITERALS = ("NaN", "Infinity", "-Infinity", "1e999", "-1e400")
STRINGS = ('"NaN"', '"inf"', '"-Infinity"')


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.runtime import Runtime
    from app.security import SecurityMiddleware

    runtime = Runtime.build(make_settings(tmp_path_factory.mktemp("nan")))
    app = create_app(runtime)
    for m in app.user_middleware:  # this test sends hundreds of control requests: no 429s here
        if m.cls is SecurityMiddleware:
            m.kwargs["limiter"] = RateLimiter(rate=1e6, burst=1e6)
    with TestClient(app) as c:
        yield c


def _resolve(s: dict, comps: dict) -> dict:
    while "$ref" in s:
        s = comps[s["$ref"].rsplit("/", 1)[-1]]
    return s


def example(s: dict, comps: dict):
    """A value of schema ``s`` with every optional field present (numbers 1.0)."""
    s = _resolve(s, comps)
    if "anyOf" in s:
        return example(next(o for o in s["anyOf"] if o.get("type") != "null"), comps)
    if "enum" in s:
        return s["enum"][0]
    t = s.get("type")
    if t == "object":
        return {k: example(v, comps) for k, v in s.get("properties", {}).items()}
    if t == "array":
        return [example(s.get("items", {}), comps)]
    return {"number": 1.0, "integer": 1, "boolean": False, "string": "x"}.get(t)


def float_paths(v, path: tuple = ()) -> Iterator[tuple]:
    if isinstance(v, float):
        yield path
    elif isinstance(v, dict):
        for k, x in v.items():
            yield from float_paths(x, (*path, k))
    elif isinstance(v, list):
        for i, x in enumerate(v):
            yield from float_paths(x, (*path, i))


def with_raw(doc, path: tuple, raw: str) -> str:
    """``doc`` as JSON text with the value at ``path`` replaced by the raw token ``raw``."""
    doc = copy.deepcopy(doc)
    o = doc
    for p in path[:-1]:
        o = o[p]
    o[path[-1]] = "@@RAW@@"
    return json.dumps(doc).replace('"@@RAW@@"', raw)


def test_every_number_in_every_body_and_query_refuses_nan_and_inf(api) -> None:
    spec = api.get("/openapi.json").json()
    comps = spec["components"]["schemas"]
    leaves, queries, wrong = 0, 0, []
    for path, ops in spec["paths"].items():
        url = path.replace("{map_id}", "1").replace("{run_id}", "1")
        for method, op in ops.items():
            body_schema = op.get("requestBody", {}).get("content", {}).get("application/json", {})
            if "schema" in body_schema:
                doc = example(body_schema["schema"], comps)
                for leaf in float_paths(doc):
                    leaves += 1
                    for raw in LITERALS + STRINGS:
                        r = api.request(
                            method.upper(),
                            url,
                            content=with_raw(doc, leaf, raw),
                            headers={"content-type": "application/json"},
                        )
                        field = ".".join(str(p) for p in leaf)
                        if r.status_code != 422 or field not in r.text:
                            wrong.append(
                                f"{method.upper()} {path} {field}={raw}: {r.status_code} {r.text[:120]}"
                            )
            for param in op.get("parameters", []):
                s = _resolve(param.get("schema", {}), comps)
                types = {s.get("type")} | {o.get("type") for o in s.get("anyOf", [])}
                if param["in"] != "query" or "number" not in types:
                    continue
                queries += 1
                for raw in ("nan", "inf", "-inf", "Infinity"):
                    r = api.request(method.upper(), url, params={param["name"]: raw})
                    if r.status_code != 422:
                        wrong.append(f"{method.upper()} {path}?{param['name']}={raw}: {r.status_code}")
    assert leaves >= 8 and queries >= 3, (leaves, queries)  # goals, poses, replay, run seeks...
    assert not wrong, "\n".join(wrong)


def test_non_finite_anywhere_in_a_body_is_refused_with_its_field(api) -> None:
    r = api.post(
        "/api/robot/mode",
        content=b'{"mode": "idle", "extra": {"deep": [1, 2, NaN]}}',
        headers={"content-type": "application/json"},
    )
    assert r.status_code == 422
    assert r.json()["errors"] == [
        {"field": "extra.deep.2", "message": "non-finite number NaN is not allowed"}
    ]
    r = api.post("/api/robot/mode", content=b'{"mode": "idle", "x": 1e999}')  # no content type at all
    assert r.status_code == 422 and "x: non-finite number 1e999" in r.json()["detail"]
    assert api.post("/api/robot/mode", json={"mode": "idle"}).status_code == 200


def test_strings_spelling_nan_are_not_numbers() -> None:
    assert non_finite_field(b'{"name": "NaN", "note": "Infinity and 1e999"}') is None
    assert non_finite_field(b'{"a": 1.5e300, "b": [1, 2]}') is None
    assert non_finite_field(b"not json NaN") is None  # the route answers malformed JSON itself
    assert non_finite_field(b"[Infinity]") == "0: non-finite number Infinity is not allowed"
    assert non_finite_field(b"-Infinity") == "body: non-finite number -Infinity is not allowed"


def test_a_string_nan_reaches_the_route_as_a_string(api) -> None:
    r = api.post("/api/robot/mode", json={"mode": "NaN"})
    assert r.status_code in (409, 422) and "non-finite" not in r.text and "NaN" in r.text


def test_query_values_in_the_run_routes(api) -> None:
    assert api.get("/api/runs/1/state", params={"t": "inf"}).status_code == 422
    assert api.get("/api/runs/1/trajectory", params={"t0": "nan"}).status_code == 422
    assert api.get("/api/runs/1/trajectory", params={"t0": "0.5"}).status_code == 404  # valid: no run 1
