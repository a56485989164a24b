"""RFC 9457 problem details: the one error body of every route.

Raise ``ProblemError(status, detail, kind=..., **extensions)`` in a route (``install(app)`` turns it
into the response; the request path becomes ``instance``), or return ``problem(...)``. Either answers
``application/problem+json`` with ``type``, ``title``, ``status``, ``detail`` plus the helpful
extension members a client acts on (``nearest_free``, ``allowed``, ``mode``...). ``install`` also
answers FastAPI's ``HTTPException`` and request-validation errors (``errors[]`` with the field path)
in this shape, and the security middleware uses ``problem_body`` for its 401/403/409/429, so a client
reads one error shape everywhere. ``problem_responses(...)`` documents them in the OpenAPI description.
"""

from __future__ import annotations

from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import FeatureUnavailable

PROBLEM_MEDIA_TYPE = "application/problem+json"
PROBLEM_BASE = "https://navdeck.dev/problems/"
"""Problem ``type`` URIs are this base + a slug; they name the kind of error, not a page to fetch."""


class Problem(BaseModel):
    """An RFC 9457 problem details object; extension members (e.g. ``nearest_free``) may follow."""

    model_config = ConfigDict(extra="allow")

    type: str = Field("about:blank", description="URI naming the kind of problem")
    title: str = Field(description="Short, human-readable summary of the kind of problem")
    status: int = Field(description="The HTTP status code", ge=400, le=599)
    detail: str = Field("", description="What went wrong in this occurrence, for a human")
    instance: str | None = Field(None, description="The request path that had the problem")


class FieldError(BaseModel):
    field: str = Field(
        description="dotted path in the body (`x`, `goals.1.theta`) or the query / path parameter's "
        "name (`limit`); `body` for the body as a whole (not JSON, wrong type)"
    )
    message: str


class ValidationProblem(Problem):
    """422 from request validation (type ``.../invalid-request``): every error with its field."""

    errors: list[FieldError] = Field(default_factory=list)


def problem_body(
    status: int, detail: str, *, kind: str | None = None, instance: str | None = None, **extensions: Any
) -> dict[str, Any]:
    """The JSON body of a problem. ``kind`` is the slug of the ``type`` URI (None: ``about:blank``,
    then ``title`` is the status phrase as RFC 9457 requires)."""
    title = HTTPStatus(status).phrase if kind is None else kind.replace("-", " ").capitalize()
    body = Problem(
        type=PROBLEM_BASE + kind if kind else "about:blank",
        title=title,
        status=status,
        detail=detail,
        instance=instance,
        **extensions,
    )
    return body.model_dump(mode="json", exclude_none=True)


def problem(
    status: int,
    detail: str,
    *,
    kind: str | None = None,
    instance: str | None = None,
    headers: dict[str, str] | None = None,
    **extensions: Any,
) -> JSONResponse:
    """A problem-details response (see ``problem_body``)."""
    body = problem_body(status, detail, kind=kind, instance=instance, **extensions)
    return JSONResponse(body, status_code=status, media_type=PROBLEM_MEDIA_TYPE, headers=headers)


def problem_responses(**described: str) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for error statuses given as ``s404="no such mission"``."""
    return {
        int(code.removeprefix("s")): {
            "description": text,
            "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
        for code, text in described.items()
    }


class ProblemError(Exception):
    """Raise to answer with a problem-details body (see ``install``)."""

    def __init__(self, status: int, detail: str, *, kind: str | None = None, **extensions: Any) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.kind = kind
        self.extensions = extensions


def field_errors(exc: RequestValidationError) -> list[dict[str, str]]:
    """``{field, message}`` per error. The field is the path inside the body (``goals.1.x``), or the
    query / path parameter's name; a body that is not JSON is ``body`` (pydantic reports the byte
    offset of the syntax error as if it were a field: it goes into the message instead)."""
    out = []
    for e in exc.errors():
        rest = [str(p) for p in e.get("loc", ())][1:]
        msg = str(e.get("msg", "invalid"))
        given = e.get("input")
        if e.get("type") == "json_invalid":
            pos = rest[0] if rest else "?"
            rest, msg = [], f"not valid JSON (at character {pos}): {e.get('ctx', {}).get('error', msg)}"
        elif isinstance(given, str | int | float) and not isinstance(given, bool) and len(repr(given)) <= 80:
            msg = f"{msg}, got {given!r}"  # say what was wrong: "Input should be 'idle'..., got 'flying'"
        out.append({"field": ".".join(rest) or "body", "message": msg})
    return out


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ProblemError)
    return problem(exc.status, exc.detail, kind=exc.kind, instance=request.url.path, **exc.extensions)


async def _handle_unavailable(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, FeatureUnavailable)
    return problem(503, str(exc), kind=f"{exc.name}-unavailable", instance=request.url.path)


async def _handle_http(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    kind = "not-found" if exc.status_code == 404 else None
    return problem(
        exc.status_code, str(exc.detail), kind=kind, instance=request.url.path, headers=exc.headers
    )


async def _handle_validation(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    errors = field_errors(exc)
    detail = "; ".join(f"{e['field']}: {e['message']}" for e in errors)
    return problem(422, detail, kind="invalid-request", instance=request.url.path, errors=errors)


def install(app: FastAPI) -> None:
    """Answer ``ProblemError``, ``HTTPException`` and request-validation errors as
    ``application/problem+json``, and say so in the OpenAPI description."""
    app.add_exception_handler(ProblemError, _handle)
    app.add_exception_handler(FeatureUnavailable, _handle_unavailable)
    app.add_exception_handler(StarletteHTTPException, _handle_http)
    app.add_exception_handler(RequestValidationError, _handle_validation)
    _document(app)


def _document(app: FastAPI) -> None:
    """Every error answer is documented as what ``install`` sends: ``application/problem+json``, a
    ``ValidationProblem`` for 422 (FastAPI's automatic ``HTTPValidationError`` is replaced), else a
    ``Problem`` (schemathesis checks each response against this)."""
    inner = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = inner()
        schemas = schema.setdefault("components", {}).setdefault("schemas", {})
        for model in (Problem, FieldError, ValidationProblem):
            schemas[model.__name__] = model.model_json_schema(ref_template="#/components/schemas/{model}")
        schemas.pop("HTTPValidationError", None)
        schemas.pop("ValidationError", None)
        for ops in schema.get("paths", {}).values():
            for op in ops.values():
                if not isinstance(op, dict):
                    continue
                for code, resp in op.get("responses", {}).items():
                    if not str(code).startswith(("4", "5")):
                        continue
                    ref = "ValidationProblem" if str(code) == "422" else "Problem"
                    resp["content"] = {
                        PROBLEM_MEDIA_TYPE: {"schema": {"$ref": f"#/components/schemas/{ref}"}}
                    }
        app.openapi_schema = schema
        return schema

    app.openapi = openapi  # type: ignore[method-assign]
