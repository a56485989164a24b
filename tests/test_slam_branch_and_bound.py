"""The branch-and-bound correlative search (nav/slam/branch_and_bound.py) returns what scoring every
candidate at full resolution returns (the numpy reference), with or without an incumbent."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_worlds import box_world_grid, plateau_field

from bench import peers
from nav.slam.field import LikelihoodField
from nav.slam.matcher import (
    SearchWindow,
    correlative_search,
    correlative_search_reference,
    nested,
)
from nav.slam.scan_to_scan import ScanToScanMatcher
from nav.slam.system import SlamOptions
from nav.types import Pose2D


def _world(seed: int) -> tuple[LikelihoodField, np.ndarray]:
    """The field of one noisy box-world scan's grid, and another noisy scan of the same place."""
    g, pts = box_world_grid(seed)
    return LikelihoodField.from_grid(g), pts


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("levels", [1, 2, 3, 4])
def test_branch_and_bound_equals_the_exhaustive_reference(seed: int, levels: int) -> None:
    rng = np.random.default_rng(seed)
    field, pts = _world(seed)
    grid_pts = np.round(rng.uniform(0.2, 2.8, (60, 2)) / 0.05) * 0.05 - 1.5
    cases = [
        (field, pts, Pose2D(*rng.uniform([-0.3, -0.3, -0.2], [0.3, 0.3, 0.2]))),
        (plateau_field(seed), grid_pts, Pose2D(1.5, 1.5, rng.choice([0.0, 0.02]))),
        # every candidate ties: only the tie-break (the prior itself) may win
        (
            LikelihoodField(np.full((80, 80), 0.5, dtype=np.float32), np.zeros(2), 0.05),
            grid_pts,
            Pose2D(2, 2, 0),
        ),
    ]
    for f, p, prior in cases:
        for half_width in (0.15, 0.4):
            window = SearchWindow(
                half_width, math.radians(6.0), math.radians(0.5), levels, branch_and_bound=True
            )
            pose, score = correlative_search(f, p, prior, window)
            ref_pose, ref_score, _ = correlative_search_reference(f, p, prior, window, math.inf)
            assert (pose, score) == (ref_pose, ref_score)


def test_branch_and_bound_finds_a_large_offset() -> None:
    field, pts = _world(7)
    prior = Pose2D(0.35, -0.3, math.radians(-12))
    window = SearchWindow(0.5, math.radians(20.0), math.radians(0.5), 4, branch_and_bound=True)
    pose, _ = correlative_search(field, pts, prior, window)
    assert math.hypot(pose.x, pose.y) < 0.06 and abs(pose.theta) < math.radians(1.5)


def test_the_narrow_match_as_incumbent_changes_nothing_on_intel_relation_pairs() -> None:
    # the wide re-search of the bench's 50 ground-truth relation pairs started from the narrow
    # search's best (as match_scan_with_fallback does) and from scratch: the same pose and score,
    # and the numpy reference's exhaustive search's on a few of them
    if not (peers.INTEL_BAG.exists() and peers.INTEL_RELATIONS.exists()):
        pytest.skip(f"{peers.INTEL_BAG} missing")
    _, related, _ = peers.intel_pairs()
    m = ScanToScanMatcher()
    wide = SlamOptions(wide_search_branch_and_bound=True, wide_search_levels=4).front_end_windows()[1]
    assert nested(m.window, wide)
    for k, (ref, cur, prior) in enumerate(related):
        field = LikelihoodField.from_points(peers._scan_points(ref), m.resolution, m.sigma)
        pts = peers._scan_points(cur)
        narrow = correlative_search(field, pts, prior, m.window)
        scratch = correlative_search(field, pts, prior, wide)
        assert correlative_search(field, pts, prior, wide, narrow) == scratch
        assert scratch[1] >= narrow[1]
        if k % 10 == 0:  # the numpy reference scores all 121 x 441 candidates: a few suffice
            ref_pose, ref_score, _ = correlative_search_reference(field, pts, prior, wide, math.inf)
            assert scratch == (ref_pose, ref_score)


def test_the_front_end_can_re_search_the_wide_window_by_branch_and_bound() -> None:
    narrow, wide = SlamOptions(wide_search_branch_and_bound=True, wide_search_levels=4).front_end_windows()
    assert wide.branch_and_bound and wide.levels == 4 and nested(narrow, wide)
    assert not SlamOptions().front_end_windows()[1].branch_and_bound
