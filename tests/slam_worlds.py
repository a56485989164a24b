"""Shared SLAM test input for the matcher kernels' and the branch-and-bound's tests: one noisy
box-world scan inserted in a log-odds grid with a second noisy scan of the same place, and a field
of flat plateaus (ties)."""

from __future__ import annotations

import numpy as np

from nav.grid import LogOddsGrid, LogOddsOptions
from nav.slam.field import LikelihoodField
from nav.slam.synthetic import box_world, cast_scan
from nav.types import Pose2D

TRUTH = Pose2D(3.0, 2.0, 0.4)


def box_world_grid(seed: int) -> tuple[LogOddsGrid, np.ndarray]:
    """A log-odds grid of one noisy box-world scan taken at ``TRUTH``, and another noisy scan there."""
    grid, res = box_world()
    rng = np.random.default_rng(seed)
    g = LogOddsGrid(LogOddsOptions(resolution=0.05))
    g.insert_scan(Pose2D(), cast_scan(grid, res, TRUTH, 360, noise=0.01, rng=rng).points(), np.zeros((0, 2)))
    return g, cast_scan(grid, res, TRUTH, 360, noise=0.01, rng=rng).points()


def plateau_field(seed: int) -> LikelihoodField:
    """A field of few distinct values in flat blocks: many candidates score exactly the same (ties)."""
    rng = np.random.default_rng(seed)
    coarse = rng.choice(
        np.array([0.0, 0.25, 0.5, 1.0], dtype=np.float32), (12, 12), p=[0.55, 0.15, 0.15, 0.15]
    )
    return LikelihoodField(np.kron(coarse, np.ones((5, 5), dtype=np.float32)), np.zeros(2), 0.05)
