"""The scan-to-scan matcher (nav/slam/scan_to_scan.py): its one compiled call gives, bit for bit, what
the separate steps give (field, coverage, the front end's search with its wide re-search, refinement),
and it recovers a known motion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench import peers
from nav.slam import scan_to_scan
from nav.slam.coverage import observed_by_scan, observed_subset
from nav.slam.field import LikelihoodField, _window_kernel
from nav.slam.matcher import ScanMatchError, match_scan_with_fallback
from nav.slam.scan_to_scan import ScanToScanMatcher, _thinned
from nav.slam.synthetic import box_world, cast_scan
from nav.slam.system import SlamOptions
from nav.types import LaserScan, Pose2D


def separate_steps(m: ScanToScanMatcher, ref: LaserScan, ref_pts: np.ndarray, pts: np.ndarray, prior: Pose2D):
    """The match as the separate steps (each with its own tests against numpy) make it."""
    field = LikelihoodField.from_points(ref_pts, m.resolution, m.sigma)
    kept = observed_subset(pts, observed_by_scan(ref, m.range_limit, pts, m.resolution, prior))
    pts = pts if kept is None else kept
    return match_scan_with_fallback(field, pts, prior, m.window, m.wide_window, m.minimum_score, m.refine)


def test_one_call_equals_the_separate_steps_on_intel_pairs() -> None:
    # the bench's 50 consecutive and 50 relation pairs: every branch (all points kept or a subset,
    # more and fewer than max_points, the wide re-search on 7 relation pairs)
    if not (peers.INTEL_BAG.exists() and peers.INTEL_RELATIONS.exists()):
        pytest.skip(f"{peers.INTEL_BAG} missing")
    consecutive, related, _ = peers.intel_pairs()
    m = ScanToScanMatcher(range_limit=peers.MATCH_RANGE)
    wide = 0
    for ref, cur, prior in consecutive + related:
        ref_pts, pts = peers._scan_points(ref), peers._scan_points(cur)
        got = m.match(ref, ref_pts, pts, prior)
        assert got == separate_steps(m, ref, ref_pts, pts, prior)
        wide += got[1] < m.minimum_score
    assert wide > 0


def test_one_call_equals_the_separate_steps_on_the_box_world() -> None:
    # a full-circle scan, points the reference did not see, an odometry prior off by 5 cm
    grid, res = box_world()
    rng = np.random.default_rng(4)
    m = ScanToScanMatcher()
    for k in range(6):
        a = Pose2D(*rng.uniform([2.0, 1.5, -3.0], [4.0, 2.5, 3.0]))
        b = a.compose(Pose2D(*rng.uniform([-0.3, -0.2, -0.2], [0.3, 0.2, 0.2])))
        fov = (math.pi, 2 * math.pi)[k % 2]
        ref = cast_scan(grid, res, a, 360, fov=fov, noise=0.01, rng=rng)
        cur = cast_scan(grid, res, b, 360, fov=fov, noise=0.01, rng=rng)
        truth = b.relative_to(a)
        prior = Pose2D(truth.x + 0.04, truth.y - 0.03, truth.theta + 0.02)
        ref_pts, pts = peers._scan_points(ref), peers._scan_points(cur)
        got = m.match(ref, ref_pts, pts, prior)
        assert got == separate_steps(m, ref, ref_pts, pts, prior)
        assert got[0].distance_to(truth) < 0.03


@pytest.mark.parametrize("sigma", [0.05, 0.2])
def test_the_wide_re_search_in_one_call_equals_the_separate_steps(
    sigma: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # an odometry prior 0.3 m and 0.25 rad off: beyond the narrow window. With sigma 0.2 the
    # field's kernel is wider than its margin, and the pooled levels come from max-pooling the field
    # rather than from splats of the scan's cells
    grid, res = box_world()
    rng = np.random.default_rng(9)
    # (a blurred field scores a poor match high: the threshold makes every match search again)
    m = ScanToScanMatcher(SlamOptions(likelihood_sigma=sigma, wide_search_minimum_score=0.99))
    radius = _window_kernel(sigma, res, 0).shape[0] // 2
    assert (radius > 10) == (sigma > 0.1)  # 0.2: wider than the 0.5 m margin (10 cells)
    calls = []
    one_call = scan_to_scan.wide_match
    monkeypatch.setattr(scan_to_scan, "wide_match", lambda *a: calls.append(a) or one_call(*a))
    for _ in range(3):
        a = Pose2D(*rng.uniform([2.0, 1.5, -3.0], [4.0, 2.5, 3.0]))
        b = a.compose(Pose2D(*rng.uniform([-0.2, -0.2, -0.2], [0.2, 0.2, 0.2])))
        ref = cast_scan(grid, res, a, 360, fov=2 * math.pi, noise=0.01, rng=rng)
        cur = cast_scan(grid, res, b, 360, fov=2 * math.pi, noise=0.01, rng=rng)
        truth = b.relative_to(a)
        prior = Pose2D(truth.x + 0.3, truth.y - 0.2, truth.theta + 0.25)
        ref_pts, pts = peers._scan_points(ref), peers._scan_points(cur)
        got = m.match(ref, ref_pts, pts, prior)
        assert got == separate_steps(m, ref, ref_pts, pts, prior)
        if sigma < 0.1:
            assert got[0].distance_to(truth) < 0.05  # found by the wide re-search
    assert calls  # the wide re-search ran


def test_thinning_equals_numpys_linspace() -> None:
    for n, k in ((101, 100), (180, 100), (361, 100), (1000, 7), (5, 2), (40, 1)):
        assert np.array_equal(_thinned(n, k), np.linspace(0, n - 1, k).astype(np.int64))


def test_empty_scans_are_refused_with_a_clear_error() -> None:
    grid, res = box_world()
    ref = cast_scan(grid, res, Pose2D(3.0, 2.0, 0.0), 180, fov=math.pi)
    m = ScanToScanMatcher()
    with pytest.raises(ValueError, match="no points"):
        m.match(ref, np.zeros((0, 2)), peers._scan_points(ref), Pose2D())
    with pytest.raises(ScanMatchError):
        m.match(ref, peers._scan_points(ref), np.zeros((0, 2)), Pose2D())
