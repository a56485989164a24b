"""What one reference scan observed (nav/slam/coverage.py): the scan-to-scan counterpart of the
submap's observed cells, which the front end's matching leaves unobserved points out by."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.slam.coverage import observed_by_scan, observed_by_scan_reference
from nav.types import LaserScan, Pose2D


def _scan(ranges: list[float], angle_min: float, increment: float) -> LaserScan:
    return LaserScan(0.0, angle_min, increment, np.array(ranges, dtype=float), 0.1, 10.0)


def test_points_behind_the_surface_or_the_scan_are_not_observed() -> None:
    # a half-circle scan (-90..90 deg, 1 deg beams) that sees a wall 2 m ahead, no return at +90
    angles = np.radians(np.arange(-90, 91))
    ranges = np.where(np.abs(np.cos(angles)) > 1e-9, 2.0 / np.maximum(np.cos(angles), 1e-9), np.inf)
    ranges = np.minimum(ranges, 8.0)
    ranges[-1] = np.inf
    scan = _scan(list(ranges), -math.pi / 2, math.radians(1.0))
    pts = np.array(
        [
            [1.0, 0.0],  # in front of the wall: seen as free
            [2.03, 0.3],  # on the wall, within the margin
            [2.5, 0.0],  # behind the wall
            [-1.0, 0.0],  # behind the scan (it covers the front half only)
            [0.0, 1.0],  # along the +90 deg beam, which had no return (its neighbour reaches it)
            [0.0, 9.0],  # beyond every beam there
        ]
    )
    got = observed_by_scan(scan, 10.0, pts, 0.05)
    assert got.tolist() == [True, True, False, False, True, False]
    # a return beyond the range limit observes nothing
    far = _scan([4.0] * 181, -math.pi / 2, math.radians(1.0))
    assert not observed_by_scan(far, 3.0, np.array([[1.0, 0.0]]), 0.05).any()


def test_a_full_circle_wraps() -> None:
    # 360 beams from 0 to 2 pi (an RPLidar's layout): a point behind and one at -0.3 deg are seen
    scan = _scan([3.0] * 360, 0.0, 2 * math.pi / 360)
    pts = np.array([[-1.0, 0.0], [1.0, -0.005], [0.0, -2.0], [0.0, -3.5]])
    assert observed_by_scan(scan, 10.0, pts, 0.05).tolist() == [True, True, True, False]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("full", [False, True])
def test_compiled_equals_the_numpy_reference(seed: int, full: bool) -> None:
    rng = np.random.default_rng(seed)
    n = 360 if full else 180
    inc = 2 * math.pi / 360 if full else math.pi / 180
    ranges = rng.uniform(0.2, 9.0, n)
    ranges[rng.random(n) < 0.1] = np.inf
    ranges[rng.random(n) < 0.05] = np.nan
    scan = _scan(list(ranges), rng.uniform(-math.pi, 0.0), inc)
    pts = rng.uniform(-10.0, 10.0, (2000, 2))
    pose = Pose2D(*rng.uniform(-1.0, 1.0, 3))
    for at in (Pose2D(), pose):
        got = observed_by_scan(scan, 8.0, pts, 0.05, at)
        assert 0 < got.sum() < len(pts)
        assert np.array_equal(got, observed_by_scan_reference(scan, 8.0, pts, 0.05, at))
    # the pose takes the points into the scan's frame
    assert np.array_equal(
        observed_by_scan(scan, 8.0, pts, 0.05, pose),
        observed_by_scan(scan, 8.0, pose.transform_points(pts), 0.05),
    )
