"""The exploration benchmark's own parts (issue 18): what the lidar sees from where, the watchman
tour the exploration time is compared with, and the family mode's settings and wall budget."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

import bench.explore as bx
from app.commands.explore import ExploreConfig, run_explore
from bench.visibility import visible_cells, visible_cells_reference
from nav.types import GridGeometry, OccupancyGrid, Pose2D
from robot.sim import World

START = Pose2D(1.5, 1.5, 0.0)


def _two_rooms() -> World:
    """12 x 8 m, a wall across at x = 6 from the floor to y = 6: the rooms meet only by the 2 m gap
    at the top, so nothing of the right room's lower half is in sight from the left room."""
    world = World.box(12.0, 8.0)
    world.add_polygon([(5.9, 0.0), (6.1, 0.0), (6.1, 6.0), (5.9, 6.0)])
    return world


@pytest.fixture(scope="module")
def rooms():
    world = _two_rooms()
    return world, bx.sight(world, START, stride=0.4, beams=180)


def _map_of(world: World, start: Pose2D, data: np.ndarray) -> OccupancyGrid:
    """``data`` over the world's cells as a built map: in the map frame, which starts at ``start``."""
    wg = world.geometry
    origin = start.inverse().compose(wg.origin)
    return OccupancyGrid(GridGeometry(wg.resolution, wg.width, wg.height, origin), data.astype(np.int8))


def test_a_wall_face_mapped_occupied_is_explored_and_a_ghost_or_a_hole_is_not():
    """The SLAM render makes a map cell that straddles a wall's face occupied (surface wins), so
    the one-cell band of free cells along every wall is mapped as the face: explored, as the
    agreement counts it. Occupied cells away from walls and unknown ones stay unexplored."""
    world = _two_rooms()
    start = Pose2D(1.5, 1.5, 0.3)
    occupied = world.static_occupied
    reach = bx.reachable_free(world, start)  # the two rooms: every free cell inside the walls
    n = np.count_nonzero(reach)
    face = ndimage.binary_dilation(occupied, structure=np.ones((3, 3), bool)) & reach
    data = np.where(reach, 0, np.where(occupied, 100, -1))
    data[face] = 100  # the walls one cell thicker on every face, as the render draws them
    data[40:43, 40:43] = 100  # a ghost obstacle in the open
    data[100:105, 30:35] = -1  # a hole never seen
    cmp = bx.compare(_map_of(world, start, data), world, start, start)
    assert cmp.explored == pytest.approx(1.0 - (9 + 25) / n)
    assert cmp.explored_free == pytest.approx(1.0 - (np.count_nonzero(face & reach) + 9 + 25) / n)
    assert cmp.agreement < 1.0  # the ghost obstacle disagrees


def test_an_occupied_cell_just_past_an_outer_wall_agrees_and_one_further_out_or_free_does_not():
    """Generated worlds' outer walls end at the grid's edge: a map cell one cell past a wall's
    outer face is occupied within one cell of that wall (agrees); two cells out, or free, it does
    not."""
    world = World.box(4.0, 3.0)
    start = Pose2D(2.0, 1.5, 0.0)
    wg = world.geometry
    k = 3  # the map reaches k cells past the world grid on every side
    inner = np.where(world.static_occupied, 100, np.where(bx.reachable_free(world, start), 0, -1))
    geometry = GridGeometry(
        wg.resolution,
        wg.width + 2 * k,
        wg.height + 2 * k,
        start.inverse().compose(Pose2D(-k * wg.resolution, -k * wg.resolution, 0.0)),
    )

    def agreement(ring: int, value: int) -> tuple[float, int]:
        data = np.full((wg.height + 2 * k, wg.width + 2 * k), -1, dtype=np.int8)
        data[k:-k, k:-k] = inner
        lo = k - ring  # the ring `ring` cells outside the grid
        hi_r, hi_c = data.shape[0] - 1 - lo, data.shape[1] - 1 - lo
        band = np.zeros(data.shape, bool)
        band[lo, lo : hi_c + 1] = band[hi_r, lo : hi_c + 1] = True
        band[lo : hi_r + 1, lo] = band[lo : hi_r + 1, hi_c] = True
        data[band] = value
        counted = np.count_nonzero((data >= 0) & ((data <= 25) | (data >= 65)))
        return bx.compare(OccupancyGrid(geometry, data), world, start, start).agreement, counted

    assert agreement(1, 100)[0] == 1.0
    for ring, value in ((2, 100), (1, 0)):
        got, counted = agreement(ring, value)
        ring_cells = 2 * (wg.width + 2 * ring) + 2 * (wg.height + 2 * ring) - 4
        assert got == pytest.approx(1.0 - ring_cells / counted)


def _truth_path() -> np.ndarray:
    """(M, 3) t, x, y: 20 m east along a corridor, then 6 m north into a room, from (2, 3)."""
    t = np.arange(0.0, 100.0, 0.05)
    s = 0.26 * t
    x = 2.0 + np.minimum(s, 20.0)
    y = 3.0 + np.clip(s - 20.0, 0.0, 6.0)
    return np.column_stack((t, x, y))


def _slam_of(truth: np.ndarray, start: Pose2D, scale: tuple[float, float], stride: int = 4) -> np.ndarray:
    """(N, 4) t, x, y, theta in the map frame (which starts at ``start``) of a SLAM whose map is
    ``scale`` times the world about the start, one scan every ``stride`` truth samples."""
    t = truth[::stride, 0]
    world_xy = (truth[::stride, 1:3] - (start.x, start.y)) * scale + (start.x, start.y)
    xy = start.inverse().transform_points(world_xy)
    return np.column_stack((t, xy, np.zeros(len(t))))


def test_slam_drift_finds_a_map_drawn_smaller_than_the_world():
    """A SLAM map 0.5 % smaller along x and 0.3 % along y than the world: the fit finds both,
    whatever the start's heading (the map frame is rotated against the world), and the trajectory
    error grows to 0.5 % of the 20 m east (+ 0.3 % of the 6 m north) at the far end."""
    truth = _truth_path()
    start = Pose2D(2.0, 3.0, 0.7)
    drift = bx.slam_drift(_slam_of(truth, start, (0.995, 0.997)), truth, start)
    assert drift.scale_pct == pytest.approx((-0.5, -0.3), abs=1e-6)
    assert drift.max_m == pytest.approx(np.hypot(0.005 * 20.0, 0.003 * 6.0), rel=1e-3)
    assert 0.0 < drift.mean_m < drift.max_m
    assert drift.residual_m == pytest.approx(0.0, abs=1e-9)


def test_slam_drift_of_an_exact_trajectory_is_nil_and_scans_past_the_truth_are_left_out():
    truth = _truth_path()
    start = Pose2D(2.0, 3.0, -0.4)
    slam = _slam_of(truth, start, (1.0, 1.0))
    late = np.array([[truth[-1, 0] + 1.0, 50.0, 50.0, 0.0]])  # a scan after the truth ends: not judged
    drift = bx.slam_drift(np.vstack((slam, late)), truth, start)
    assert drift.max_m == pytest.approx(0.0, abs=1e-9)
    assert drift.scale_pct == pytest.approx((0.0, 0.0), abs=1e-6)
    empty = bx.slam_drift(np.zeros((0, 4)), truth, start)
    assert np.isnan(empty.mean_m) and np.isnan(empty.scale_pct[0])


def test_navdeck_explore_reports_slams_drift_against_the_truth():
    """A short exploration of the stock apartment: the result carries SLAM's trajectory error
    against the truth (centimetres over a few metres) and the map's scale along x and y, as JSON."""
    res = run_explore(ExploreConfig(world="apartment", seed=0, timeout=15.0))
    assert res.state == "timeout" and res.path_length_m > 0.5
    assert 0.0 <= res.slam_error_mean_m <= res.slam_error_max_m < 0.2
    out = json.loads(json.dumps(res.as_dict()))
    assert len(out["slam_scale_pct"]) == 2
    assert out["slam_error_max_m"] == pytest.approx(res.slam_error_max_m, abs=1e-3)


def test_the_family_reports_the_worst_slam_drift_and_skips_runs_without_it():
    base = {k: 1.0 for k in ("explored_pct", "explored_free_pct", "agreement_pct", "collisions", "ratio")}
    base |= {"tour_ratio": 1.0, "time_s": 100.0, "complete": 1.0}
    runs = [
        base | {"slam_error_max_m": 0.05, "slam_scale_x_pct": -0.2, "slam_scale_y_pct": 0.1},
        base | {"slam_error_max_m": 0.19, "slam_scale_x_pct": 0.3, "slam_scale_y_pct": -0.61},
        dict(base),  # a run logged before the figures existed
    ]
    figures = {f.name: f.value for f in bx._family_figures("office", runs)}
    assert figures["office (N=3): SLAM trajectory error, worst max"] == pytest.approx(0.19)
    assert figures["office (N=3): SLAM map scale error, worst |%|"] == pytest.approx(0.61)


def test_places_are_in_order_of_travel_and_see_the_reachable_free_area(rooms):
    world, s = rooms
    assert np.all(np.diff(s.travel) >= 0)
    assert s.sees.shape == (len(s.views), int(np.count_nonzero(bx.reachable_free(world, START))))
    seen = np.asarray(s.sees.sum(axis=0)).ravel() > 0
    assert seen.mean() > 0.9  # walls hide only slivers from every place together


def test_the_tour_sees_every_cell_some_place_sees(rooms):
    world, s = rooms
    tour = bx.greedy_tour(world, START, s)
    rows = [int(np.flatnonzero(np.all(s.views == p, axis=1))[0]) for p in tour.places]
    covered = np.asarray(s.sees[rows].sum(axis=0)).ravel() > 0
    visible = np.asarray(s.sees.sum(axis=0)).ravel() > 0
    assert np.array_equal(covered, visible)
    assert (tour.places[:, 0] > 6.1).any() and (tour.places[:, 1] < 5.0).any()


def test_the_tour_is_no_faster_than_the_lower_bound_and_goes_round_the_wall(rooms):
    world, s = rooms
    tour = bx.greedy_tour(world, START, s)
    bound = bx.tour_lower_bound_s(s)
    assert bound > 0
    assert tour.seconds >= bound
    # the right room's lower half is seen only past the gap: at least the way up to it and back down
    assert tour.length_m >= (6.0 - START.y) + 2.0
    assert tour.seconds == pytest.approx(tour.length_m / s.max_vel_x)


def test_two_opt_undoes_a_nearest_neighbour_detour():
    x = np.array([0.0, 1.0, -1.5, 4.0])  # from 0, nearest first: 1, then -1.5, then 4: 9 m
    d = np.abs(x[:, None] - x[None, :])
    nn = bx._nearest_neighbour_path(d)
    assert nn == [0, 1, 2, 3]
    best = bx._two_opt_path(d, nn)
    assert best[0] == 0 and sorted(best) == [0, 1, 2, 3]
    assert d[best[:-1], best[1:]].sum() == pytest.approx(7.0)  # -1.5 first, then out to 4


def test_family_defaults_are_fifty_worlds_families_interleaved():
    cfg = bx.FamilyConfig.from_env({})
    worlds = cfg.worlds()
    assert len(worlds) == 50 and worlds[:3] == [("apartment", 0), ("office", 0), ("apartment", 1)]
    assert cfg.budget_s == float("inf") and cfg.log is None


def test_family_settings_come_from_the_environment():
    cfg = bx.FamilyConfig.from_env(
        {
            "NAVDECK_EXPLORE_TRIALS": "3",
            "NAVDECK_EXPLORE_FAMILIES": "office",
            "NAVDECK_EXPLORE_SEED0": "0",
            "NAVDECK_EXPLORE_BUDGET_S": "600",
            "NAVDECK_EXPLORE_TIMEOUT_S": "900",
        }
    )
    assert cfg.worlds() == [("office", 0), ("office", 1), ("office", 2)]
    assert (cfg.budget_s, cfg.timeout_s) == (600.0, 900.0)
    cfg = bx.FamilyConfig.from_env({"NAVDECK_EXPLORE_TRIALS": "2", "NAVDECK_EXPLORE_SEED0": "10"})
    assert cfg.worlds()[-1] == ("office", 11)


@pytest.mark.parametrize(
    ("name", "value", "match"),
    [
        ("NAVDECK_EXPLORE_TRIALS", "many", "not a number"),
        ("NAVDECK_EXPLORE_TRIALS", "0", "must be positive"),
        ("NAVDECK_EXPLORE_BUDGET_S", "-5", "must be positive"),
        ("NAVDECK_EXPLORE_FAMILIES", "apartment,castle", "unknown"),
    ],
)
def test_bad_family_settings_are_refused_by_name(name, value, match):
    with pytest.raises(ValueError, match=match) as err:
        bx.FamilyConfig.from_env({name: value})
    assert name in str(err.value)


def test_no_trial_starts_once_the_wall_budget_is_spent(monkeypatch, tmp_path):
    # run_one is minutes of simulated exploring per world: here only the budget's bookkeeping runs
    ran: list[tuple[str, int]] = []

    def one(spec: str, seed: int, timeout: float) -> dict[str, float]:
        ran.append((spec, seed))
        return {"explored_pct": 96.0, "time_s": 100.0}

    monkeypatch.setattr(bx, "run_one", one)
    now = iter([0.0, 0.0, 40.0, 80.0, 120.0])  # wall clock before each trial
    log = tmp_path / "trials.jsonl"
    cfg = bx.FamilyConfig(trials=5, budget_s=100.0, log=str(log))
    runs = bx.run_family(cfg, clock=lambda: next(now))
    assert ran == [("apartment:0", 0), ("office:0", 0), ("apartment:1", 1)]
    assert [len(v) for v in runs.values()] == [2, 1]
    assert len(log.read_text().splitlines()) == 3


def test_navigate_while_mapping_clicks_towards_a_goal_on_the_growing_map():
    # one goal, a short horizon: exercises the frontier clicks (_toward) against the explorer's API
    seen: list[tuple[int, bool]] = []
    r = bx.navigate_while_mapping(
        n_goals=1, per_goal_s=8.0, on_goal=lambda i, g, ok, t, c: seen.append((i, ok))
    )
    assert r["goals"] == 1.0 and [i for i, _ in seen] == [0]
    assert r["collisions"] == 0.0 and r["sim_s"] >= 8.0


def test_a_place_a_click_failed_at_is_not_clicked_again():
    edges = bx.FrontierExplorer()
    edges.mark_failed((1.0, 2.0))
    assert edges.is_banned((1.0 + 0.9 * edges.options.blacklist_radius, 2.0))
    assert not edges.is_banned((1.0 + 1.1 * edges.options.blacklist_radius, 2.0))
    edges.forgive()  # a forgiven place may be clicked again
    assert not edges.is_banned((1.0, 2.0))


def _same_sets(a, b) -> bool:
    a, b = a.tocsr(), b.tocsr()
    a.sort_indices()
    b.sort_indices()
    return a.shape == b.shape and np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)


def test_the_sight_kernel_sees_the_same_cells_as_the_numpy_reference():
    """The compiled walk along each ray gives every place the very cells the reference's sample
    arrays give (offset origin, rays leaving the grid, ranges ending on a sample, cells not targets)."""
    rng = np.random.default_rng(3)
    geo = GridGeometry(0.05, 90, 70, Pose2D(-3.17, 2.41, 0.0))
    target = rng.random((70, 90)) < 0.7
    index = np.full(target.shape, -1, dtype=np.int64)
    index[target] = np.arange(int(np.count_nonzero(target)))
    views = geo.cell_to_world(rng.integers(0, 70, 40), rng.integers(0, 90, 40))
    angles = np.linspace(-np.pi, np.pi, 72, endpoint=False)
    steps = np.arange(0.0, 3.0, 0.05)
    ranges = rng.uniform(0.0, 3.0, (40, 72))
    ranges[:, ::5] = steps[rng.integers(0, steps.size, (40, 15))]  # exactly on a sample: not seen
    ranges[::7] = 3.0  # rays to the range, many leaving the grid
    fast = visible_cells(geo, index, views, ranges, angles, steps)
    ref = visible_cells_reference(geo, index, views, ranges, angles, steps)
    assert ref.nnz > 10_000
    assert _same_sets(fast, ref)


def test_sight_is_the_reference_sight(rooms):
    world, s = rooms
    wg = world.geometry
    target = bx.reachable_free(world, START)
    index = np.full(target.shape, -1, dtype=np.int64)
    index[target] = np.arange(int(np.count_nonzero(target)))
    angles = np.linspace(-np.pi, np.pi, 180, endpoint=False)
    rmax = bx.load_profile("skid4").lidar.range_max
    ranges = world.raycaster.cast(s.views, np.broadcast_to(angles, (len(s.views), 180)), rmax)
    ranges = np.where(np.isfinite(ranges), ranges, rmax)
    steps = np.arange(0.0, rmax, wg.resolution)
    assert _same_sets(s.sees, visible_cells_reference(wg, index, s.views, ranges, angles, steps))


def test_the_sight_kernel_refuses_a_rotated_grid():
    geo = GridGeometry(0.05, 10, 10, Pose2D(0.0, 0.0, 0.3))
    with pytest.raises(ValueError, match="rotated"):
        visible_cells(
            geo,
            np.zeros((10, 10), np.int64),
            np.zeros((1, 2)),
            np.ones((1, 1)),
            np.zeros(1),
            np.arange(0.0, 1.0, 0.05),
        )
