"""The FastAPI application: REST API, websockets, the 3D view relay and the dashboard's static files."""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import pkgutil
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

import app.api.routes as routes_pkg
from app.api.problems import install as install_problems
from app.api_docs import mount_api_docs
from app.auth import UserStore
from app.hardening import HardeningMiddleware
from app.ratelimit import document_rate_limits
from app.runtime import Runtime
from app.security import LEASE_RULES, AuthContext, LeaseGuard, SecurityMiddleware, make_viz_authorize
from app.viewer.relay import make_router

FRONTEND_DIR = Path(__file__).resolve().parent.parent / "frontend"

UVICORN_OPTIONS: dict[str, Any] = {
    "log_level": "warning",
    "ws_max_size": 1 << 20,  # a websocket message larger than 1 MiB is garbage: closed (1009)
    # Idle keep-alive connections live longer than a reverse proxy's (nginx keepalive_timeout 60-75 s)
    # and a poller's gaps: with uvicorn's 5 s a client reusing a connection the server was closing
    # got a reset (6 of 113,784 polls in a 10-minute soak). Browsers retry those; proxies report 502.
    "timeout_keep_alive": 75,
}
"""How navdeck runs uvicorn (``navdeck serve`` and the embedded test server alike)."""
log = logging.getLogger("navdeck")


def _route_modules() -> list:
    """Every module in app/api/routes with a ``router`` (one router per resource)."""
    mods = [
        importlib.import_module(f"{routes_pkg.__name__}.{m.name}")
        for m in pkgutil.iter_modules(routes_pkg.__path__)
    ]
    return [m for m in mods if hasattr(m, "router")]


async def _sweep_leases(guard, period: float = 1.0) -> None:
    """Free a lease whose REST-only holder went quiet (the websocket case is handled on close)."""
    while True:
        await asyncio.sleep(period)
        try:
            guard.sweep()
        except Exception:
            log.exception("lease sweep failed")


def create_app(runtime: Runtime) -> FastAPI:
    settings = runtime.settings
    guard = LeaseGuard(runtime.lease, runtime.session, idle_s=settings.lease_idle_s)
    auth = AuthContext(
        UserStore(runtime.engine, session_ttl_s=settings.session_ttl_s), bool(settings.require_auth)
    )

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        runtime.start()
        sweeper = asyncio.create_task(_sweep_leases(guard))
        try:
            yield
        finally:
            sweeper.cancel()
            runtime.close()

    app = FastAPI(
        title="navdeck",
        version="0.1.0",
        summary="Operator station and navigation server for small lidar robots",
        description=LEASE_RULES,
        lifespan=lifespan,
        docs_url=None,  # FastAPI's pages load their assets from a CDN: served offline by app.api_docs
        redoc_url=None,
    )
    app.state.runtime = runtime
    app.state.guard = guard
    app.state.auth = auth
    app.add_middleware(SecurityMiddleware, auth=auth, guard=guard)
    # Outermost (added last): size limits, security headers and websocket Origin checks (app/hardening.py).
    app.add_middleware(HardeningMiddleware, max_upload_bytes=settings.max_upload_bytes)

    install_problems(app)  # every error is an RFC 9457 problem (app/api/problems.py)
    for module in _route_modules():
        app.include_router(module.router)

    document_rate_limits(app)  # 429 on the control endpoints (limited in app.security)

    mount_api_docs(app)

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon() -> FileResponse:  # what browsers ask for on pages without a <link rel="icon"> (/viz/)
        return FileResponse(FRONTEND_DIR / "favicon.svg", media_type="image/svg+xml")

    app.include_router(
        make_router(lambda: runtime.viewer, make_viz_authorize(auth.require_auth), enabled=settings.viewer)
    )
    app.mount("/", StaticFiles(directory=FRONTEND_DIR, html=True), name="frontend")
    return app
