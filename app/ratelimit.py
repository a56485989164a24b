"""Per-client token buckets for the control endpoints (issue 9 part 5; docs/reliability.md).

A script or a stuck browser tab hammering goals, mode changes or resets must not flood the control
loop, the planner or the run log. Each client (the station id ``SecurityMiddleware`` resolved: the
client cookie, a sign-in, or ``addr:<ip>``) has a bucket of ``burst`` tokens refilled at ``rate`` per
second; its address has a second bucket ``per_address`` times larger, so rotating cookies buys nothing.
An empty bucket answers 429 with ``Retry-After`` (RFC 6585). The e-stop is never limited: it is not in
``CONTROL_PREFIXES`` and ``is_limited`` refuses it explicitly.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

# Writes that command the robot or its control state. Sign-in has its own throttle (app.auth).
CONTROL_PREFIXES: tuple[str, ...] = (
    "/api/robot/mode",
    "/api/robot/reset",
    "/api/control/acquire",
    "/api/teleop",
    "/api/mapping",
    "/api/localization",
    "/api/navigation",
    "/api/behaviors",
)
NEVER_LIMITED = ("/api/robot/estop",)
WRITES = frozenset({"POST", "PUT", "PATCH", "DELETE"})


def is_limited(method: str, path: str) -> bool:
    """True for a write to a control endpoint; the e-stop never."""
    if method not in WRITES or any(path == p or path.startswith(p + "/") for p in NEVER_LIMITED):
        return False
    return any(path == p or path.startswith(p + "/") for p in CONTROL_PREFIXES)


@dataclass
class _Bucket:
    tokens: float
    stamp: float


@dataclass
class RateLimiter:
    """Token buckets keyed by client and by address. ``take`` returns 0 when allowed, else the
    seconds until a token is back (the ``Retry-After``)."""

    rate: float = 5.0  # tokens per second per client (300 control requests a minute)
    burst: float = 20.0  # bucket size: a burst of clicks or a waypoint list never waits
    per_address: float = 4.0  # the address bucket is this many clients wide
    max_keys: int = 4096  # idle full buckets are pruned past this many keys
    clock: object = time.monotonic
    _buckets: dict[str, _Bucket] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def _take(self, key: str, rate: float, burst: float, now: float) -> float:
        b = self._buckets.get(key)
        if b is None:
            b = self._buckets[key] = _Bucket(burst, now)
        b.tokens = min(burst, b.tokens + (now - b.stamp) * rate)
        b.stamp = now
        if b.tokens >= 1.0:
            return 0.0
        return (1.0 - b.tokens) / rate

    def take(self, client: str, address: str) -> float:
        now = self.clock()  # type: ignore[operator]
        k = self.per_address
        with self._lock:
            if len(self._buckets) > self.max_keys:
                self._prune(now)
            wait = max(
                self._take("c:" + client, self.rate, self.burst, now),
                self._take("a:" + address, self.rate * k, self.burst * k, now),
            )
            if wait == 0.0:  # take from both only when both allow (a refusal costs nothing)
                self._buckets["c:" + client].tokens -= 1.0
                self._buckets["a:" + address].tokens -= 1.0
            return wait

    def _prune(self, now: float) -> None:
        idle = max(self.burst / self.rate, 1.0) * self.per_address
        for key in [k for k, b in self._buckets.items() if now - b.stamp > idle]:
            del self._buckets[key]

    def retry_after(self, wait: float) -> int:
        """Whole seconds for the header (at least 1)."""
        return max(1, math.ceil(wait))


RATE_LIMITED_RESPONSE = {
    "description": "too many control requests from this client: wait ``Retry-After`` seconds",
    "headers": {"Retry-After": {"schema": {"type": "integer"}, "description": "seconds to wait"}},
    "content": {
        "application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}},
    },
}


def document_rate_limits(app) -> None:
    """Add the 429 answer to every rate-limited operation of ``app``'s OpenAPI schema."""
    inner = app.openapi

    def openapi() -> dict:
        schema = inner()
        for path, ops in schema.get("paths", {}).items():
            for method, op in ops.items():
                if isinstance(op, dict) and is_limited(method.upper(), path):
                    op.setdefault("responses", {}).setdefault("429", RATE_LIMITED_RESPONSE)
        return schema

    app.openapi = openapi
