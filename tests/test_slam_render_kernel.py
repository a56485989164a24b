"""The compiled submap placement of the map render equals its numpy references."""

from __future__ import annotations

import numpy as np
import pytest

from nav.slam.kernels import place_submap
from nav.slam.render import SURFACE_SAMPLE, _lookup, _surface_wins
from nav.types import Pose2D


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_compiled_submap_placement_equals_numpys(seed: int) -> None:
    rng = np.random.default_rng(seed)
    res = 0.05
    lo = rng.choice(np.array([-2.0, -0.4, 0.0, 0.4, 2.0], dtype=np.float32), size=(60, 80))
    sn = rng.random((60, 80)) < 0.8
    origin = rng.uniform(-2.0, 0.0, 2)
    pose = Pose2D(*rng.uniform(-1.0, 1.0, 2), float(rng.uniform(-np.pi, np.pi)))
    gx = -5.0 + (np.arange(200) + 0.5) * res
    gy = -4.0 + (np.arange(180) + 0.5) * res
    xx, yy = np.meshgrid(gx, gy)
    for surface_wins, reference in ((True, _surface_wins), (False, _lookup)):
        val, ok = place_submap(
            pose.as_array(), origin, lo, sn, gx, gy, res, SURFACE_SAMPLE * res, surface_wins
        )
        ref_val, ref_ok = reference(pose, origin, lo, sn, xx, yy, res)
        assert 0 < np.count_nonzero(ok) < ok.size  # the submap covers part of the window
        np.testing.assert_array_equal(ok, ref_ok)
        np.testing.assert_array_equal(val, ref_val)
