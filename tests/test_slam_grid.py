"""LogOddsGrid: ray-traced free space, hits, clamping, growth and OccupancyGrid values."""

from __future__ import annotations

import numpy as np

from nav.grid import LogOddsGrid, LogOddsOptions, trace_rays
from nav.types import Pose2D


def test_single_ray_marks_free_cells_and_hit() -> None:
    g = LogOddsGrid(LogOddsOptions(resolution=0.1, grow_margin=1.0))
    g.insert_scan(Pose2D(0.05, 0.05, 0.0), np.array([[1.0, 0.0]]))
    occ = g.to_occupancy_grid()
    rows, cols = occ.geometry.world_to_cell(
        np.array([[1.05, 0.05], [0.55, 0.05], [0.05, 0.05], [0.05, 0.55]])
    )
    vals = occ.data[rows, cols]
    assert vals[0] == 70  # one hit at hit_probability 0.7
    assert vals[1] == 40  # one pass at miss_probability 0.4
    assert vals[2] == 40  # the sensor cell itself is traversed
    assert vals[3] == -1  # never observed
    assert set(np.unique(occ.data)) == {-1, 40, 70}
    assert occ.data.dtype == np.int8


def test_logodds_clamped_and_once_per_scan() -> None:
    opt = LogOddsOptions(resolution=0.1)
    g = LogOddsGrid(opt)
    # 50 beams to the same cell in one scan update it once
    g.insert_scan(Pose2D(), np.tile([[2.0, 0.0]], (50, 1)))
    r, c = g.cells(np.array([[2.0, 0.0]]))
    assert np.isclose(g.logodds[r[0], c[0]], opt.l_occ)
    for _ in range(40):
        g.insert_scan(Pose2D(), np.array([[2.0, 0.0]]))
    assert np.isclose(g.logodds[r[0], c[0]], opt.l_max)
    r2, c2 = g.cells(np.array([[1.0, 0.0]]))
    assert np.isclose(g.logodds[r2[0], c2[0]], opt.l_min)
    assert g.to_occupancy_grid().data[r[0], c[0]] == 97


def test_grid_grows_and_keeps_contents() -> None:
    g = LogOddsGrid(LogOddsOptions(resolution=0.05, grow_margin=0.5))
    g.insert_scan(Pose2D(), np.array([[1.0, 0.0]]))
    before = g.to_occupancy_grid()
    hit_world = np.array([[1.01, 0.01]])
    g.insert_scan(Pose2D(), np.array([[-6.0, 4.0]]))
    after = g.to_occupancy_grid()
    assert after.data.shape[0] > before.data.shape[0] and after.data.shape[1] > before.data.shape[1]
    rb, cb = before.geometry.world_to_cell(hit_world)
    ra, ca = after.geometry.world_to_cell(hit_world)
    assert before.data[rb[0], cb[0]] == after.data[ra[0], ca[0]] == 70
    ra, ca = after.geometry.world_to_cell(np.array([[-6.0 + 0.01, 4.0 + 0.01]]))
    assert after.data[ra[0], ca[0]] == 70


def test_no_return_beams_only_clear() -> None:
    g = LogOddsGrid(LogOddsOptions(resolution=0.1))
    g.insert_scan(Pose2D(), np.zeros((0, 2)), misses=np.array([[0.0, 1.0]]))
    assert g.logodds.max() <= 0.0
    assert (g.logodds < 0).sum() >= 10


def test_trace_rays_covers_every_crossed_cell() -> None:
    rng = np.random.default_rng(3)
    ends = rng.uniform(-5, 5, (200, 2))
    pts, ray = trace_rays(np.zeros((200, 2)), ends, 0.025)
    # consecutive samples of one ray are at most one step apart and the last is before the end
    d = np.hypot(*np.diff(pts, axis=0).T)[np.diff(ray) == 0]
    assert d.max() <= 0.025 + 1e-9
    assert np.all(np.bincount(ray) >= 1)
