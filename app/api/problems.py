"""RFC 9457 problem details: one error body for every route that adopts it.

Raise ``ProblemError(status, detail, kind=..., **extensions)`` in a route (``install(app)`` turns it
into the response; the request path becomes ``instance``), or return ``problem(...)``. Either answers
``application/problem+json`` with ``type``, ``title``, ``status``, ``detail`` plus the helpful
extension members a client acts on (``nearest_free``, ``allowed``, ``mode``...).
``problem_responses(...)`` documents them in the OpenAPI description.
"""

from __future__ import annotations

from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

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


def problem(
    status: int, detail: str, *, kind: str | None = None, instance: str | None = None, **extensions: Any
) -> JSONResponse:
    """A problem-details response. ``kind`` is the slug of the ``type`` URI (None: ``about:blank``,
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
    return JSONResponse(body.model_dump(exclude_none=True), status_code=status, media_type=PROBLEM_MEDIA_TYPE)


def problem_responses(**described: str) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for error statuses given as ``s404="no such mission"``."""
    return {
        int(code.removeprefix("s")): {
            "model": Problem,
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


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ProblemError)
    return problem(exc.status, exc.detail, kind=exc.kind, instance=request.url.path, **exc.extensions)


def install(app: FastAPI) -> None:
    """Answer every ``ProblemError`` raised by a route as ``application/problem+json``."""
    app.add_exception_handler(ProblemError, _handle)
