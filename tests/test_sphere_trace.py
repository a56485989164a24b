"""The beam model's sphere tracer against the exact column walk (``nav.raycast``, itself checked
against a brute-force ray/box test in tests/test_sim_raycast.py) on seeded grids."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from nav.localization.sphere_trace import BLOCKED, ClearanceTracer, trace_fan, trace_ray
from nav.raycast import RayCaster
from nav.types import GridGeometry, Pose2D


def _random_mask(seed: int) -> tuple[np.ndarray, GridGeometry]:
    """Rooms of random boxes, scattered single cells and one-cell diagonal walls (which a march
    by the plain distance field leaks through) on a non-square grid, rotated origin for odd
    seeds (the tracer works in grid-local cells, like the column walk)."""
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(40, 140)), int(rng.integers(40, 140))
    occ = rng.random((h, w)) < rng.uniform(0.0, 0.03)
    occ[[0, -1], :] |= rng.random() < 0.5
    for _ in range(int(rng.integers(0, 12))):
        r, c = rng.integers(0, h), rng.integers(0, w)
        occ[r : r + rng.integers(1, 20), c : c + rng.integers(1, 4)] = True
    for _ in range(int(rng.integers(1, 5))):  # one-cell diagonal walls: cells touching at corners
        r, c, n = rng.integers(0, h), rng.integers(0, w), int(rng.integers(5, 40))
        step = 1 if rng.random() < 0.5 else -1
        rr, cc = r + np.arange(n), c + step * np.arange(n)
        keep = (rr < h) & (cc >= 0) & (cc < w)
        occ[rr[keep], cc[keep]] = True
    theta = 0.0 if seed % 2 == 0 else 0.4
    return occ, GridGeometry(0.05, w, h, Pose2D(-1.0, 2.0, theta))


def _trace_all(tracer: ClearanceTracer, xy: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
    clear, stride, w, h = tracer.tables
    g = tracer.geometry
    local = tracer.to_local(xy)
    a = angles - g.origin.theta
    t_max = max_range / g.resolution
    out = np.array(
        [
            trace_ray(clear, stride, w, h, u, v, np.cos(ai), np.sin(ai), t_max)
            for (u, v), ai in zip(local, a, strict=True)
        ]
    )
    return out * g.resolution


@pytest.mark.parametrize("seed", range(12))
def test_trace_equals_exact_column_walk(seed: int) -> None:
    """Origins anywhere (in walls, off the grid on every side), any direction including the axes
    and diagonals, ranges short and past the grid: the same first occupied cell and distance."""
    occ, geo = _random_mask(seed)
    rng = np.random.default_rng(100 + seed)
    n = 3000
    local = rng.uniform(-0.3, 1.3, size=(n, 2)) * np.array(geo.size_m)
    xy = geo.origin.transform_points(local)
    angles = rng.uniform(-np.pi, np.pi, n)
    angles[::7] = rng.integers(-4, 5, angles[::7].size) * (np.pi / 4)  # axis-aligned, diagonal
    max_range = float(rng.uniform(0.5, 1.5)) * max(geo.size_m)
    want = RayCaster(occ, geo).cast(xy, angles[:, None], max_range)[:, 0]
    got = _trace_all(ClearanceTracer(occ, geo), xy, angles, max_range)
    assert np.array_equal(np.isinf(got), np.isinf(want))
    hit = np.isfinite(want)
    assert hit.sum() > n // 10  # the seeds exercise hits, not only misses
    np.testing.assert_allclose(got[hit], want[hit], rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_fan_equals_single_rays(seed: int) -> None:
    """``trace_fan`` (rays of one origin, jumps interleaved) gives every ray ``trace_ray``'s
    result exactly, with its work arrays reused across origins (in walls, off the grid)."""
    occ, geo = _random_mask(seed)
    clear, stride, w, h = ClearanceTracer(occ, geo).tables
    rng = np.random.default_rng(200 + seed)
    b = 61
    work = [np.empty(b) for _ in range(3)]
    active = np.empty(b, dtype=np.int64)
    for _ in range(200):
        u0, v0 = rng.uniform(-0.3, 1.3) * w, rng.uniform(-0.3, 1.3) * h
        a = rng.uniform(-np.pi, np.pi) + np.linspace(-np.pi, np.pi, b)
        a[::10] = rng.integers(-4, 5, a[::10].size) * (np.pi / 4)
        du, dv = np.cos(a), np.sin(a)
        t_max = float(rng.uniform(5.0, 1.5 * max(w, h)))
        t, t_hi, out = work
        trace_fan(clear, stride, w, h, u0, v0, du, dv, t_max, t, t_hi, active, out)
        want = [trace_ray(clear, stride, w, h, u0, v0, x, y, t_max) for x, y in zip(du, dv, strict=True)]
        np.testing.assert_array_equal(out, want)


def test_trace_on_empty_and_full_grids() -> None:
    geo = GridGeometry(0.1, 30, 20, Pose2D(0.0, 0.0, 0.0))
    empty = ClearanceTracer(np.zeros((20, 30), dtype=bool), geo)
    assert np.isinf(_trace_all(empty, np.array([[1.0, 1.0], [-1.0, 1.0]]), np.array([0.3, 0.0]), 10.0)).all()
    full = ClearanceTracer(np.ones((20, 30), dtype=bool), geo)
    # from inside: 0; from off the grid: the distance to the grid's edge
    got = _trace_all(full, np.array([[1.0, 1.0], [-1.0, 1.0], [1.0, 1.0]]), np.array([0.3, 0.0, np.pi]), 10.0)
    np.testing.assert_allclose(got, [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_clearance_table_is_a_lower_bound(seed: int) -> None:
    """No jump can pass an occupied cell: every table value is at most the distance from any point
    of its cell to any point of an occupied cell (centre distance minus a cell diagonal), after
    float32 rounding too; occupied cells read BLOCKED; the bound is not capped."""
    occ, geo = _random_mask(seed)
    tracer = ClearanceTracer(occ, geo)
    clear, stride, w, h = tracer.tables
    table = clear.reshape(h + 2, stride)
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = occ
    assert np.all(table[pad] == BLOCKED)
    free = ~pad
    exact = distance_transform_edt(~pad)[free] - np.sqrt(2.0)
    assert np.all(table[free].astype(np.float64) < np.maximum(exact, 1e-6))
    assert np.all(table[free] >= 0.0)
    assert table.max() >= exact.max() - 1e-3  # uncapped


def test_non_finite_rays_read_no_return() -> None:
    """A NaN or infinite origin (a corrupted particle) gives no return, without indexing the
    table with it."""
    occ, geo = _random_mask(0)
    clear, stride, w, h = ClearanceTracer(occ, geo).tables
    for u0, v0, du in ((np.nan, 5.0, 1.0), (5.0, np.inf, 1.0), (5.0, 5.0, np.nan)):
        assert trace_ray(clear, stride, w, h, u0, v0, du, 0.0, 50.0) == np.inf


def test_mask_shape_must_match() -> None:
    with pytest.raises(ValueError, match="mask shape"):
        ClearanceTracer(np.zeros((3, 4), dtype=bool), GridGeometry(0.1, 3, 4, Pose2D()))
