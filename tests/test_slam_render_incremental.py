"""The live map's incremental render equals the full render of the same submaps, exactly."""

from __future__ import annotations

import numpy as np
import pytest

from nav.grid import LogOddsGrid
from nav.slam.render import SubmapRender, render_submaps
from nav.slam.synthetic import LOOP_WAYPOINTS, box_world, cast_scan, drifting_odometry, loop_trajectory
from nav.slam.system import GraphSlam, SlamOptions
from nav.types import Pose2D


def _assert_same(a: LogOddsGrid, b: LogOddsGrid) -> None:
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.logodds, b.logodds)
    np.testing.assert_array_equal(a.seen, b.seen)


@pytest.mark.parametrize("across", [False, True])
def test_incremental_render_equals_the_full_render_across_optimizations(across: bool) -> None:
    """A drifting loop (odometry trusted, so loop closures move the finished submaps): the map is
    published every few scans, before and after the back end's optimizations."""
    options = SlamOptions(
        submap_num_range_data=10,
        linear_search_window=0.0,
        angular_search_window=0.0,
        translation_weight=1e4,
        rotation_weight=1e4,
        optimize_every_n_nodes=30,
        surface_wins_across_submaps=across,
    )
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS, 0.15, turn_step=np.radians(15))
    odom = drifting_odometry(truth, yaw_drift=0.01, scale=1.02)
    rng = np.random.default_rng(3)
    slam = GraphSlam(options)
    live = SubmapRender(options.grid_options(), across)  # fed every submap copied, as a reference
    o0 = Pose2D.from_array(odom[0])
    reused = 0
    for k in range(len(truth)):
        scan = cast_scan(
            grid, res, Pose2D.from_array(truth[k]), 180, range_max=6.0, noise=0.01, rng=rng, stamp=0.2 * k
        )
        slam.add_scan(scan, Pose2D.from_array(odom[k]).relative_to(o0))
        slam.optimize_if_due()
        if k % 7:
            continue
        with slam._lock:
            layers = slam._submap_layers(view=True)  # what map() places (the view rule)
            finished = sum(sm.finished for sm in slam._submaps)
        poses = np.array([ly[0].as_array() for ly in layers]).reshape(-1, 3)
        full = render_submaps(layers, options.grid_options(), across)
        kept = live.kept(poses)
        reused += kept > 0
        _assert_same(live.render(poses, finished, layers[kept:]), full)
        published = slam.map()
        assert published.geometry == full.to_occupancy_grid().geometry
        np.testing.assert_array_equal(published.data, full.to_occupancy_grid().data)
    assert slam.num_loop_closures > 0
    assert live.full_renders > 0, "no optimization moved a kept submap: the test tests nothing"
    assert reused > 10


def test_a_cell_keeps_its_value_when_the_map_grows() -> None:
    """The map's cells lie on the map frame's lattice, so a submap far away that widens the map
    changes no cell of the first submap's (the kept sum relies on it)."""
    opt = SlamOptions().grid_options()
    rng = np.random.default_rng(0)
    lo = rng.choice(np.array([opt.l_min, 0.0, opt.l_max], dtype=np.float32), size=(40, 50))
    sn = rng.random((40, 50)) < 0.9
    a = (Pose2D(0.013, -0.021, 0.3), np.array([-1.0, -0.7]), lo, sn)
    b = (Pose2D(-7.31, -5.17, -1.1), np.array([0.0, 0.0]), lo, sn)
    alone = render_submaps([a], opt)
    both = render_submaps([a, b], opt)
    shift = np.round((alone.origin - both.origin) / opt.resolution).astype(int)
    np.testing.assert_allclose(alone.origin - both.origin, shift * opt.resolution, atol=1e-9)
    h, w = alone.shape
    np.testing.assert_array_equal(
        both.logodds[shift[1] : shift[1] + h, shift[0] : shift[0] + w], alone.logodds
    )
