"""SLAM gets the wheel odometry at the scan's own stamp, not the later tick's (issue 18)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from app.odometry_history import OdometryHistory
from bench.mapping import APARTMENT_START, build
from nav.types import LaserScan, Pose2D, Twist2D


def test_history_interpolates_between_updates_and_unwraps_the_heading() -> None:
    h = OdometryHistory()
    h.add(1.0, Pose2D(0.0, 0.0, math.pi - 0.1))
    h.add(1.1, Pose2D(0.02, -0.01, -math.pi + 0.1))  # turned 0.2 rad through +-pi
    pose, older = h.pose_at(1.025)
    assert not older
    assert pose.x == pytest.approx(0.005) and pose.y == pytest.approx(-0.0025)
    assert abs(math.remainder(pose.theta - (math.pi - 0.05), 2 * math.pi)) < 1e-9


def test_history_holds_at_the_ends_and_says_when_a_stamp_is_older() -> None:
    h = OdometryHistory()
    assert h.pose_at(0.0) is None
    h.add(1.0, Pose2D(1.0, 0.0, 0.0))
    h.add(1.05, Pose2D(2.0, 0.0, 0.0))
    newer, older = h.pose_at(1.2)
    assert newer.x == pytest.approx(2.0) and not older
    oldest, older = h.pose_at(0.5)
    assert oldest.x == pytest.approx(1.0) and older


def test_history_is_bounded_and_restarts_when_the_clock_goes_back() -> None:
    h = OdometryHistory(horizon=0.5)
    for k in range(100):
        h.add(0.05 * k, Pose2D(0.01 * k, 0.0, 0.0))
    assert len(h) == 11  # 0.5 s at 20 Hz, both ends kept
    h.add(4.95, Pose2D(5.0, 0.0, 0.0))  # the same stamp again replaces the newest
    assert len(h) == 11 and h.pose_at(4.95)[0].x == pytest.approx(5.0)
    h.add(0.1, Pose2D(0.0, 1.0, 0.0))  # the base's clock restarted
    assert len(h) == 1 and h.pose_at(4.0)[0].y == pytest.approx(1.0)


def test_mapping_hands_slam_the_odometry_at_the_scan_stamp() -> None:
    """A scan stamped between two ticks gets the pose interpolated between their odometry, and one
    older than the history the oldest pose (counted); the old stage gave the tick's pose."""
    drive = build("apartment", APARTMENT_START)
    s, m = drive.session, drive.mapping
    try:
        m.start()
        ticks: list[tuple[float, Pose2D]] = []
        for _ in range(20):
            s.set_teleop(Twist2D(0.2, 0.0, 0.4), "test")  # moving and turning: every tick moves
            s.run_for(s.period)
            ticks.append((s._last_frame.ticks.stamp, s.odom_pose))
        (t0, p0), (t1, p1) = ticks[-2], ticks[-1]
        assert p0.distance_to(p1) > 0.005

        given: list[tuple[float, Pose2D]] = []
        add_scan = m.slam.add_scan

        def record(scan: LaserScan, odom: Pose2D, laser_pose: Pose2D) -> object:
            given.append((scan.stamp, odom))
            return add_scan(scan, odom, laser_pose)

        m.slam.add_scan = record  # type: ignore[method-assign]
        frame = s._last_frame
        held = m.scans_older_than_odometry  # a scan before the first odometry update may count
        mid = replace(s.last_scan, stamp=0.25 * t0 + 0.75 * t1)
        m.tick(s, replace(frame, scan=mid), s.clock.now())
        stamp, odom = given[-1]
        assert stamp == mid.stamp
        assert odom.x == pytest.approx(0.25 * p0.x + 0.75 * p1.x, abs=1e-9)
        assert odom.y == pytest.approx(0.25 * p0.y + 0.75 * p1.y, abs=1e-9)
        assert odom.theta == pytest.approx(0.25 * p0.theta + 0.75 * p1.theta, abs=1e-9)
        assert m.scans_older_than_odometry == held

        ancient = replace(s.last_scan, stamp=t1 - 10.0)  # before the 2 s history
        m.tick(s, replace(frame, scan=ancient), s.clock.now())
        oldest_stamp = min(t for t, _ in ticks if t >= t1 - s.options.odom_history)
        oldest = dict(ticks)[oldest_stamp]
        assert np.allclose(
            (given[-1][1].x, given[-1][1].y, given[-1][1].theta), (oldest.x, oldest.y, oldest.theta)
        )
        assert m.scans_older_than_odometry == held + 1
        assert m.state()["scans_older_than_odometry"] == held + 1
    finally:
        s.close()
