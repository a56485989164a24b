"""Odometry-to-laser time offset: recovered from heading increments, and applied by the offline
driver (which restarts with shifted odometry) only when it is significant."""

from __future__ import annotations

import numpy as np

from nav.slam.offline import run_offline
from nav.slam.synthetic import LOOP_WAYPOINTS, box_world, cast_scan, loop_trajectory
from nav.slam.system import SlamOptions
from nav.slam.time_offset import estimate_odometry_lag, interpolate_poses
from nav.types import Pose2D


def _heading(t: np.ndarray) -> np.ndarray:
    """A robot that turns in bursts (yaw rate changes are what make a lag observable)."""
    return 0.8 * np.sin(0.7 * t) + 0.3 * np.sin(2.3 * t)


def test_recovers_known_lag() -> None:
    rng = np.random.default_rng(1)
    t_scan = np.cumsum(rng.uniform(0.18, 0.22, 400))
    t_odom = np.arange(0.0, t_scan[-1] + 1.0, 0.12)
    for lag in (0.0, 0.13, -0.07):
        # the laser stamped ``lag`` late against odometry: the odometry stamped t is the heading
        # the laser would stamp t + lag
        odom_theta = _heading(t_odom + lag)
        headings = _heading(t_scan) + rng.normal(0, np.radians(0.3), t_scan.size) + 2.0  # other frame
        est = estimate_odometry_lag(t_scan, headings, t_odom, odom_theta)
        assert abs(est.lag - lag) < 0.01, (lag, est)
        if lag:
            assert est.cost < 0.5 * est.cost_at_zero


def test_straight_driving_gives_no_lag() -> None:
    t_scan = np.arange(0.0, 60.0, 0.2)
    t_odom = np.arange(0.0, 61.0, 0.1)
    est = estimate_odometry_lag(t_scan, np.full(t_scan.size, 0.4), t_odom, np.full(t_odom.size, 0.1))
    assert est.lag == 0.0 and est.cost == est.cost_at_zero


def _offline_run(lag: float) -> float:
    """Offline SLAM on a synthetic loop with the laser stamped ``lag`` s late against odometry;
    returns the applied lag."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS[:3], 0.12, turn_step=np.radians(12))[:100]  # one turn
    t_scan = 0.2 * np.arange(len(truth))
    t_odom = t_scan - lag  # the odometry sample of truth[k] is stamped lag before its scan
    rng = np.random.default_rng(4)
    recs = []
    odom = interpolate_poses(t_scan, t_odom, truth)
    for k in range(len(truth)):
        scan = cast_scan(
            grid, res, Pose2D.from_array(truth[k]), 90, range_max=6.0, noise=0.01, rng=rng, stamp=t_scan[k]
        )
        recs.append((t_scan[k], scan, Pose2D.from_array(odom[k])))
    opts = SlamOptions(odometry_lag_estimation_nodes=95, submap_num_range_data=15)
    slam = run_offline(recs, Pose2D(), opts, odometry=(t_odom, truth))
    return slam.odometry_lag


def test_offline_driver_applies_the_estimated_lag() -> None:
    applied = _offline_run(0.1)
    assert abs(applied - 0.1) < 0.02, applied
    assert _offline_run(0.0) == 0.0
