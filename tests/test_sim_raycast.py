"""Ray casting against brute-force ray/box intersection on random grids."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.raycast import RayCaster, bresenham_cells, cast_rays, traversed_cells
from nav.types import GridGeometry, Pose2D


def brute_force(
    occ: np.ndarray, g: GridGeometry, origin: np.ndarray, angles: np.ndarray, max_range: float
) -> np.ndarray:
    """Entry distance into every occupied cell (slab test in the grid frame), minimum per ray."""
    rows, cols = np.nonzero(occ)
    res = g.resolution
    local = g.origin.inverse().transform_points(origin.reshape(1, 2))[0]
    x0, y0 = cols * res, rows * res
    x1, y1 = x0 + res, y0 + res
    out = []
    for a in angles - g.origin.theta:
        dx, dy = math.cos(a), math.sin(a)
        lo, hi = np.full(rows.shape, -np.inf), np.full(rows.shape, np.inf)
        for o, d, b0, b1 in ((local[0], dx, x0, x1), (local[1], dy, y0, y1)):
            if abs(d) < 1e-15:
                inside = (o >= b0) & (o < b1)
                lo = np.where(inside, lo, np.inf)
            else:
                ta, tb = (b0 - o) / d, (b1 - o) / d
                lo, hi = np.maximum(lo, np.minimum(ta, tb)), np.minimum(hi, np.maximum(ta, tb))
        ok = (hi > np.maximum(lo, 0.0)) | ((lo <= 0) & (hi > 0))
        t = np.maximum(lo, 0.0)[ok]
        d_min = t.min() if t.size else np.inf
        out.append(d_min if d_min <= max_range else np.inf)
    return np.array(out)


@pytest.mark.parametrize("clearance", [False, True])
@pytest.mark.parametrize("seed", range(12))
def test_matches_brute_force_on_random_grids(seed: int, clearance: bool) -> None:
    rng = np.random.default_rng(seed)
    h, w = rng.integers(10, 60, size=2)
    occ = rng.random((h, w)) < rng.uniform(0.002, 0.15)  # sparse grids give long free runs
    theta = 0.0 if seed % 3 else float(rng.uniform(-np.pi, np.pi))
    g = GridGeometry(float(rng.choice([0.05, 0.1, 0.25])), int(w), int(h), Pose2D(-1.3, 0.7, theta))
    # origins inside and outside the grid
    origins = g.origin.transform_points(rng.uniform(-0.2, 1.2, size=(3, 2)) * np.array(g.size_m))
    angles = rng.uniform(-np.pi, np.pi, size=(3, 80))
    max_range = float(rng.uniform(0.5, 1.5) * max(g.size_m))
    got = RayCaster(occ, g, clearance=clearance).cast(origins, angles, max_range)
    assert got.shape == (3, 80)
    for i in range(3):
        want = brute_force(occ, g, origins[i], angles[i], max_range)
        np.testing.assert_allclose(got[i], want, rtol=0, atol=1e-9)


def test_axis_aligned_and_diagonal_rays_in_a_box() -> None:
    occ = np.zeros((20, 20), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    g = GridGeometry(0.1, 20, 20)
    angles = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, np.pi / 4])
    d = cast_rays(occ, g, np.array([1.0, 1.0]), angles, 5.0)[0]
    np.testing.assert_allclose(d[:4], [0.9, 0.9, 0.9, 0.9], atol=1e-12)
    assert d[4] == pytest.approx(0.9 * math.sqrt(2), abs=1e-12)


def test_max_range_off_grid_and_inside_obstacle() -> None:
    occ = np.zeros((10, 10), dtype=bool)
    occ[5, 5] = True
    g = GridGeometry(1.0, 10, 10)
    assert np.isinf(cast_rays(occ, g, np.array([0.5, 5.5]), np.array([0.0]), 4.0)[0, 0])
    assert cast_rays(occ, g, np.array([0.5, 5.5]), np.array([0.0]), 5.0)[0, 0] == pytest.approx(4.5)
    assert cast_rays(occ, g, np.array([5.5, 5.5]), np.array([1.0]), 5.0)[0, 0] == 0.0
    # from far outside the grid the ray enters it and hits the cell
    assert cast_rays(occ, g, np.array([-20.5, 5.5]), np.array([0.0]), 50.0)[0, 0] == pytest.approx(25.5)
    # leaving the grid: nothing beyond counts
    assert np.isinf(cast_rays(occ, g, np.array([0.5, 0.5]), np.array([np.pi]), 50.0)[0, 0])


def test_raycaster_reuse_matches_function_and_any_occupied() -> None:
    rng = np.random.default_rng(3)
    occ = rng.random((30, 40)) < 0.05
    g = GridGeometry(0.05, 40, 30, Pose2D(1.0, -2.0, 0.0))
    rc = RayCaster(occ, g)
    origins = np.array([[1.5, -1.5], [2.2, -0.9]])
    angles = rng.uniform(-np.pi, np.pi, (2, 50))
    np.testing.assert_array_equal(rc.cast(origins, angles, 3.0), cast_rays(occ, g, origins, angles, 3.0))
    with_edt = RayCaster(occ, g, clearance=True).cast(origins, angles, 3.0)
    np.testing.assert_allclose(with_edt, rc.cast(origins, angles, 3.0), rtol=0, atol=1e-12)
    r, c = np.nonzero(occ)
    centre = g.cell_to_world(r[:1], c[:1])
    assert rc.any_occupied(centre)
    free_r, free_c = np.nonzero(~occ)
    assert not rc.any_occupied(g.cell_to_world(free_r[:5], free_c[:5]))
    assert not rc.any_occupied(np.array([[100.0, 100.0]]))
    # the pose form agrees with transforming the points first, on a rotated grid too
    rot = RayCaster(occ, GridGeometry(0.05, 40, 30, Pose2D(1.0, -2.0, 0.4)))
    body = rng.uniform(-0.1, 0.1, size=(4, 2))
    seen = set()
    for _ in range(200):
        pose = Pose2D(*rng.uniform([0.5, -2.5, -np.pi], [3.0, 0.5, np.pi]))
        want = bool(rot.occupied_at(pose.transform_points(body)).any())
        assert rot.any_occupied_at_pose(body, pose.x, pose.y, pose.theta) == want
        seen.add(want)
    assert seen == {True, False}


def bresenham_reference(r0: int, c0: int, r1: int, c1: int) -> list[tuple[int, int]]:
    dr, dc = r1 - r0, c1 - c0
    n = max(abs(dr), abs(dc))
    cells = []
    for i in range(n + 1):
        # round half away from zero of i * d / n, in exact integer arithmetic
        fr = (2 * i * abs(dr) + n) // (2 * n) if n else 0
        fc = (2 * i * abs(dc) + n) // (2 * n) if n else 0
        cells.append((r0 + int(np.sign(dr)) * fr, c0 + int(np.sign(dc)) * fc))
    return cells


def test_bresenham_many_segments() -> None:
    rng = np.random.default_rng(5)
    s = rng.integers(-20, 20, size=(50, 2))
    e = rng.integers(-20, 20, size=(50, 2))
    e[0] = s[0]  # zero-length segment
    rows, cols, seg = bresenham_cells(s, e)
    for i in range(50):
        got = list(zip(rows[seg == i].tolist(), cols[seg == i].tolist(), strict=True))
        ref = bresenham_reference(*s[i], *e[i])
        assert got == ref
        # 8-connected and ends where asked
        assert got[0] == tuple(s[i]) and got[-1] == tuple(e[i])
        steps = np.abs(np.diff(np.array(got), axis=0))
        assert steps.size == 0 or steps.max() <= 1
    rows2, _, _ = bresenham_cells(s, e, include_end=False)
    assert len(rows2) == len(rows) - 50


def test_traversed_cells_match_supercover_reference() -> None:
    rng = np.random.default_rng(9)
    g = GridGeometry(0.1, 30, 20, Pose2D(-0.5, 0.25, 0.0))
    starts = rng.uniform([-0.5, 0.25], [2.5, 2.25], size=(40, 2))
    ends = rng.uniform([-1.0, 0.0], [3.0, 2.5], size=(40, 2))
    rows, cols, seg = traversed_cells(g, starts, ends, include_end=True)
    for i in range(40):
        got = set(zip(rows[seg == i].tolist(), cols[seg == i].tolist(), strict=True))
        # reference: dense sampling along the segment (cells touched for a positive length)
        t = np.linspace(0, 1, 20001)[:, None]
        pts = starts[i] + t * (ends[i] - starts[i])
        r, c = g.world_to_cell(pts)
        inside = g.in_bounds(r, c)
        ref = set(zip(r[inside].tolist(), c[inside].tolist(), strict=True))
        assert ref <= got
        assert len(got - ref) <= 1  # at most a corner-grazing cell the sampling missed
    r2, c2, s2 = traversed_cells(g, starts, ends, include_end=False)
    end_r, end_c = g.world_to_cell(ends)
    assert not np.any((r2 == end_r[s2]) & (c2 == end_c[s2]))


def test_traversed_cells_axis_parallel_zero_length_and_unique() -> None:
    g = GridGeometry(1.0, 10, 10)
    starts = np.array([[0.5, 2.5], [3.5, 0.5], [4.2, 4.2], [0.5, 0.5]])
    ends = np.array([[5.5, 2.5], [3.5, 4.5], [4.2, 4.2], [9.7, 8.1]])
    rows, cols, seg = traversed_cells(g, starts, ends)
    assert sorted(cols[seg == 0].tolist()) == [0, 1, 2, 3, 4] and set(rows[seg == 0].tolist()) == {2}
    assert sorted(rows[seg == 1].tolist()) == [0, 1, 2, 3] and set(cols[seg == 1].tolist()) == {3}
    assert not np.any(seg == 2)  # zero length: nothing before the end cell
    key = seg * 100 + rows * 10 + cols
    assert np.unique(key).size == key.size
    _, _, seg_end = traversed_cells(g, starts, ends, include_end=True)
    assert np.count_nonzero(seg_end == 2) == 1
