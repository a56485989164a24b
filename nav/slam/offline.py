"""Offline SLAM over a recorded sequence: the front end on every scan, the back end every
``SlamOptions.optimize_every_n_nodes`` nodes (what the live worker thread would do), and a final
optimization. Pure: records in, a finished :class:`GraphSlam` out."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from nav.slam.system import GraphSlam, SlamOptions
from nav.types import LaserScan, Pose2D

Progress = Callable[[int, int], None]


def run_offline(
    records: Sequence[tuple[float, LaserScan, Pose2D]],
    laser_pose: Pose2D,
    options: SlamOptions | None = None,
    progress: Progress | None = None,
) -> GraphSlam:
    """Run SLAM over ``(stamp, scan, odom)`` records; ``progress(done, total)`` after each scan."""
    slam = GraphSlam(options)
    total = len(records)
    for k, (_stamp, scan, odom) in enumerate(records):
        slam.add_scan(scan, odom, laser_pose)
        slam.optimize_if_due()
        if progress is not None:
            progress(k + 1, total)
    slam.run_backend()
    return slam
