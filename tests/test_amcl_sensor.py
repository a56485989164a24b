"""Laser models on hand-computable cases (Thrun Tables 6.1 and 6.3, Nav2 combination rules)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.localization import Amcl
from nav.localization import sensor_models as sm
from nav.localization.options import AmclOptions
from nav.localization.sphere_trace import ClearanceTracer
from nav.raycast import cast_rays
from nav.types import GridGeometry, LaserScan, OccupancyGrid, Pose2D

RES = 0.1


def wall_grid() -> OccupancyGrid:
    """2 x 2 m, 0.1 m cells, a wall filling column 10 (x in [1.0, 1.1))."""
    data = np.zeros((20, 20), dtype=np.int8)
    data[:, 10] = 100
    return OccupancyGrid(GridGeometry(RES, 20, 20, Pose2D(0.0, 0.0, 0.0)), data)


OPTS = AmclOptions()  # z_hit 0.5, z_rand 0.5, sigma_hit 0.2
RMAX = 4.0


def pz(d: float) -> float:
    return OPTS.z_hit * math.exp(-d * d / (2 * OPTS.sigma_hit**2)) + OPTS.z_rand / RMAX


def test_distance_field_cell_values() -> None:
    f = sm.LikelihoodField(wall_grid(), max_dist=2.0, sigma_hit=0.2)
    pts = np.array([[1.05, 0.55], [0.85, 0.55], [0.55, 0.55], [1.45, 1.95]])
    np.testing.assert_allclose(f.distance_at(pts[:, 0], pts[:, 1]), [0.0, 0.2, 0.5, 0.4], atol=1e-12)
    # Off the map reads max_dist (Nav2), and the cap applies.
    capped = sm.LikelihoodField(wall_grid(), max_dist=0.3, sigma_hit=0.2)
    assert capped.distance_at(np.array([0.05]), np.array([0.05]))[0] == pytest.approx(0.3)
    assert f.distance_at(np.array([-5.0]), np.array([0.5]))[0] == pytest.approx(2.0)


def _beams(ranges: list[float]) -> sm.Beams:
    return sm.Beams(np.array(ranges, dtype=float), np.zeros(len(ranges)), RMAX)


def test_likelihood_field_values_by_hand() -> None:
    f = sm.LikelihoodField(wall_grid(), 2.0, OPTS.sigma_hit)
    particle = np.array([[0.55, 1.05, 0.0]])
    # Endpoints at x = 1.05 (on the wall, d = 0) and x = 0.85 (d = 0.2); the max-range beam is ignored.
    beams = _beams([0.5, 0.3, RMAX])
    logp = sm.likelihood_field_weights(f, particle, Pose2D(), beams, OPTS)
    assert logp[0] == pytest.approx(math.log(1.0 + pz(0.0) ** 3 + pz(0.2) ** 3))
    logp_prob = sm.likelihood_field_prob_weights(f, particle, Pose2D(), beams, OPTS)
    assert logp_prob[0] == pytest.approx(math.log(pz(0.0)) + math.log(pz(0.2)))


def test_laser_pose_is_applied() -> None:
    """A laser mounted 0.2 m ahead and turned +90 deg on a robot facing -y looks along +x."""
    f = sm.LikelihoodField(wall_grid(), 2.0, OPTS.sigma_hit)
    particle = np.array([[0.55, 1.25, -math.pi / 2]])
    laser = Pose2D(0.2, 0.0, math.pi / 2)  # laser at (0.55, 1.05) in the map, heading +x
    ex, ey = sm.beam_endpoints(particle, laser, _beams([0.5]))
    np.testing.assert_allclose([ex[0, 0], ey[0, 0]], [1.05, 1.05], atol=1e-12)
    logp = sm.likelihood_field_prob_weights(f, particle, laser, _beams([0.5]), OPTS)
    assert logp[0] == pytest.approx(math.log(pz(0.0)))


def test_better_pose_scores_higher() -> None:
    f = sm.LikelihoodField(wall_grid(), 2.0, OPTS.sigma_hit)
    particles = np.array([[0.55, 1.05, 0.0], [0.35, 1.05, 0.0], [0.55, 1.05, 0.6]])
    b = sm.Beams(np.array([0.5, 0.5 / math.cos(0.3)]), np.array([0.0, 0.3]), RMAX)
    for fn in (sm.likelihood_field_weights, sm.likelihood_field_prob_weights):
        w = fn(f, particles, Pose2D(), b, OPTS)
        assert w[0] > w[1] and w[0] > w[2]


def test_beam_model_by_hand() -> None:
    grid = wall_grid()
    particle = np.array([[0.55, 1.05, 0.0]])  # expected range along +x: 1.0 - 0.55 = 0.45
    o = AmclOptions(laser_model_type="beam")
    occ = grid.occupied_mask()

    def one(r: float) -> float:
        return float(sm.beam_model_weights(occ, grid, cast_rays, particle, Pose2D(), _beams([r]), o)[0])

    hit = o.z_hit + o.z_rand / RMAX
    assert one(0.45) == pytest.approx(math.log1p(hit**3))
    z = 0.30 - 0.45
    short = o.z_hit * math.exp(-z * z / (2 * o.sigma_hit**2)) + o.z_short * o.lambda_short * math.exp(
        -o.lambda_short * 0.30
    )
    assert one(0.30) == pytest.approx(math.log1p((short + o.z_rand / RMAX) ** 3))
    z = RMAX - 0.45
    mx = o.z_hit * math.exp(-z * z / (2 * o.sigma_hit**2)) + o.z_max
    assert one(RMAX) == pytest.approx(math.log1p(mx**3))


def test_beam_model_prefers_true_pose() -> None:
    grid = wall_grid()
    occ = grid.occupied_mask()
    truth = np.array([0.55, 1.05, 0.2])
    bearings = np.linspace(-0.6, 0.6, 9)
    expected = cast_rays(occ, grid.geometry, truth[None, :2], truth[2] + bearings, RMAX)[0]
    beams = sm.Beams(np.where(np.isfinite(expected), expected, RMAX), bearings, RMAX)
    particles = truth + np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.3]])
    w = sm.beam_model_weights(occ, grid, cast_rays, particles, Pose2D(), beams, AmclOptions())
    assert np.argmax(w) == 0


def test_select_beams_nav2_rules() -> None:
    ranges = np.linspace(0.1, 3.0, 360)
    ranges[[6, 12]] = [np.inf, np.nan]
    scan = LaserScan(0.0, -math.pi, 2 * math.pi / 360, ranges, range_min=0.15, range_max=6.0)
    b = sm.select_beams(scan, AmclOptions(laser_max_beams=60, laser_max_range=2.5))
    # step = (360 - 1) // 59 = 6: beams 0, 6, ..., 354, minus the NaN at index 12.
    assert b.ranges.shape == (59,)
    assert b.range_max == 2.5
    assert b.ranges[0] == 2.5  # 0.1 m is below range_min -> treated as max range
    assert b.ranges[1] == 2.5  # no return
    assert b.bearings[2] == pytest.approx(-math.pi + 18 * 2 * math.pi / 360)
    assert np.all(b.ranges <= 2.5)
    assert np.count_nonzero(b.hit) == np.count_nonzero((ranges[::6] > 0.15) & (ranges[::6] < 2.5))


def test_beam_skip_drops_unexplained_beams() -> None:
    """Two beams fit the wall for every particle; one hits an unmapped object 0.4 m short of it.
    With beam skipping the outlier is ignored, so the score equals the two-beam score."""
    f = sm.LikelihoodField(wall_grid(), 2.0, OPTS.sigma_hit)
    particles = np.array([[0.55, 1.05, 0.0], [0.56, 1.04, 0.0], [0.54, 1.06, 0.01]])
    b3 = sm.Beams(np.array([0.5, 0.5, 0.1]), np.zeros(3), RMAX)  # third endpoint 0.4 m from the wall
    skip = AmclOptions(
        do_beamskip=True, beam_skip_distance=0.3, beam_skip_threshold=0.5, beam_skip_error_threshold=0.5
    )
    full = sm.likelihood_field_prob_weights(f, particles, Pose2D(), b3, AmclOptions())
    skipped = sm.likelihood_field_prob_weights(f, particles, Pose2D(), b3, skip)
    two = sm.likelihood_field_prob_weights(
        f, particles, Pose2D(), sm.Beams(b3.ranges[:2], b3.bearings[:2], RMAX), AmclOptions()
    )
    np.testing.assert_allclose(skipped, two)
    assert np.all(full < skipped)
    # If most beams would be skipped the filter is lost: all beams are used again.
    lost = AmclOptions(
        do_beamskip=True, beam_skip_distance=0.3, beam_skip_threshold=0.5, beam_skip_error_threshold=0.9
    )
    np.testing.assert_allclose(sm.likelihood_field_prob_weights(f, particles, Pose2D(), b3, lost), full)


def test_scan_fit_bounds() -> None:
    f = sm.LikelihoodField(wall_grid(), 2.0, 0.2)
    assert sm.scan_fit(f, Pose2D(0.55, 1.05, 0.0), Pose2D(), _beams([0.5, 0.5])) == pytest.approx(1.0)
    assert sm.scan_fit(f, Pose2D(0.15, 1.05, 0.0), Pose2D(), _beams([0.5])) == pytest.approx(
        math.exp(-(0.4**2) / (2 * 0.2**2))
    )
    assert sm.scan_fit(f, Pose2D(), Pose2D(), _beams([RMAX])) == 0.0


def _rooms_grid(seed: int) -> OccupancyGrid:
    """A seeded 12 x 9 m map (0.05 m cells): outer walls, random boxes and unknown patches, on a
    rotated origin for odd seeds."""
    rng = np.random.default_rng(seed)
    h, w = 180, 240
    data = np.zeros((h, w), dtype=np.int8)
    data[[0, -1], :] = data[:, [0, -1]] = 100
    for _ in range(14):
        r, c = rng.integers(5, h - 20), rng.integers(5, w - 20)
        data[r : r + rng.integers(1, 15), c : c + rng.integers(1, 15)] = 100
    for _ in range(4):
        r, c = rng.integers(5, h - 20), rng.integers(5, w - 20)
        data[r : r + 10, c : c + 10] = -1
    theta = 0.0 if seed % 2 == 0 else 0.3
    return OccupancyGrid(GridGeometry(0.05, w, h, Pose2D(-2.0, 1.0, theta)), data)


@pytest.mark.parametrize("seed", range(4))
def test_compiled_beam_model_equals_reference(seed: int) -> None:
    """The compiled beam update (one pass casting and scoring every beam, sphere tracing across
    open space) gives the numpy reference's log weights: particles anywhere, including in walls
    and off the map, readings with and without returns, a laser mounted off-centre."""
    grid = _rooms_grid(seed)
    rng = np.random.default_rng(seed)
    geo = grid.geometry
    local = rng.uniform(-0.1, 1.1, size=(500, 2)) * np.array(geo.size_m)
    xy = geo.origin.transform_points(local)
    particles = np.column_stack((xy, rng.uniform(-np.pi, np.pi, 500)))
    rmax = 5.0
    ranges = rng.uniform(0.1, rmax, 40)
    ranges[rng.random(40) < 0.2] = rmax  # no returns
    beams = sm.Beams(ranges, np.linspace(-np.pi, np.pi, 40, endpoint=False), rmax)
    laser = Pose2D(0.1, -0.05, 0.1)
    o = AmclOptions(laser_model_type="beam")
    occ = grid.occupied_mask()
    want = sm.beam_model_weights(occ, grid, cast_rays, particles, laser, beams, o)
    got = sm.beam_model_weights_compiled(ClearanceTracer(occ, geo), particles, laser, beams, o)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_amcl_beam_model_default_is_the_compiled_pass() -> None:
    """Amcl's default beam model (compiled, on a clearance table built once per map, not capped
    at the likelihood field's max distance) weighs poses like the reference with ``cast_rays``."""
    grid = _rooms_grid(1)
    o = AmclOptions(laser_model_type="beam", laser_likelihood_max_dist=0.5)
    fast, ref = Amcl(o, grid, seed=0), Amcl(o, grid, seed=0, cast_rays=cast_rays)
    assert fast._caster is not None and ref._caster is None
    clear = fast._caster.tables[0]
    assert clear.max() * grid.geometry.resolution > 2.0 * o.laser_likelihood_max_dist
    rng = np.random.default_rng(3)
    poses = np.column_stack(
        (rng.uniform(-1.0, 9.0, 300), rng.uniform(1.0, 9.0, 300), rng.uniform(-3, 3, 300))
    )
    ranges = rng.uniform(0.2, 6.0, 360)
    scan = LaserScan(0.0, -math.pi, 2 * math.pi / 360, ranges, 0.15, 6.0)
    np.testing.assert_allclose(
        fast.log_likelihood(poses, scan, Pose2D(0.05, 0.0, 0.0)),
        ref.log_likelihood(poses, scan, Pose2D(0.05, 0.0, 0.0)),
        rtol=1e-12,
        atol=1e-12,
    )
