"""Clocks: wall time when serving, a virtual clock for tests, benchmarks and ``sim-nav``.

The control loop asks the clock for ``now()`` and ``sleep_until(t)``. The virtual clock jumps
straight to ``t`` so the same code runs as fast as the machine allows and is deterministic.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float: ...

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> None:
        """Return at time ``t`` (or early when ``stop`` is set)."""
        ...

    @property
    def is_virtual(self) -> bool: ...


class RealClock:
    """Monotonic wall time."""

    is_virtual = False

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> None:
        delay = t - time.monotonic()
        if delay <= 0:
            return
        if stop is not None:
            stop.wait(delay)
        else:
            time.sleep(delay)


class VirtualClock:
    """Time that only moves when someone sleeps: deterministic and as fast as the CPU allows."""

    is_virtual = True

    def __init__(self, start: float = 0.0) -> None:
        self._t = start
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> None:
        with self._lock:
            if t > self._t:
                self._t = t

    def advance(self, dt: float) -> None:
        with self._lock:
            self._t += dt
