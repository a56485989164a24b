"""The scan matcher's compiled kernels (nav/slam/kernels.py) give what their numpy references give."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_worlds import box_world_grid, plateau_field

from bench import peers
from nav.grid import VIEW_CLEARED, VIEW_HIT, VIEW_UNSURE, LogOddsGrid, LogOddsOptions
from nav.slam import kernels
from nav.slam.beam_search import best_candidate, keep_best, keep_best_reference, score_children
from nav.slam.field import LikelihoodField, _halved_window_kernels, _window_kernel, field_reference, halve_max
from nav.slam.matcher import (
    RefineOptions,
    SearchWindow,
    correlative_search,
    correlative_search_reference,
    correlative_search_runner_up,
    match_scan,
    match_scan_with_fallback,
    refine_pose,
    refine_pose_reference,
    score_candidates_reference,
    surface_lines,
    surface_lines_reference,
    translation_information,
    translation_information_reference,
    window_moments_reference,
)
from nav.slam.scan_to_scan import ScanToScanMatcher
from nav.slam.synthetic import box_world, cast_scan
from nav.slam.system import grazing_shortening
from nav.types import Pose2D


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_field_equals_the_shifted_maxima_reference(seed: int) -> None:
    g, _ = box_world_grid(seed)
    field = LikelihoodField.from_grid(g, sigma=0.05)
    assert np.array_equal(field.field, field_reference(g.logodds > 0, 0.05, g.resolution))
    # incremental splat of new cells equals a rebuild with them occupied
    rng = np.random.default_rng(seed)
    new = rng.choice(g.logodds.size, 40, replace=False)
    field.splat(new)
    occ = (g.logodds > 0).reshape(-1).copy()
    occ[new] = True
    assert np.array_equal(field.field, field_reference(occ.reshape(g.shape), 0.05, g.resolution))


def test_field_from_points_marks_the_cells_hit() -> None:
    pts = np.array([[0.0, 0.0], [1.02, -0.51], [2.5, 3.0]])
    field = LikelihoodField.from_points(pts, 0.05, sigma=0.05, margin=0.3)
    cells = np.floor((pts - field.origin) / 0.05).astype(int)
    occ = np.zeros(field.field.shape, dtype=bool)
    occ[cells[:, 1], cells[:, 0]] = True
    assert np.array_equal(field.field, field_reference(occ, 0.05, 0.05))
    assert field.field[cells[:, 1], cells[:, 0]].min() == 1.0
    with pytest.raises(ValueError):
        LikelihoodField.from_points(np.zeros((0, 2)), 0.05)


@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_field_from_points_equals_the_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-6, 9, (180, 2))
    pts[:30] = np.round(pts[:30] / 0.05) * 0.05  # on cell borders
    fast = LikelihoodField.from_points(pts, 0.05, sigma=0.05, margin=0.5)
    ref = LikelihoodField.from_points_reference(pts, 0.05, sigma=0.05, margin=0.5)
    assert np.array_equal(fast.origin, ref.origin)
    assert fast.field.dtype == ref.field.dtype and np.array_equal(fast.field, ref.field)


def test_pairwise_float32_sum_is_numpys_sum_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    for n in [*range(0, 140), 255, 256, 257, 1000]:
        v = (rng.random(n) * rng.choice([1e-3, 1.0, 1e3], n)).astype(np.float32)
        assert kernels.pairwise_sum32(v, 0, n) == v.sum() == np.stack((v, v)).sum(axis=1)[0]


@pytest.mark.parametrize(("level", "n"), [(0, 150), (1, 100), (2, 100), (0, 5)])
def test_compiled_candidate_scores_equal_the_reference(level: int, n: int) -> None:
    g, _ = box_world_grid(3)
    field = LikelihoodField.from_grid(g, levels=2)
    rng = np.random.default_rng(level)
    # points partly off the grid too (those count 0 on both sides)
    rows0 = rng.integers(-5, g.shape[0] + 5, (21, n))
    cols0 = rng.integers(-5, g.shape[1] + 5, (21, n))
    cand = np.column_stack((rng.integers(0, 21, 500), rng.integers(-6, 7, 500), rng.integers(-6, 7, 500)))
    step = 1 << level
    fast = kernels.score_candidates(field.pooled[level], rows0, cols0, cand, step)
    ref = score_candidates_reference(field, level, rows0, cols0, cand, step)
    # bit for bit: both sum the float32 field in float32 in numpy's pairwise order, so equal
    # scores (ties) stay equal and the search picks the same candidate
    assert fast.dtype == ref.dtype == np.float32
    assert np.array_equal(fast, ref)
    assert fast.max() > 0.0


@pytest.mark.parametrize(
    ("offset", "weights"),
    [((0.06, -0.04, 0.05), (3.0, 10.0)), ((-0.03, 0.05, -0.03), (10.0, 40.0)), ((0.2, 0.1, 0.1), (0.5, 2.0))],
)
def test_compiled_refinement_equals_the_reference(offset: tuple[float, float, float], weights: tuple) -> None:
    g, pts = box_world_grid(4)
    field = LikelihoodField.from_grid(g)
    opts = RefineOptions(translation_weight=weights[0], rotation_weight=weights[1])
    start = Pose2D(*offset)
    prior = Pose2D(offset[0] * 0.5, offset[1] * 0.5, offset[2] * 0.5)
    fast, fast_score = refine_pose(field, pts, start, prior, opts)
    ref, ref_score = refine_pose_reference(field, pts, start, prior, opts)
    assert abs(fast.x - ref.x) < 1e-9 and abs(fast.y - ref.y) < 1e-9 and abs(fast.theta - ref.theta) < 1e-9
    assert abs(fast_score - ref_score) < 1e-9


def test_search_with_the_compiled_scores_finds_the_true_pose() -> None:
    g, pts = box_world_grid(5)
    field = LikelihoodField.from_grid(g, levels=2)
    for levels, top_level_points in ((0, None), (2, None), (2, 25)):
        window = SearchWindow(
            0.3, math.radians(15), math.radians(0.5), levels=levels, top_level_points=top_level_points
        )
        pose, score = correlative_search(field, pts, Pose2D(0.17, -0.12, math.radians(6)), window)
        assert math.hypot(pose.x, pose.y) < 0.05 and abs(pose.theta) < math.radians(1.0), pose
        assert score > 0.6


@pytest.mark.parametrize(
    ("seed", "margin", "view_margin"), [(0, 0.0, 0.0), (1, 0.0, 0.025), (2, 0.025, 0.0), (3, 0.025, 0.05)]
)
def test_compiled_ray_insertion_equals_the_reference(seed: int, margin: float, view_margin: float) -> None:
    # several scans from different poses, with returns and return-less rays (which stop at
    # occupied cells), into two grids: one per implementation; every result must be identical
    # (``margin``: the returns' rays are shortened where they grazed their surface; ``view_margin``:
    # the grids keep the view states, the rays' grazing stretches not counting as firm crossings)
    world, res = box_world()
    rng = np.random.default_rng(seed)
    track = view_margin > 0.0
    fast = LogOddsGrid(LogOddsOptions(resolution=0.05), track_view=track)
    ref = LogOddsGrid(LogOddsOptions(resolution=0.05), track_view=track)
    for k in range(6):
        pose = Pose2D(3.0 + 0.4 * k, 2.0 + 0.2 * k, 0.3 * k)
        pts = cast_scan(world, res, pose, 360, noise=0.01, rng=rng).points()
        angles = rng.uniform(-math.pi, math.pi, 40)
        misses = 5.0 * np.column_stack((np.cos(angles), np.sin(angles)))
        origin = np.array([[pose.x, pose.y]])
        ends = np.vstack((pose.transform_points(pts), pose.transform_points(misses)))
        hit = np.concatenate((np.ones(len(pts), bool), np.zeros(len(misses), bool)))
        shorten = np.concatenate((grazing_shortening(pts, margin), np.zeros(len(misses))))
        view_shorten = np.concatenate((grazing_shortening(pts, view_margin), np.zeros(len(misses))))
        a = fast.insert_rays(origin, ends, hit, shorten, view_shorten)
        b = ref.insert_rays_reference(origin, ends, hit, shorten, view_shorten)
        assert np.array_equal(a.became_occupied, b.became_occupied)
        assert a.became_free == b.became_free and a.resized == b.resized
        assert np.array_equal(a.miss_reach, b.miss_reach)
        assert np.array_equal(fast.logodds, ref.logodds) and np.array_equal(fast.seen, ref.seen)
        if track:
            assert np.array_equal(fast.view, ref.view)
    assert (a.miss_reach < 1.0).any()  # some return-less rays did stop at a wall
    if track:  # every state occurs: cells last hit, crossed far from a surface, crossed only grazing
        assert {VIEW_UNSURE, VIEW_CLEARED, VIEW_HIT} <= set(np.unique(fast.view[fast.seen]).tolist())
    else:
        assert fast.view is None


@pytest.mark.parametrize(("seed", "max_points"), [(0, 100), (1, 100), (2, 200), (3, 100), (4, 6)])
def test_compiled_exhaustive_search_equals_the_reference(seed: int, max_points: int) -> None:
    g, pts = box_world_grid(10 + seed)
    field = LikelihoodField.from_grid(g)
    rng = np.random.default_rng(seed)
    prior = Pose2D(*rng.uniform([-0.08, -0.08, -0.1], [0.08, 0.08, 0.1]))
    window = SearchWindow(0.1 + 0.05 * (seed % 4), math.radians(10), math.radians(0.5), max_points=max_points)
    for separation in (math.inf, 0.12):
        fast = correlative_search_runner_up(field, pts, prior, window, separation)
        ref = correlative_search_reference(field, pts, prior, window, separation)
        assert fast == ref  # pose, score and runner-up bit for bit
    assert fast[2] > 0.0  # some candidate lies beyond the separation


@pytest.mark.parametrize("level", [1, 2, 4])
def test_compiled_max_pooling_equals_the_reference(level: int) -> None:
    g, _ = box_world_grid(20)
    field = LikelihoodField.from_grid(g, levels=level)
    assert np.array_equal(field.pooled[level], field.pooled_reference(level))


@pytest.mark.parametrize(
    ("levels", "half_width", "max_points", "top_level_points"),
    [(2, 0.5, 100, None), (4, 1.5, 100, None), (3, 0.5, 200, None), (2, 0.5, 100, 25), (3, 0.5, 200, 7)],
)
def test_compiled_coarse_to_fine_search_equals_the_reference(
    levels: int, half_width: float, max_points: int, top_level_points: int | None
) -> None:
    g, pts = box_world_grid(30 + levels)
    field = LikelihoodField.from_grid(g, levels=levels)
    prior = Pose2D(0.3, -0.2, math.radians(8))
    window = SearchWindow(
        half_width, math.radians(20), math.radians(0.5), levels, 48, max_points, top_level_points
    )
    for separation in (0.5, math.inf):  # without a runner-up the last level is pruned by its parents
        fast = correlative_search_runner_up(field, pts, prior, window, separation)
        ref = correlative_search_reference(field, pts, prior, window, separation)
        assert fast == ref  # pose, score and runner-up bit for bit
        assert math.hypot(fast[0].x, fast[0].y) < 0.06


@pytest.mark.parametrize(("level", "wc", "n"), [(0, 10, 100), (1, 10, 37), (2, 40, 100), (3, 40, 200)])
def test_compiled_children_and_scores_equal_numpys(level: int, wc: int, n: int) -> None:
    # the beam's split of each kept candidate into its 4 children one level down and their scores:
    # matcher._correlative's numpy split, then the numpy scores; points past every edge
    rng = np.random.default_rng(level)
    size = 120
    field = LikelihoodField(rng.random((size, size)).astype(np.float32), np.zeros(2), 0.05, levels=level)
    rows0 = rng.integers(-8, size + 8, (81, n))
    cols0 = rng.integers(-8, size + 8, (81, n))
    step = 1 << level
    lo = -(wc // (2 * step)) - 2
    cand = np.column_stack(
        (rng.integers(0, 81, 300), rng.integers(lo, -lo, 300), rng.integers(lo, -lo, 300))
    ).astype(np.int64)
    kids = np.repeat(cand, 4, axis=0)
    kids[:, 1] = 2 * kids[:, 1] + np.tile([0, 0, 1, 1], len(cand))
    kids[:, 2] = 2 * kids[:, 2] + np.tile([0, 1, 0, 1], len(cand))
    lo_y, lo_x = kids[:, 1] * step, kids[:, 2] * step
    inside = (lo_y + step - 1 >= -wc) & (lo_y <= wc) & (lo_x + step - 1 >= -wc) & (lo_x <= wc)
    assert 0 < np.count_nonzero(inside) < len(kids)  # both kept and dropped children
    children, scores = score_children(field.pooled[level], rows0, cols0, cand, step, wc)
    np.testing.assert_array_equal(children, kids[inside])
    ref = score_candidates_reference(field, level, rows0, cols0, kids[inside], step)
    assert np.array_equal(scores, ref)  # bit for bit


@pytest.mark.parametrize(("n", "beam"), [(4356, 48), (192, 48), (48, 48), (30, 48), (1000, 1), (500, 64)])
def test_compiled_beam_keeps_the_best_ties_to_the_earlier(n: int, beam: int) -> None:
    rng = np.random.default_rng(n + beam)
    for values in (rng.random(n), rng.choice([0.25, 0.5, 0.75, 0.8], n), np.sort(rng.random(n))):
        score = values.astype(np.float32)  # ties at the beam's edge in the second
        assert np.array_equal(keep_best(score, beam), keep_best_reference(score, beam))
    score = np.full(n, 0.5, dtype=np.float32)  # all equal: the first ``beam``
    assert np.array_equal(keep_best(score, beam), np.arange(min(n, beam)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pooled_levels_of_a_points_field_are_splats_of_the_pooled_kernel(seed: int) -> None:
    # points_pooled / points_phase build a scan field's pooled levels and their phases from the
    # scan's cells, exactly what max-pooling the field and splitting it give
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-6, 6, (150, 2))
    pts[:30, 1] = 2.0  # a wall: overlapping splats
    field = LikelihoodField.from_points(pts, 0.05, sigma=0.05, levels=4)
    kernel = _window_kernel(0.05, 0.05, 0)
    rows, cols = kernels.points_cells(pts, float(field.origin[0]), float(field.origin[1]), 0.05)
    h, w = field.field.shape
    assert kernels.points_fit(rows, cols, kernel.shape[0] // 2, h, w)
    for level in range(1, 5):
        step = 1 << level
        assert np.array_equal(kernels.points_pooled(rows, cols, kernel, step, h, w), field.pooled[level])
        for pad in (0, 6):
            got = kernels.points_phase(rows, cols, kernel, step, h, w, pad)
            assert np.array_equal(got, field.phase(level, pad))
    assert not kernels.points_fit(rows, cols, 11, h, w)  # a kernel wider than the margin is clipped


def test_compiled_best_candidate_breaks_ties_as_numpys_lexsort() -> None:
    rng = np.random.default_rng(3)
    cand = np.column_stack(
        (rng.integers(0, 41, 400), rng.integers(-9, 10, 400), rng.integers(-9, 10, 400))
    ).astype(np.int64)
    scores = rng.choice(np.array([0.5, 0.75, 0.8], dtype=np.float32), 400)  # many equal scores
    a, dy, dx, best, runner_up = best_candidate(cand, scores, 20, 0.2, 0.05)
    dist = np.abs(cand[:, 1]) + np.abs(cand[:, 2]) + np.abs(cand[:, 0] - 20)
    k = np.lexsort((dist, -scores))[0]  # the numpy reference's pick
    assert (a, dy, dx, best) == (*cand[k], float(scores[k]))
    apart = np.hypot(cand[:, 1] - dy, cand[:, 2] - dx) * 0.05 > 0.2
    assert runner_up == float(scores[apart].max())
    assert best_candidate(cand, scores, 20, math.inf, 0.05)[4] == 0.0  # none apart


def test_compiled_rotated_cells_equal_numpys() -> None:
    rng = np.random.default_rng(7)
    pts = rng.uniform(-8, 8, (150, 2))
    pts[:20] = np.round(pts[:20] / 0.05) * 0.05  # on cell borders: the floor must go the same way
    thetas = 0.3 + math.radians(0.5) * np.arange(-40, 41)
    origin = np.array([-10.0, -9.95])
    rows, cols = kernels.rotated_cells(pts, np.cos(thetas), np.sin(thetas), 0.25, -0.1, *origin, 0.05)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    x, y = pts[None, :, 0], pts[None, :, 1]
    rot = np.stack((c * x - s * y, s * x + c * y), axis=-1) + np.array([0.25, -0.1])
    cell = np.floor((rot - origin) / 0.05).astype(np.int64)
    assert np.array_equal(rows, cell[..., 1]) and np.array_equal(cols, cell[..., 0])


@pytest.mark.parametrize(
    ("size", "n", "pad"), [(40, 100, 0), (600, 100, 0), (40, 100, 6), (600, 24, 6), (90, 37, 9), (90, 200, 6)]
)
def test_compiled_top_level_scores_equal_the_reference(size: int, n: int, pad: int) -> None:
    # a scan-sized and a submap-sized grid, both split into phases, unpadded and padded by the
    # block count or more; points past every edge and points far outside
    rng = np.random.default_rng(size + n)
    field = LikelihoodField(rng.random((size, size)).astype(np.float32), np.zeros(2), 0.05, levels=2)
    rows0 = rng.integers(-8, size + 8, (3, n))
    cols0 = rng.integers(-8, size + 8, (3, n))
    rows0[0, :5] = -100  # blocks that miss the grid
    cols0[1, 3:9] = size + 60
    fast = kernels.block_scores(field.phase(2, pad), rows0, cols0, -3, 6, 4, pad)
    a_idx, by, bx = np.meshgrid(np.arange(3), np.arange(-3, 3), np.arange(-3, 3), indexing="ij")
    cand = np.column_stack((a_idx.ravel(), by.ravel(), bx.ravel()))
    ref = score_candidates_reference(field, 2, rows0, cols0, cand, 4)
    assert np.array_equal(fast.ravel(), ref)


@pytest.mark.parametrize(("shape", "half"), [((37, 52), 1), ((40, 29), 2), ((25, 25), 3), ((3, 70), 5)])
def test_compiled_window_max_equals_the_reference(shape: tuple[int, int], half: int) -> None:
    rng = np.random.default_rng(half)
    grid = np.where(rng.random(shape) < 0.1, rng.random(shape), 0.0).astype(np.float32)
    field = LikelihoodField(grid, np.zeros(2), 0.05)
    fast = kernels.window_max(field.field, half)
    assert fast.shape == (shape[0] + 2 * half, shape[1] + 2 * half)
    assert np.array_equal(halve_max(fast), field.window_max_reference(half))
    assert np.array_equal(field.window_max(half), halve_max(fast))  # a field of an array: the exact pass


@pytest.mark.parametrize("half", [1, 2, 4])
def test_search_bounds_cover_the_window_max_as_the_field_grows(half: int) -> None:
    # both fields bound by the spread kernel splatted at their occupied cells: the true window
    # max wherever the kernels stay inside the grid, more only next to its edge; both are then
    # raised by splats at new cells and must stay at least the true window max
    rng = np.random.default_rng(half)
    pts = rng.uniform(-3, 4, (120, 2))
    g, _ = box_world_grid(40 + half)
    for field in (LikelihoodField.from_points(pts, 0.05), LikelihoodField.from_grid(g)):
        bound = field.window_max(half)
        exact = field.window_max_reference(half)
        assert (bound >= exact).all()
        # the kernel's radius (3 cells at sigma 0.05) plus the window, and more, in halved cells
        edge = half + 3
        assert np.array_equal(bound[edge:-edge, edge:-edge], exact[edge:-edge, edge:-edge])
        for _ in range(3):
            field.splat(rng.choice(field.field.size, 25, replace=False))
            assert field.window_max(half) is bound  # updated in place, not rebuilt
            assert (bound >= field.window_max_reference(half)).all()
        assert bound.max() == 1.0


@pytest.mark.parametrize("seed", range(8))
def test_angle_pruned_exhaustive_search_equals_the_reference(seed: int) -> None:
    # the bound-pruned search (no runner-up asked) against the numpy search over every candidate,
    # bit for bit: on noisy scans of the box world (random priors and windows) and on plateaus,
    # where exact ties between candidates (broken by the distance to the prior, then the order)
    # are the rule
    rng = np.random.default_rng(100 + seed)
    g, pts = box_world_grid(50 + seed)
    world = LikelihoodField.from_grid(g)
    plateau = plateau_field(seed)
    flat = LikelihoodField(np.full((80, 80), 0.5, dtype=np.float32), np.zeros(2), 0.05)
    grid_pts = np.round(rng.uniform(0.2, 2.8, (60, 2)) / 0.05) * 0.05 - 1.5
    cases = [
        (world, pts, Pose2D(*rng.uniform([-0.1, -0.1, -0.15], [0.1, 0.1, 0.15]))),
        (
            LikelihoodField.from_points(pts, 0.05),
            pts,
            Pose2D(*rng.uniform([-0.05, -0.05, -0.1], [0.05, 0.05, 0.1])),
        ),
        (plateau, grid_pts, Pose2D(1.5, 1.5, rng.choice([0.0, 0.02]))),
        # one flat value everywhere: every candidate ties and so does every angle's bound with the
        # best score; only the tie-break (the prior itself) may win
        (flat, grid_pts, Pose2D(2.0, 2.0, 0.1)),
    ]
    for field, p, prior in cases:
        for half_width in (0.05, 0.1, 0.15):
            window = SearchWindow(half_width, math.radians(rng.choice([2.0, 10.0])), math.radians(0.5))
            fast = correlative_search_runner_up(field, p, prior, window, math.inf)
            ref = correlative_search_reference(field, p, prior, window, math.inf)
            assert fast == ref


def test_angle_pruned_search_equals_the_reference_on_intel_pairs() -> None:
    # the bench's 50 consecutive and 50 ground-truth relation pairs of the Intel lab log (the
    # scan-to-scan field of the reference scan, the SLAM front end's narrow window)
    if not (peers.INTEL_BAG.exists() and peers.INTEL_RELATIONS.exists()):
        pytest.skip(f"{peers.INTEL_BAG} missing")
    consecutive, related, _ = peers.intel_pairs()
    matcher = ScanToScanMatcher()
    for ref, cur, prior in consecutive + related:
        field = LikelihoodField.from_points(peers._scan_points(ref), matcher.resolution, matcher.sigma)
        pts = peers._scan_points(cur)
        fast = correlative_search_runner_up(field, pts, prior, matcher.window, math.inf)
        assert fast == correlative_search_reference(field, pts, prior, matcher.window, math.inf)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_compiled_window_moments_and_surface_lines_equal_numpys_bit_for_bit(seed: int) -> None:
    """The degeneracy check's window moments (compiled) are numpy's to the bit, on box-world scans
    (walls, corners, jumps) and on random clouds of every small size around the window's; so are
    the lines, their normals and the information matrix built from them."""
    grid, res = box_world()
    rng = np.random.default_rng(seed)
    pose = Pose2D(rng.uniform(2, 8), rng.uniform(1.5, 5), rng.uniform(-np.pi, np.pi))
    clouds = [cast_scan(grid, res, pose, 360, noise=0.01, rng=rng).points()]
    clouds += [rng.normal(0.0, 3.0, (n, 2)) for n in (7, 8, 9, 15, 64, 201)]
    for pts in clouds:
        for half in (1, 3):
            got = kernels.window_moments(np.ascontiguousarray(pts), half)
            for a, b in zip(got, window_moments_reference(pts, half), strict=True):
                assert np.array_equal(a, b)
            for a, b in zip(surface_lines(pts, half), surface_lines_reference(pts, half), strict=True):
                assert np.array_equal(a, b)
            theta = float(rng.uniform(-np.pi, np.pi))
            info = translation_information(pts, theta, half)
            assert np.array_equal(info, translation_information_reference(pts, theta, half))
    assert surface_lines(clouds[0])[1].mean() > 0.5  # walls: most points are on a line


@pytest.mark.parametrize(
    ("shape", "step", "pad"),
    [((37, 53), 4, 0), ((64, 32), 8, 0), ((5, 3), 16, 0), ((9, 11), 1, 0), ((37, 53), 4, 6)],
)
def test_compiled_phase_split_equals_numpys_strided_slices(
    shape: tuple[int, int], step: int, pad: int
) -> None:
    grid = np.random.default_rng(step).random(shape).astype(np.float32)
    phase = kernels.phase_split(grid, step, pad)
    h, w = -(-shape[0] // step), -(-shape[1] // step)
    assert phase.shape == (step, step, h + 2 * pad, w + 2 * pad)
    padded = np.pad(grid, ((0, h * step - shape[0]), (0, w * step - shape[1])))
    for pr in range(step):
        for pc in range(step):
            assert np.array_equal(phase[pr, pc], np.pad(padded[pr::step, pc::step], pad))


def test_the_3x3_solve_equals_numpys_bit_for_bit() -> None:
    """Gauss-Newton's step: LAPACK's dgesv called directly gives np.linalg.solve's bits on symmetric
    positive definite systems like its normal equations (scales from 1e-4 to 1e4)."""
    rng = np.random.default_rng(0)
    pivots = np.empty(3, dtype=np.int32)
    for _ in range(2000):
        j = rng.normal(size=(12, 3)) * 10.0 ** rng.uniform(-2, 2, 3)
        h = j.T @ j + np.diag(rng.uniform(0.0, 10.0, 3))
        b = rng.normal(size=3) * 10.0 ** rng.uniform(-6, 2)
        expected = np.linalg.solve(h, b)
        x, lu = b.copy(), h.copy()
        kernels._solve3(lu, x, pivots)
        assert np.array_equal(x, expected)


def test_the_3x3_solve_refuses_what_numpys_refuses() -> None:
    pivots = np.empty(3, dtype=np.int32)
    with pytest.raises(np.linalg.LinAlgError, match="infs or NaNs"):
        kernels._solve3(np.eye(3), np.array([1.0, np.nan, 0.0]), pivots)
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        kernels._solve3(np.zeros((3, 3)), np.ones(3), pivots)


@pytest.mark.parametrize("half", [1, 2, 3, 5])
def test_a_halved_splat_is_the_halved_full_resolution_splat(half: int) -> None:
    # the half-resolution bound splatted with each parity's kernel equals the full-resolution
    # spread kernel's splat halved, next to the grid's edges too (every parity of centre)
    rng = np.random.default_rng(half)
    h, w = 30, 44  # even: a halved odd grid has a half-empty last block, which a splat may fill
    rows, cols = rng.integers(-4, h + 4, 60), rng.integers(-4, w + 4, 60)
    full = np.zeros((h, w), dtype=np.float32)
    kernels.splat_dense(full, rows, cols, _window_kernel(0.05, 0.05, half))
    halved = np.zeros(((h + 1) // 2, (w + 1) // 2), dtype=np.float32)
    kernels.splat_halved(halved, rows, cols, _halved_window_kernels(0.05, 0.05, half))
    assert np.array_equal(halved, halve_max(full))


@pytest.mark.parametrize("seed", range(4))
def test_the_one_call_match_equals_search_then_refinement(seed: int) -> None:
    # match_scan's exhaustive window runs the search and the refinement in one compiled call
    # (kernels.exhaustive_match): the same pose and score as the two separate calls, bit for bit,
    # more points than the search scores included (the refinement uses them all)
    rng = np.random.default_rng(300 + seed)
    g, pts = box_world_grid(60 + seed)
    field = LikelihoodField.from_grid(g)
    refine = RefineOptions(translation_weight=3.0, rotation_weight=10.0)
    for n in (40, 100, 250):
        p = pts[rng.choice(len(pts), min(n, len(pts)), replace=False)]
        prior = Pose2D(*rng.uniform([-0.1, -0.1, -0.15], [0.1, 0.1, 0.15]))
        window = SearchWindow(0.1, math.radians(10.0), math.radians(0.5))
        coarse, _ = correlative_search(field, p, prior, window)
        assert match_scan(field, p, prior, window, refine) == refine_pose(field, p, coarse, coarse, refine)
        # minimum score 2 (above any): the wide search always runs, its match kept when it scores more
        wide = SearchWindow(0.3, math.radians(20.0), math.radians(1.0), levels=2)
        pose, score = match_scan_with_fallback(field, p, prior, window, wide, 2.0, refine)
        narrow = refine_pose(field, p, coarse, coarse, refine)
        wide_coarse, _ = correlative_search(field, p, prior, wide)
        widened = refine_pose(field, p, wide_coarse, wide_coarse, refine)
        assert (pose, score) == (widened if widened[1] > narrow[1] else narrow)
