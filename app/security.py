"""Who may do what: one policy table over method + path prefix, enforced by one ASGI middleware.

Other engineers add routes all the time; a per-route dependency would be forgotten on some of them, a
middleware with a prefix table is not (OWASP: deny by default). Every write under ``/api`` needs the
operator role unless the table says otherwise; the routes that move the robot also need the control
lease (``LeaseGuard``), mode requests only need nobody else to hold it; the e-stop is allowed for every
signed-in user, always. The lease rules are written once, in ``LEASE_RULES`` (also the API description).

The same middleware resolves the caller for websockets (cookie on the upgrade request) and refuses
the upgrade when sign-in is required and missing. Routes read the caller as ``principal_of(scope)``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import re
import secrets
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import IntEnum
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import quote

from app.api.problems import PROBLEM_MEDIA_TYPE, problem_body
from app.auth import CLIENT_COOKIE, SESSION_COOKIE, LoginThrottle, Principal, Role, UserStore, token_digest
from app.control import ControlLease
from app.modes import Mode, TransitionRefused
from app.ratelimit import RateLimiter, is_limited

log = logging.getLogger("navdeck.security")

Scope = dict[str, Any]
Message = dict[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


class Need(IntEnum):
    PUBLIC = 0  # anyone, signed in or not
    SIGNED_IN = 1  # any signed-in user (viewer or operator)
    OPERATOR = 2  # operator role
    UNCONTESTED = 3  # operator role, and nobody else holds the lease (a mode request: never takes it)
    DRIVE = 4  # operator role and the control lease (taken if free)


WRITE = frozenset({"POST", "PUT", "PATCH", "DELETE"})
READ = frozenset({"GET", "HEAD", "OPTIONS"})


@dataclass(frozen=True)
class Rule:
    methods: frozenset[str]
    prefix: str
    need: Need

    def matches(self, method: str, path: str) -> bool:
        if method not in self.methods:
            return False
        p = self.prefix
        return path == p or path.startswith(p if p.endswith("/") else p + "/")


# First match wins. Writes not listed fall through to the ``/api`` operator rule (deny by default).
POLICY: tuple[Rule, ...] = (
    Rule(WRITE | READ, "/api/auth/", Need.PUBLIC),
    Rule(READ, "/api/health", Need.PUBLIC),
    Rule(WRITE, "/api/robot/estop", Need.SIGNED_IN),
    Rule(WRITE, "/api/control/release", Need.SIGNED_IN),
    Rule(WRITE, "/api/control", Need.OPERATOR),
    Rule(WRITE, "/api/robot/mode", Need.UNCONTESTED),
    Rule(WRITE, "/api/teleop", Need.DRIVE),
    Rule(WRITE, "/api/mapping", Need.UNCONTESTED),
    Rule(WRITE, "/api/localization", Need.DRIVE),
    Rule(WRITE, "/api/navigation", Need.DRIVE),
    Rule(WRITE, "/api/missions", Need.DRIVE),
    Rule(WRITE, "/api/behaviors", Need.DRIVE),
    Rule(WRITE, "/api/maps", Need.OPERATOR),
    Rule(WRITE, "/api/replay", Need.SIGNED_IN),  # replays a recording in its own 3D view: moves nothing
    Rule(WRITE, "/api", Need.OPERATOR),
    Rule(WRITE, "/", Need.OPERATOR),
    Rule(READ, "/login.html", Need.PUBLIC),
    Rule(READ, "/style.css", Need.PUBLIC),
    Rule(READ, "/js/", Need.PUBLIC),
    Rule(READ, "/favicon.ico", Need.PUBLIC),
    Rule(READ, "/favicon.svg", Need.PUBLIC),
    Rule(READ, "/", Need.SIGNED_IN),
)

# Websocket paths that can move the robot: only these count towards lease presence.
DRIVING_SOCKETS = ("/ws/teleop",)


def required(method: str, path: str) -> Need:
    """The policy's answer for one request (websockets are checked as GET)."""
    for rule in POLICY:
        if rule.matches(method, path):
            return rule.need
    return Need.OPERATOR


_CLIENT_RE = re.compile(r"^[A-Za-z0-9_-]{16,64}$")


@dataclass
class AuthContext:
    """Sign-in state shared by the middleware and the auth routes (``app.state.auth``)."""

    store: UserStore
    require_auth: bool
    throttle: LoginThrottle = field(default_factory=LoginThrottle)
    secure_cookies: bool = False  # set behind TLS (cookies then carry ``Secure``)
    cache_s: float = 2.0  # a session look-up is reused this long (a sign-out clears it at once)
    cache: dict[str, tuple[float, Principal | None]] = field(default_factory=dict)

    def forget(self, token: str) -> None:
        self.cache.pop(token, None)


def principal_of(scope: Scope) -> Principal | None:
    """The caller resolved by ``SecurityMiddleware`` (None if the app runs without it)."""
    state = scope.get("state") or {}
    return state.get("principal")


LEASE_RULES = """\
**Control lease.** Many clients may watch; one client at a time holds control, and everyone sees who
(`GET /api/control`, `control` in `GET /api/robot` and in every telemetry message).

1. Calls that move the robot (`/api/missions`, `/api/navigation/*`, `/api/localization/*`,
   `/api/behaviors/*`, teleop on `/ws/teleop`) take the lease when it is free and answer 409 while
   another client holds it.
2. Mode requests (`POST /api/robot/mode`, `/api/mapping/*`) are not driving: they never take the lease,
   and are refused (409) only while *another* client holds it.
3. The holder is present while it has a `/ws/teleop` socket open, or for `lease_idle_s` (default 15 s)
   after its last REST request. A holder without a socket yields to a `/ws/teleop` socket opened from
   the same station (a cookie-less script's REST calls and its websocket); between two stations the
   lease moves only by `take_over` (`POST /api/control/acquire {"take_over": true}` or the socket
   message `{"type": "take_control"}`).
4. When the lease ends (holder idle, its last socket closed, released, or taken over) only **teleop**
   stops: it is the deadman (teleop commands are also zeroed 0.5 s after the last one). A mission
   (navigation with its recoveries, global localization) and a mapping session keep running with no
   client connected, until they finish or are stopped by `POST /api/missions/{id}/cancel` (or
   `POST /api/navigation/cancel`), a new mission, a mode request or the e-stop.
5. The e-stop (`POST /api/robot/estop`) is allowed for every signed-in user, always.
"""


class LeaseGuard:
    """The control lease plus presence: who is connected, and what happens when the holder leaves
    (``LEASE_RULES``).

    The holder is present while it has a teleop websocket open, or for ``idle_s`` after its last REST
    request (scripts driving over REST). When it leaves, the lease frees and teleop stops (teleop zeroed,
    TELEOP mode back to IDLE); a mission or mapping session keeps running: a robot must not drop its
    mission because the operator's laptop went to sleep (issue 22)."""

    STOP_MODES = frozenset({Mode.TELEOP})  # the only mode the lease is a deadman for

    def __init__(self, lease: ControlLease, session: Any, idle_s: float = 15.0) -> None:
        self.lease = lease
        self.session = session
        self.idle_s = idle_s
        self._sockets: dict[str, int] = {}
        self._raw: dict[str, str] = {}  # public lease id -> client id (the cookie value stays private)
        self._seen: dict[str, float] = {}
        self._lock = threading.Lock()

    # presence ----------------------------------------------------------------------------------
    def touch(self, client_id: str) -> None:
        now = time.monotonic()
        self._seen[client_id] = now
        if len(self._seen) > 5000:  # bounded: forget clients silent for an hour
            for k in [k for k, t in self._seen.items() if now - t > 3600.0]:
                self._seen.pop(k, None)

    def attach(self, client_id: str) -> None:
        with self._lock:
            self._sockets[client_id] = self._sockets.get(client_id, 0) + 1
        self.touch(client_id)

    def detach(self, client_id: str, reason: str = "disconnected") -> None:
        """A driving websocket closed; the last one of the holder frees the lease and stops the robot."""
        with self._lock:
            left = self._sockets.get(client_id, 1) - 1
            if left > 0:
                self._sockets[client_id] = left
                return
            self._sockets.pop(client_id, None)
        self.free(client_id, reason)

    def connected(self, client_id: str) -> bool:
        return self._sockets.get(client_id, 0) > 0

    def sweep(self, now: float | None = None) -> None:
        """Free a lease whose holder has no socket and has been silent for ``idle_s``."""
        raw = self._holder_raw()
        if raw is None or self.connected(raw):
            return
        now = time.monotonic() if now is None else now
        if now - self._seen.get(raw, now) > self.idle_s:
            self.free(raw, f"idle for {self.idle_s:.0f} s")

    def free(self, client_id: str, reason: str) -> bool:
        """Release ``client_id``'s lease (if it holds it) and stop the robot."""
        if not self.lease.release(_public_id(client_id)):
            return False
        self._raw.pop(_public_id(client_id), None)
        self.stop_robot(f"control released: {reason}")
        return True

    def stop_robot(self, reason: str) -> None:
        s = self.session
        s.stop_teleop()
        if s.modes.mode in self.STOP_MODES:
            with contextlib.suppress(TransitionRefused):
                s.request_mode(Mode.IDLE)
        s.add_event("control", reason=reason)

    # lease -------------------------------------------------------------------------------------
    def _holder_raw(self) -> str | None:
        h = self.lease.holder
        return None if h is None else self._raw.get(h.client_id, h.client_id)

    def holds(self, p: Principal) -> bool:
        raw = self._holder_raw()
        return raw is not None and _same_station(raw, p.client_id)

    def acquire(self, p: Principal, *, take_over: bool = False) -> bool:
        if not p.can_drive:
            return False
        if self.holds(p):
            return True
        previous = self.lease.holder
        self._raw[_public_id(p.client_id)] = p.client_id
        ok = self.lease.acquire(_public_id(p.client_id), p.display, take_over=take_over)
        if not ok:
            self._raw.pop(_public_id(p.client_id), None)
        if ok and previous is not None:
            self._raw.pop(previous.client_id, None)
            self.session.stop_teleop(None)  # the old holder's last command must not keep driving
            self.session.add_event("control", reason=f"{p.display} took control from {previous.name}")
        return ok

    def acquire_for_socket(self, p: Principal) -> bool:
        """A ``/ws/teleop`` socket opening: take a free lease, or the lease of this station's holder
        when that holder has no socket (a script's REST call, then its websocket: one station)."""
        raw = self._holder_raw()
        absent_same_station = (
            raw is not None and not self.connected(raw) and _station(raw) == _station(p.client_id)
        )
        return self.acquire(p, take_over=absent_same_station)

    def uncontested_refusal(self, p: Principal) -> dict | None:
        """None if nobody else holds the lease (a mode request may go ahead, taking nothing); else the
        409 body."""
        raw = self._holder_raw()
        if raw is None or self.holds(p):
            return None
        return self._held_body()

    def release(self, p: Principal) -> bool:
        raw = self._holder_raw()
        if raw is None or not _same_station(raw, p.client_id):
            return False
        return self.free(raw, f"released by {p.display}")

    def drive_refusal(self, p: Principal) -> dict | None:
        """None if ``p`` may move the robot now (taking a free lease); else the 409 body."""
        if self.holds(p) or self.acquire(p):
            self.touch(p.client_id)
            return None
        return self._held_body()

    def _held_body(self) -> dict:
        h = self.lease.holder
        who = h.name if h else "another client"
        return {
            "detail": f"{who} holds control; take control first (POST /api/control/acquire "
            '{"take_over": true})',
            "control": self.as_dict(),
        }

    def as_dict(self) -> dict:
        d = self.lease.as_dict()
        h = d["holder"]
        if h is not None:
            raw = self._raw.get(h["client_id"], "")
            since = datetime.fromtimestamp(h["since"], UTC).isoformat().replace("+00:00", "Z")
            h = {"name": h["name"], "since": since, "connected": self.connected(raw)}
        return {"holder": h}


def _public_id(client_id: str) -> str:
    """What the lease stores and ``GET /api/robot`` shows: a digest, never the client's cookie value
    (which would let anyone who reads it act as that station)."""
    return "c-" + hashlib.sha256(client_id.encode()).hexdigest()[:16]


def _same_station(holder_id: str, client_id: str) -> bool:
    """Cookie-less API clients from one address (``addr:<ip>``) are one station with their websockets
    (``addr:<ip>#n``); browsers are told apart by their client cookie."""
    return holder_id == client_id or (client_id.startswith("addr:") and holder_id.startswith(client_id + "#"))


def _station(client_id: str) -> str:
    """The station of a client id: a cookie-less websocket ``addr:<ip>#n`` belongs to ``addr:<ip>``."""
    return client_id.split("#", 1)[0] if client_id.startswith("addr:") else client_id


def _cookies(scope: Scope) -> dict[str, str]:
    raw = b"; ".join(v for k, v in scope.get("headers", ()) if k == b"cookie").decode("latin-1")
    jar: SimpleCookie = SimpleCookie()
    with contextlib.suppress(Exception):
        jar.load(raw)
    return {k: m.value for k, m in jar.items()}


def _client_addr(scope: Scope) -> str:
    client = scope.get("client")
    return client[0] if client else "unknown"


def _is_page(path: str) -> bool:
    return path == "/" or path.endswith(".html") or path in ("/viz", "/viz/", "/docs", "/redoc")


class SecurityMiddleware:
    """Resolve the caller (cookies), apply ``POLICY``, keep lease presence, set the client cookie."""

    def __init__(
        self, app: ASGIApp, *, auth: AuthContext, guard: LeaseGuard, limiter: RateLimiter | None = None
    ) -> None:
        self.app = app
        self.auth = auth
        self.guard = guard
        self.limiter = limiter or RateLimiter()  # control endpoints (app/ratelimit.py); never the e-stop
        self.secure = "; Secure" if auth.secure_cookies else ""

    def resolve(self, scope: Scope) -> tuple[Principal | None, str | None]:
        """(principal or None, a new client id to set as cookie or None)."""
        cookies = _cookies(scope)
        cid = cookies.get(CLIENT_COOKIE, "")
        new_cid = None
        if not _CLIENT_RE.match(cid):
            new_cid = secrets.token_urlsafe(18)
            cid = f"addr:{_client_addr(scope)}"
        if not self.auth.require_auth:
            return Principal(client_id=cid, role=Role.OPERATOR), new_cid
        token = cookies.get(SESSION_COOKIE, "")
        if not token:
            return None, new_cid
        now = time.monotonic()
        cache = self.auth.cache
        hit = cache.get(token)
        if hit is not None and now - hit[0] < self.auth.cache_s:
            p = hit[1]
            if p is not None and p.expired():
                p = None
        else:
            found = self.auth.store.lookup(token)
            p = None
            if found is not None:
                user, expires = found
                p = Principal(cid, Role(user.role), user.username, token_digest(token), expires)
            if len(cache) > 1000:
                cache.clear()
            cache[token] = (now, p)
        if p is None:
            return None, new_cid
        # A signed-in script without a client cookie is one station per sign-in, not per address.
        station = cid if new_cid is None else f"s:{p.token_hash[:24]}"
        return Principal(station, p.role, p.username, p.token_hash, p.expires_at), new_cid

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        principal, new_cid = self.resolve(scope)
        scope.setdefault("state", {})["principal"] = principal
        path = scope.get("path", "/")
        method = "GET" if kind == "websocket" else scope.get("method", "GET")
        need = required(method, path)

        if kind == "websocket":
            if need > Need.PUBLIC and principal is None:
                await receive()  # websocket.connect
                await send({"type": "websocket.close", "code": 1008, "reason": "sign in required"})
                return
            await self.app(scope, receive, send)
            return

        if principal is not None:
            self.guard.touch(principal.client_id)
        refusal = self._refusal(need, method, path, principal, scope)
        if refusal is None and principal is not None and is_limited(method, path):
            wait = self.limiter.take(principal.client_id, _client_addr(scope))
            if wait > 0:
                after = self.limiter.retry_after(wait)
                detail = (
                    f"too many control requests: {self.limiter.rate:g} per second "
                    f"(bursts of {self.limiter.burst:g}); retry in {after} s"
                )
                refusal = 429, {"detail": detail}, [(b"retry-after", str(after).encode())]
        if refusal is not None:
            status, body, headers = refusal
            await _respond(send, status, body, headers)
            return

        # Browsers get their client cookie with a page (or sign-in); API scripts never see one, so every
        # request of a cookie-less script is the same station ``addr:<ip>``.
        gets_cookie = _is_page(path) or path.startswith("/api/auth/")
        extra = self._cookie_headers(new_cid if gets_cookie else None)
        try:
            if not extra:
                await self.app(scope, receive, send)
                return

            async def send_with_cookie(message: Message) -> None:
                if message["type"] == "http.response.start":
                    message = {**message, "headers": list(message.get("headers", [])) + extra}
                await send(message)

            await self.app(scope, receive, send_with_cookie)
        finally:
            # idle time counts from the answer too: a slow request (a goal on a busy machine) must not
            # let the lease lapse while it is being handled
            if principal is not None:
                self.guard.touch(principal.client_id)

    def _refusal(
        self, need: Need, method: str, path: str, p: Principal | None, scope: Scope
    ) -> tuple[int, dict | None, list] | None:
        if need == Need.PUBLIC:
            return None
        if p is None:
            if method in READ and _is_page(path):
                qs = scope.get("query_string", b"").decode("latin-1")
                target = path + (f"?{qs}" if qs else "")
                return 303, None, [(b"location", f"/login.html?next={quote(target, safe='')}".encode())]
            return 401, {"detail": "sign in required"}, [(b"www-authenticate", b'Cookie realm="navdeck"')]
        if need >= Need.OPERATOR and not p.can_drive:
            return 403, {"detail": f"{p.display} is a {p.role.value}: only operators may do this"}, []
        if need == Need.UNCONTESTED:
            body = self.guard.uncontested_refusal(p)
            if body is not None:
                return 409, body, []
        if need == Need.DRIVE:
            body = self.guard.drive_refusal(p)
            if body is not None:
                return 409, body, []
        return None

    def _cookie_headers(self, new_cid: str | None) -> list[tuple[bytes, bytes]]:
        if new_cid is None:
            return []
        value = f"{CLIENT_COOKIE}={new_cid}; Path=/; Max-Age=31536000; SameSite=Strict; HttpOnly{self.secure}"
        return [(b"set-cookie", value.encode())]


async def _respond(send: Send, status: int, body: dict | None, headers: list) -> None:
    """Answer from the middleware; a refusal is a problem-details body like every route's error."""
    if body is None:
        data, ctype = b"", b"application/json"
    else:
        body = dict(body)
        detail = str(body.pop("detail", ""))
        data = json.dumps(problem_body(status, detail, kind=_REFUSAL_KIND.get(status), **body)).encode()
        ctype = PROBLEM_MEDIA_TYPE.encode()
    hdrs = [(b"content-type", ctype), (b"content-length", str(len(data)).encode()), *headers]
    await send({"type": "http.response.start", "status": status, "headers": hdrs})
    await send({"type": "http.response.body", "body": data})


_REFUSAL_KIND = {401: "sign-in-required", 403: "forbidden", 409: "control-held", 429: "rate-limited"}


# Messages a viewer's 3D view must not send upstream to viser: clicks and drags (they set goals and
# initial poses) and GUI edits (shared by every client). msgpack keeps strings verbatim.
VIEWER_BLOCKED = (
    b"ScenePointerMessage",
    b"SceneNodeClickMessage",
    b"SceneNodeDragMessage",
    b"GuiUpdateMessage",
    b"TransformControlsUpdateMessage",
)


def make_viz_authorize(require_auth: bool) -> Callable[[Any], bool]:
    """The relay's ``authorize`` hook: signed in to watch; a viewer's pointer and GUI input is dropped."""

    def authorize(ws: Any) -> bool:
        p = principal_of(ws.scope)
        if p is None:
            return not require_auth
        if p.can_drive:
            return True
        inner = ws.receive

        async def receive_filtered() -> Message:
            while True:
                msg = await inner()
                data = msg.get("bytes") or (msg.get("text") or "").encode()
                if msg.get("type") == "websocket.receive" and any(b in data for b in VIEWER_BLOCKED):
                    continue
                return msg

        ws.receive = receive_filtered
        return True

    return authorize
