"""Shared route dependencies and request models."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request, WebSocket
from pydantic import BaseModel, ConfigDict

from app.runtime import Runtime
from app.security import principal_of


class StrictModel(BaseModel):
    """Request bodies: unknown fields are errors and NaN/inf never get in (422)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


def get_runtime_ws(websocket: WebSocket) -> Runtime:
    return websocket.app.state.runtime


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]


def get_actor(request: Request) -> str:
    """Who is asking, as others may see it (a mission's cancel actor): the user, else ``operator``."""
    p = principal_of(request.scope)
    return p.display if p is not None else "operator"


ActorDep = Annotated[str, Depends(get_actor)]
