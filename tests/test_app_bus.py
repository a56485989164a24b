"""The snapshot fan-out never blocks the publisher: slow subscribers lose old snapshots."""

from __future__ import annotations

import asyncio

from app.bus import Snapshot, SnapshotBus
from nav.types import Pose2D, Twist2D


def snap(i: int) -> Snapshot:
    return Snapshot(
        stamp=float(i),
        seq=i,
        mode="idle",
        pose=Pose2D(),
        odom_pose=Pose2D(),
        velocity=Twist2D(),
        command=Twist2D(),
    )


def test_slow_subscriber_gets_only_latest() -> None:
    bus = SnapshotBus()
    slow = bus.subscribe()
    for i in range(100):
        bus.publish(snap(i))
    got = slow.take()
    assert got is not None and got.seq == 99
    assert slow.dropped == 99
    assert slow.take() is None


def test_async_subscriber_wakes_on_publish_from_thread() -> None:
    async def main() -> int:
        bus = SnapshotBus()
        sub = bus.subscribe(asyncio.get_running_loop())
        loop = asyncio.get_running_loop()
        loop.run_in_executor(None, lambda: [bus.publish(snap(i)) for i in range(5)])
        s = await asyncio.wait_for(sub.next(), 2.0)
        sub.close()
        assert bus.subscriber_count == 0
        return s.seq

    assert asyncio.run(main()) >= 0


def test_late_subscriber_gets_current_state() -> None:
    bus = SnapshotBus()
    bus.publish(snap(7))
    assert bus.subscribe().take().seq == 7
