"""The control lease: exactly one client drives at a time; everyone can see who."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class LeaseHolder:
    client_id: str
    name: str
    since: float


class ControlLease:
    def __init__(self) -> None:
        self._holder: LeaseHolder | None = None
        self._lock = threading.Lock()

    @property
    def holder(self) -> LeaseHolder | None:
        return self._holder

    def acquire(self, client_id: str, name: str = "", *, take_over: bool = False) -> bool:
        """Take the lease if it is free (or held by this client); ``take_over`` steals it."""
        with self._lock:
            if self._holder is None or self._holder.client_id == client_id or take_over:
                if self._holder is None or self._holder.client_id != client_id:
                    self._holder = LeaseHolder(client_id, name or client_id, time.time())
                return True
            return False

    def release(self, client_id: str) -> bool:
        with self._lock:
            if self._holder is not None and self._holder.client_id == client_id:
                self._holder = None
                return True
            return False

    def holds(self, client_id: str) -> bool:
        h = self._holder
        return h is not None and h.client_id == client_id

    def as_dict(self) -> dict:
        h = self._holder
        return {"holder": None if h is None else {"client_id": h.client_id, "name": h.name, "since": h.since}}
