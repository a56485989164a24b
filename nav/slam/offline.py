"""Offline SLAM over a recorded sequence: the front end on every scan, the back end every
``SlamOptions.optimize_every_n_nodes`` nodes (what the live worker thread would do), and a final
optimization. Pure: records in, a finished :class:`GraphSlam` out.

With the log's raw odometry (``odometry=(t, poses)``) the odometry-to-laser time offset is
estimated from the data (:mod:`nav.slam.time_offset`) once ``odometry_lag_estimation_nodes`` nodes
are in; when it is significant the run restarts from the first scan with odometry interpolated at
``t_scan - lag``. A log without a lag (Intel) costs nothing extra."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from nav.slam.system import GraphSlam, SlamOptions
from nav.slam.time_offset import LagEstimate, estimate_odometry_lag, interpolate_poses
from nav.types import LaserScan, Pose2D

Progress = Callable[[int, int], None]
Record = tuple[float, LaserScan, Pose2D]


def _estimate_lag(slam: GraphSlam, t_odom: np.ndarray, odom: np.ndarray, options: SlamOptions) -> LagEstimate:
    stamps, poses = slam.front_end_nodes()
    return estimate_odometry_lag(stamps, poses[:, 2], t_odom, odom[:, 2], options.odometry_lag_max)


def _shifted(records: Sequence[Record], t_odom: np.ndarray, odom: np.ndarray, lag: float) -> list[Record]:
    t_scan = np.array([float(r[1].stamp) for r in records])
    pose = interpolate_poses(t_scan - lag, t_odom, odom)
    return [(r[0], r[1], Pose2D(*map(float, p))) for r, p in zip(records, pose, strict=True)]


def run_offline(
    records: Sequence[Record],
    laser_pose: Pose2D,
    options: SlamOptions | None = None,
    progress: Progress | None = None,
    odometry: tuple[np.ndarray, np.ndarray] | None = None,
) -> GraphSlam:
    """Run SLAM over ``(stamp, scan, odom)`` records; ``progress(done, total)`` after each scan.
    ``odometry``: the log's raw odometry samples ``(t (M,), poses (M, 3))`` the records' odometry
    was interpolated from; enables the time-offset estimation. The applied lag is
    ``slam.odometry_lag``."""
    o = options or SlamOptions()
    slam = GraphSlam(o)
    calibrate = odometry is not None and o.odometry_lag_estimation_nodes > 0
    total = len(records)
    k = 0
    while k < total:
        _stamp, scan, odom = records[k]
        slam.add_scan(scan, odom, laser_pose)
        slam.optimize_if_due()
        k += 1
        if progress is not None:
            progress(k, total)
        if calibrate and (slam.num_nodes >= o.odometry_lag_estimation_nodes or k == total):
            calibrate = False
            t_odom, poses = (np.asarray(a, float) for a in odometry)  # type: ignore[union-attr]
            est = _estimate_lag(slam, t_odom, poses, o)
            # restart only for a lag that matters and clearly explains the data better
            if abs(est.lag) >= o.odometry_lag_minimum and est.cost < 0.8 * est.cost_at_zero:
                records = _shifted(records, t_odom, poses, est.lag)
                slam = GraphSlam(o)
                slam.odometry_lag = est.lag
                k = 0
    slam.run_backend()
    while slam.unsearched_nodes:  # a confirmed global closure stops a round early
        slam.run_backend()
    return slam
