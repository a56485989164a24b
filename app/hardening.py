"""Hostile-input hardening for every request: body size limits, browser security headers, and the
Origin check on websocket upgrades (issue 9 part 5; docs/reliability.md).

One outermost ASGI middleware, so it also covers responses produced by other middlewares (a 401 from
app.security) and routes added later by other modules.

- Size limits (OWASP ASVS 13.1): a request body larger than its limit is refused with 413 before the
  route reads it (``Content-Length``) or as soon as the streamed body passes it (chunked uploads).
  ``multipart/form-data`` (map and run uploads) gets ``max_upload_bytes``; everything else (JSON
  commands) gets ``max_body_bytes``.
- Headers (OWASP Secure Headers Project): ``X-Content-Type-Options: nosniff``, ``X-Frame-Options:
  SAMEORIGIN`` (the dashboard frames its own 3D view), ``Referrer-Policy: same-origin`` and a
  Content-Security-Policy. The dashboard's own pages load only same-origin scripts; viser's client page
  is one HTML file whose bundle is inlined and unpacked at run time (inline script, eval, blob and
  wasm workers), so ``/viz/`` pages get a policy that allows exactly that but still only from 'self';
  /docs and /redoc load Swagger UI / ReDoc from this server too (app/api_docs.py), with the inline
  script FastAPI's page builders write.
- Websockets (RFC 6455 section 10.2): browsers always send ``Origin`` on an upgrade and a page on
  another site could otherwise drive the robot with the operator's cookies (cross-site websocket
  hijacking). An upgrade whose Origin is not this server's own Host (or listed in
  ``NAVDECK_ALLOWED_ORIGINS``) is refused with 403. Clients that send no Origin (scripts, the load tool)
  are not browsers and are left to sign-in.
- Non-finite numbers (RFC 8259 has none): Python's JSON parser accepts ``NaN``, ``Infinity`` and
  ``-Infinity`` and turns ``1e999`` into inf, and a model field or a plain ``dict`` body would pass them
  on to poses and speeds. Every JSON body (under ``max_body_bytes``, so buffering it is cheap) is checked
  here once for all routes, present and future: such a number anywhere is a 422 naming its field.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Awaitable, Callable, Iterable
from typing import Any
from urllib.parse import urlsplit

from starlette.exceptions import HTTPException

from app.api.problems import PROBLEM_MEDIA_TYPE, problem_body

Scope = dict[str, Any]
Message = dict[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

MAX_BODY_BYTES = 1 << 20  # JSON commands and forms: a goal is ~100 bytes
CLOSE_POLICY = 1008

DASHBOARD_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self' ws: wss:; "
    "frame-src 'self'; frame-ancestors 'self'; object-src 'none'; base-uri 'self'; form-action 'self'"
)
VIZ_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob: data:; "
    "worker-src 'self' blob: data:; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
    "font-src 'self' data:; connect-src 'self' ws: wss: blob: data:; frame-ancestors 'self'; "
    "object-src 'none'; base-uri 'self'"
)
DOCS_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "font-src 'self' data:; img-src 'self' data:; worker-src 'self' blob:; connect-src 'self'; "
    "frame-ancestors 'self'; object-src 'none'; base-uri 'self'"
)
COMMON_HEADERS: tuple[tuple[bytes, bytes], ...] = (
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"SAMEORIGIN"),
    (b"referrer-policy", b"same-origin"),
    (b"cross-origin-opener-policy", b"same-origin"),
)


def csp_for(path: str) -> str:
    """The Content-Security-Policy for one path (see the module docstring for why they differ)."""
    if path.endswith("/viz") or "/viz/" in path:
        return VIZ_CSP
    if path in ("/docs", "/redoc") or path.startswith("/docs/"):
        return DOCS_CSP
    return DASHBOARD_CSP


def allowed_origins_from_env() -> frozenset[str]:
    """``NAVDECK_ALLOWED_ORIGINS``: comma-separated origins (``https://ops.example.com``) also allowed."""
    raw = os.environ.get("NAVDECK_ALLOWED_ORIGINS", "")
    return frozenset(o.strip().rstrip("/").lower() for o in raw.split(",") if o.strip())


def _header(scope: Scope, name: bytes) -> str | None:
    for k, v in scope.get("headers", ()):
        if k == name:
            return v.decode("latin-1")
    return None


def origin_allowed(origin: str | None, host: str | None, extra: Iterable[str] = ()) -> bool:
    """True if a websocket upgrade with this ``Origin`` may proceed: none given (not a browser), the
    same host[:port] as the request's ``Host`` (any scheme: TLS may end at a proxy), or listed."""
    if origin is None:
        return True
    origin = origin.strip().rstrip("/").lower()
    if origin in set(extra):
        return True
    if origin == "null" or not host:
        return False
    netloc = urlsplit(origin).netloc
    return bool(netloc) and netloc == host.strip().lower()


class _NonFinite(float):
    """A non-finite number as parsed, remembering how the request wrote it."""

    text: str

    def __new__(cls, text: str) -> _NonFinite:
        obj = super().__new__(cls, float(text))
        obj.text = text
        return obj


def _parse_float(text: str) -> float:
    value = float(text)
    return value if math.isfinite(value) else _NonFinite(text)


_MAYBE_NON_FINITE = re.compile(rb"NaN|Infinity|[0-9][eE]\+?[0-9]{3}")


def non_finite_field(body: bytes) -> str | None:
    """``"field: message"`` for the first non-finite number in a JSON body, or None (also for bodies that
    are not JSON at all: the route's own parser answers those). A byte scan skips the parse for almost
    every body: only ``NaN``, ``Infinity`` or a 3-digit exponent can make one."""
    if not _MAYBE_NON_FINITE.search(body):
        return None
    try:
        doc = json.loads(body, parse_constant=_NonFinite, parse_float=_parse_float)
    except (ValueError, RecursionError):
        return None
    stack: list[tuple[str, object]] = [("", doc)]
    while stack:
        where, v = stack.pop()
        if isinstance(v, _NonFinite):
            return f"{where or 'body'}: non-finite number {v.text} is not allowed"
        if isinstance(v, dict):
            stack.extend((f"{where}.{k}" if where else str(k), x) for k, x in reversed(list(v.items())))
        elif isinstance(v, list):
            stack.extend((f"{where}.{i}" if where else str(i), x) for i, x in reversed(list(enumerate(v))))
    return None


class RequestTooLarge(HTTPException):
    """The streamed request body passed its limit. An HTTPException so that FastAPI's body parsing
    re-raises it as is (it turns other errors into 400) and the app answers 413."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body larger than {limit} bytes")


class HardeningMiddleware:
    def __init__(
        self,
        app: ASGIApp,
        *,
        max_upload_bytes: int,
        max_body_bytes: int = MAX_BODY_BYTES,
        allowed_origins: Iterable[str] | None = None,
    ) -> None:
        self.app = app
        self.max_upload_bytes = max_upload_bytes
        self.max_body_bytes = max_body_bytes
        self.allowed_origins = (
            allowed_origins_from_env() if allowed_origins is None else frozenset(allowed_origins)
        )

    def limit_for(self, scope: Scope) -> int:
        ctype = (_header(scope, b"content-type") or "").lower()
        return self.max_upload_bytes if ctype.startswith("multipart/form-data") else self.max_body_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":
            if not origin_allowed(_header(scope, b"origin"), _header(scope, b"host"), self.allowed_origins):
                await receive()  # websocket.connect; closing before accept answers the upgrade with 403
                await send({"type": "websocket.close", "code": CLOSE_POLICY, "reason": "origin not allowed"})
                return
            await self.app(scope, receive, send)
            return
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        limit = self.limit_for(scope)
        length = _header(scope, b"content-length")
        if length is not None and (not length.strip().isdigit() or int(length) > limit):
            await _reject(send, 413, f"request body larger than {limit} bytes")
            return
        extra = (*COMMON_HEADERS, (b"content-security-policy", csp_for(scope.get("path", "/")).encode()))
        seen = 0
        started = False

        async def limited_receive() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise RequestTooLarge(limit)
            return msg

        async def send_with_headers(msg: Message) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
                present = {k.lower() for k, _ in msg.get("headers", ())}
                added = [h for h in extra if h[0] not in present]
                msg = {**msg, "headers": [*msg.get("headers", ()), *added]}
            await send(msg)

        inner_receive = limited_receive
        ctype = (_header(scope, b"content-type") or "").lower()
        if scope.get("method") in ("POST", "PUT", "PATCH", "DELETE") and not ctype.startswith(
            ("multipart/", "application/x-www-form-urlencoded")
        ):
            # JSON (or untyped) body: read it whole (it is <= max_body_bytes), refuse non-finite numbers,
            # then hand the same bytes to the app.
            chunks: list[bytes] = []
            try:
                while True:
                    msg = await limited_receive()
                    if msg["type"] != "http.request":
                        break
                    chunks.append(msg.get("body", b""))
                    if not msg.get("more_body", False):
                        break
            except RequestTooLarge:
                await _reject(send_with_headers, 413, f"request body larger than {limit} bytes")
                return
            body = b"".join(chunks)
            problem = non_finite_field(body)
            if problem is not None:
                field_name, _, message = problem.partition(": ")
                await _reject(
                    send_with_headers, 422, problem, errors=[{"field": field_name, "message": message}]
                )
                return
            replayed = False

            async def inner_receive() -> Message:
                nonlocal replayed
                if not replayed:
                    replayed = True
                    return {"type": "http.request", "body": body, "more_body": False}
                return await receive()

        try:
            await self.app(scope, inner_receive, send_with_headers)
        except RequestTooLarge:
            if started:
                raise
            await _reject(send_with_headers, 413, f"request body larger than {limit} bytes")


async def _reject(send: Send, status: int, detail: str, errors: list[dict] | None = None) -> None:
    extra: dict[str, Any] = {} if errors is None else {"errors": errors}  # ValidationProblem's shape
    kind = {413: "too-large", 422: "invalid-request"}.get(status)
    body = json.dumps(problem_body(status, detail, kind=kind, **extra)).encode()
    headers = [
        (b"content-type", PROBLEM_MEDIA_TYPE.encode()),
        (b"content-length", str(len(body)).encode()),
        (b"connection", b"close"),
        *COMMON_HEADERS,
    ]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
