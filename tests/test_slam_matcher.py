"""Scan matching: known offsets recovered on synthetic scans and on real Intel Research Lab scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.datasets import SLAM_BENCHMARK
from nav.grid import LogOddsOptions
from nav.slam.matcher import RefineOptions, ScanMatchError, SearchWindow, correlative_search, match_scan
from nav.slam.submap import Submap
from nav.slam.synthetic import box_world, cast_scan
from nav.types import Pose2D

INTEL = SLAM_BENCHMARK / "bags/intel.orig.bag"
REFINE = RefineOptions(translation_weight=0.5, rotation_weight=2.0)


def _submap_from(points: np.ndarray) -> Submap:
    sm = Submap(0, Pose2D(), LogOddsOptions(resolution=0.05), sigma=0.05)
    sm.insert(0, Pose2D(), Pose2D(), points, np.zeros((0, 2)))
    return sm


@pytest.mark.parametrize("offset", [(0.06, -0.04, 0.05), (-0.08, 0.07, -0.12), (0.03, 0.09, 0.15)])
def test_recovers_known_offset_synthetic(offset: tuple[float, float, float]) -> None:
    grid, res = box_world()
    rng = np.random.default_rng(1)
    truth = Pose2D(3.0, 2.0, 0.4)
    ref = cast_scan(grid, res, truth, 360, noise=0.005, rng=rng)
    sm = _submap_from(ref.points())
    # the same place seen again with fresh noise; the prior is off by `offset`
    again = cast_scan(grid, res, truth, 360, noise=0.005, rng=rng).points()
    window = SearchWindow(0.15, math.radians(10), math.radians(0.5))
    pose, score = match_scan(sm.field(), again, Pose2D(*offset), window, REFINE)
    assert abs(pose.x) < 0.01 and abs(pose.y) < 0.01 and abs(pose.theta) < math.radians(0.5)
    assert score > 0.7


def test_coarse_to_fine_search_finds_large_offset() -> None:
    grid, res = box_world()
    truth = Pose2D(6.0, 3.0, -0.2)
    pts = cast_scan(grid, res, truth, 360).points()
    sm = _submap_from(pts)
    window = SearchWindow(1.5, math.radians(20), math.radians(0.5), levels=4, beam=64)
    pose, score = correlative_search(sm.field(window.levels), pts, Pose2D(0.9, -1.1, 0.25), window)
    assert math.hypot(pose.x, pose.y) < 0.06 and abs(pose.theta) < math.radians(1.0)
    assert score > 0.8


def test_empty_scan_raises() -> None:
    grid, res = box_world()
    sm = _submap_from(cast_scan(grid, res, Pose2D(3, 3, 0), 90).points())
    with pytest.raises(ScanMatchError):
        match_scan(sm.field(), np.zeros((0, 2)), Pose2D(), SearchWindow())


@pytest.mark.skipif(not INTEL.exists(), reason="Intel benchmark log not available")
def test_recovers_known_offset_on_real_intel_scans() -> None:
    from robot.logs.reader import load_log

    recs, _ = load_log(INTEL, max_scans=400)
    # a scan from the middle of the slice, matched against a submap of itself + its neighbours
    # placed with odometry; the prior is the odometry pose shifted by a known offset
    base = recs[300]
    sm = Submap(0, Pose2D(), LogOddsOptions(resolution=0.05), sigma=0.05)
    sm.insert(0, Pose2D(), Pose2D(), base.scan.points(), np.zeros((0, 2)))
    offset = Pose2D(0.07, -0.06, math.radians(4.0))
    window = SearchWindow(0.15, math.radians(10), math.radians(0.5))
    pose, score = match_scan(sm.field(), base.scan.points(), offset, window, REFINE)
    assert math.hypot(pose.x, pose.y) < 0.02 and abs(pose.theta) < math.radians(0.5), pose
    assert score > 0.7
    # consecutive real scans: the match must agree with odometry to within odometry's error
    nxt = recs[302]
    odo = nxt.odom.relative_to(base.odom)
    pose2, score2 = match_scan(sm.field(), nxt.scan.points(), odo, window, REFINE)
    assert pose2.distance_to(odo) < 0.1 and abs(pose2.theta - odo.theta) < math.radians(3)
    assert score2 > 0.5


def test_default_refinement_is_not_pinned_to_the_search_lattice() -> None:
    # the truth lies half a lattice step (0.025 m) from every search pose: the refinement must
    # get there; the old 10 / 40 pull towards the lattice pose kept ~0.028 m of that offset
    from nav.slam.system import SlamOptions

    grid, res = box_world()
    rng = np.random.default_rng(2)
    truth = Pose2D(3.0, 2.0, 0.4)
    sm = _submap_from(cast_scan(grid, res, truth, 360, noise=0.005, rng=rng).points())
    again = cast_scan(grid, res, truth, 360, noise=0.005, rng=rng).points()
    window = SearchWindow(0.1, math.radians(10), math.radians(0.5))
    o = SlamOptions()
    default = RefineOptions(translation_weight=o.translation_weight, rotation_weight=o.rotation_weight)
    stiff = RefineOptions(translation_weight=10.0, rotation_weight=40.0)
    for offset in [(0.024, -0.026, 0.004), (0.074, 0.026, 0.0)]:
        pose, _ = match_scan(sm.field(), again, Pose2D(*offset), window, default)
        pinned, _ = match_scan(sm.field(), again, Pose2D(*offset), window, stiff)
        assert math.hypot(pose.x, pose.y) < 0.015, pose
        assert math.hypot(pinned.x, pinned.y) > 2 * math.hypot(pose.x, pose.y), (pinned, pose)
