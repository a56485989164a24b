"""Snapshots and their latest-value fan-out.

The control loop publishes one ``Snapshot`` per tick. Each subscriber holds only the newest one:
a slow subscriber skips snapshots and can never delay the loop (publishing is O(subscribers),
lock-free for the loop apart from one short lock, and never waits on a consumer).
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nav.types import LaserScan, OccupancyGrid, Path, Pose2D, Twist2D


@dataclass(frozen=True)
class Snapshot:
    """What the robot and the pipeline look like at one control tick (map frame unless noted)."""

    stamp: float
    seq: int
    mode: str
    pose: Pose2D  # base_link in map
    odom_pose: Pose2D  # base_link in odom
    velocity: Twist2D  # measured, body frame
    command: Twist2D  # sent to the driver this tick, body frame
    clamped: tuple[str, ...] = ()  # which command components were limited this tick
    scan: LaserScan | None = None  # latest scan, laser frame
    laser_pose: Pose2D = field(default_factory=Pose2D)  # laser in base_link
    trail: np.ndarray | None = None  # (N, 2) recent poses in map frame
    grid: OccupancyGrid | None = None  # current map (shared, immutable once published)
    grid_version: int = 0
    health: dict[str, Any] = field(default_factory=dict)
    estop: bool = False
    fault: str | None = None
    # Filled by later pipeline stages; None when not active.
    path: Path | None = None
    local_plan: np.ndarray | None = None
    goal: Pose2D | None = None
    particles: np.ndarray | None = None
    behavior: str | None = None
    extras: dict[str, Any] = field(default_factory=dict)


class Subscription:
    """One consumer's one-slot mailbox."""

    def __init__(self, bus: SnapshotBus, loop: asyncio.AbstractEventLoop | None) -> None:
        self._bus = bus
        self._loop = loop
        self._latest: Snapshot | None = None
        self._lock = threading.Lock()
        self._thread_event = threading.Event()
        self._async_event = asyncio.Event() if loop is not None else None
        self.dropped = 0  # snapshots overwritten before being read

    def _put(self, snap: Snapshot) -> None:
        with self._lock:
            if self._latest is not None:
                self.dropped += 1
            self._latest = snap
        self._thread_event.set()
        if self._loop is not None and self._async_event is not None:
            try:
                self._loop.call_soon_threadsafe(self._async_event.set)
            except RuntimeError:  # loop closed: the subscriber is gone
                self._bus.unsubscribe(self)

    def take(self) -> Snapshot | None:
        with self._lock:
            snap, self._latest = self._latest, None
            self._thread_event.clear()
            return snap

    def wait(self, timeout: float | None = None) -> Snapshot | None:
        """Blocking wait (for threads)."""
        self._thread_event.wait(timeout)
        return self.take()

    async def next(self) -> Snapshot:
        """Await the next snapshot (for asyncio consumers)."""
        assert self._async_event is not None, "subscribe with a loop to await"
        while True:
            snap = self.take()
            if snap is not None:
                return snap
            self._async_event.clear()
            snap = self.take()
            if snap is not None:
                return snap
            await self._async_event.wait()

    def close(self) -> None:
        self._bus.unsubscribe(self)


class SnapshotBus:
    def __init__(self) -> None:
        self._subs: list[Subscription] = []
        self._lock = threading.Lock()
        self.latest: Snapshot | None = None

    def subscribe(self, loop: asyncio.AbstractEventLoop | None = None) -> Subscription:
        sub = Subscription(self, loop)
        with self._lock:
            self._subs = [*self._subs, sub]
        if self.latest is not None:
            sub._put(self.latest)
        return sub

    def attach(self, sub: Subscription) -> Subscription:
        """Add a custom subscription (a Subscription subclass, e.g. a small ring buffer for a recorder
        that must see every snapshot); it gets the latest snapshot at once, like ``subscribe``."""
        with self._lock:
            self._subs = [*self._subs, sub]
        if self.latest is not None:
            sub._put(self.latest)
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        with self._lock:
            self._subs = [s for s in self._subs if s is not sub]

    @property
    def subscriber_count(self) -> int:
        return len(self._subs)

    def publish(self, snap: Snapshot) -> None:
        self.latest = snap
        for sub in self._subs:  # copy-on-write list: safe to iterate without the lock
            sub._put(snap)
