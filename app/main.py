"""The FastAPI application: REST API, websockets, the 3D view relay and the dashboard's static files."""

from __future__ import annotations

import contextlib
import importlib
import logging
import pkgutil
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles

import app.api.routes as routes_pkg
from app.runtime import Runtime

FRONTEND_DIR = Path(__file__).resolve().parent.parent / "frontend"
log = logging.getLogger("navdeck")


def _route_modules() -> list:
    """Every module in app/api/routes with a ``router`` (one router per resource)."""
    mods = [
        importlib.import_module(f"{routes_pkg.__name__}.{m.name}")
        for m in pkgutil.iter_modules(routes_pkg.__path__)
    ]
    return [m for m in mods if hasattr(m, "router")]


def create_app(runtime: Runtime) -> FastAPI:
    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        runtime.start()
        try:
            yield
        finally:
            runtime.close()

    app = FastAPI(
        title="navdeck",
        version="0.1.0",
        summary="Operator station and navigation server for small lidar robots",
        lifespan=lifespan,
    )
    app.state.runtime = runtime

    @app.exception_handler(RequestValidationError)
    async def _validation(_req: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            {"field": ".".join(str(p) for p in e["loc"][1:]) or "body", "message": e["msg"]}
            for e in exc.errors()
        ]
        summary = "; ".join(f"{e['field']}: {e['message']}" for e in errors)
        return JSONResponse(status_code=422, content={"detail": summary, "errors": errors})

    for module in _route_modules():
        app.include_router(module.router)

    from app.viewer.relay import make_router

    app.include_router(make_router(lambda: runtime.viewer))
    app.mount("/", StaticFiles(directory=FRONTEND_DIR, html=True), name="frontend")
    return app
