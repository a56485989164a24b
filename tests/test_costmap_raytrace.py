"""The compiled beam clearing visits exactly the supercover cells of ``nav.raycast.traversed_cells``."""

from __future__ import annotations

import numpy as np
import pytest

from nav.costmap.raytrace import clear_segments
from nav.raycast import traversed_cells
from nav.types import GridGeometry, Pose2D


@pytest.mark.parametrize("theta", [0.0, 0.3])
@pytest.mark.parametrize("include_end", [False, True])
def test_clear_segments_matches_traversed_cells(theta: float, include_end: bool) -> None:
    rng = np.random.default_rng(7)
    geo = GridGeometry(0.05, 60, 50, Pose2D(-1.0, -0.7, theta))
    for _ in range(20):
        # a few segments at a time so a wrong or missing cell is not hidden by another segment;
        # many start or end off the grid (clipped), some are short and inside one cell
        starts = rng.uniform(-2.0, 3.0, (3, 2))
        ends = starts + rng.uniform(-3.0, 3.0, (3, 2)) * rng.choice([1.0, 0.01], (3, 1))
        ref = np.zeros((50, 60), np.uint8)
        r, c, _ = traversed_cells(geo, starts, ends, include_end=include_end)
        ref[r, c] = 1
        got = np.zeros((50, 60), np.uint8)
        bounds = clear_segments(got, geo, starts, ends, 1, include_end=include_end)
        assert np.array_equal(got, ref)
        if r.size:
            assert bounds == (r.min(), r.max() + 1, c.min(), c.max() + 1)
        else:
            assert bounds is None


def test_clear_segments_leaves_the_end_cell_and_other_cells() -> None:
    geo = GridGeometry(0.1, 10, 10, Pose2D())
    costs = np.full((10, 10), 254, np.uint8)
    clear_segments(costs, geo, np.array([[0.05, 0.55]]), np.array([[0.75, 0.55]]), 0)
    assert costs[5, :7].tolist() == [0] * 7  # cells 0..6 cleared along row 5
    assert costs[5, 7] == 254  # the return's cell is kept
    assert (costs[np.arange(10) != 5] == 254).all()
