"""Operator notices: session events a dashboard must show where the operator is looking.

Refusals that happen on the server, not in answer to the browser's own request (a click in the 3D view
goes browser -> viser -> session), and notices such as "the pose now counts from the new map frame"
reach the dashboard through its telemetry socket: every message carries the ``notices`` recorded since
the previous one. An event with a ``tab`` goes only to that browser tab (the tab whose 3D view was
clicked); one without goes to every dashboard.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from app.session import Session

OPERATOR_EVENTS = frozenset({"refused", "notice"})
MAX_PENDING = 32  # a dashboard that stops reading loses the oldest, never grows the server's memory


class NoticeTap:
    """Collects the operator events meant for one dashboard tab until ``drain()`` (thread-safe: events
    are added on the session's thread, drained on uvicorn's loop)."""

    def __init__(self, session: Session, tab: str | None) -> None:
        self.session = session
        self.tab = tab or None
        self._pending: deque[dict[str, Any]] = deque(maxlen=MAX_PENDING)
        session.event_listeners.append(self._on_event)

    def _on_event(self, ev: dict[str, Any]) -> None:
        if ev.get("type") in OPERATOR_EVENTS and ev.get("tab") in (None, "", self.tab):
            self._pending.append(ev)

    def drain(self) -> list[dict[str, Any]]:
        out = []
        while self._pending:
            out.append(self._pending.popleft())
        return out

    def close(self) -> None:
        if self._on_event in self.session.event_listeners:
            self.session.event_listeners.remove(self._on_event)
