"""No ghost free space (issue 16): a beam without return never clears past a surface the map holds,
in SLAM submaps and in the costmap's obstacle layer; the simulator's lidar never sees through a
wall; after a teleop loop of the apartment the map holds no free cell in a wall or outside the
building and is the building's size."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import nav.slam.system as system_module
from bench.ghost import ghost_report, map_after_loop, measure
from bench.mapping import APARTMENT_LOOP, APARTMENT_START
from maps.stock import stock_world_path
from nav.costmap.obstacle_layer import ObstacleLayer, ObstacleLayerOptions
from nav.grid import VIEW_CLEARED, VIEW_HIT, VIEW_UNSURE, LogOddsGrid, LogOddsOptions
from nav.raycast import traversed_cells
from nav.slam.loop_closure import LoopCandidate
from nav.slam.render import render_submaps, view_logodds
from nav.slam.synthetic import LOOP_WAYPOINTS, box_world, cast_scan, loop_trajectory
from nav.slam.system import GraphSlam, SlamOptions, grazing_shortening
from nav.types import LETHAL_OBSTACLE, NO_INFORMATION, GridGeometry, LaserScan, OccupancyGrid, Pose2D
from robot.sim import World


def test_no_return_ray_stops_at_the_first_occupied_cell() -> None:
    g = LogOddsGrid(LogOddsOptions(resolution=0.1, grow_margin=1.0))
    wall = np.column_stack((np.full(21, 2.05), np.linspace(-1.0, 1.0, 21)))
    g.insert_scan(Pose2D(0.05, 0.05, 0.0), wall)
    change = g.insert_scan(Pose2D(0.05, 0.05, 0.0), np.zeros((0, 2)), misses=np.array([[5.0, 0.0]]))
    occ = g.to_occupancy_grid()
    rows, cols = occ.geometry.world_to_cell(
        np.array([[1.55, 0.05], [2.05, 0.05], [2.55, 0.05], [4.55, 0.05]])
    )
    before, at, behind, far = occ.data[rows, cols]
    assert before < 50 and at > 50  # cleared up to the wall, the wall kept
    assert behind == far == -1  # nothing behind the wall observed
    assert change.miss_reach is not None and change.miss_reach[0] == pytest.approx(0.4, abs=0.01)


def test_a_return_still_clears_through_an_old_obstacle() -> None:
    opt = LogOddsOptions(resolution=0.1, grow_margin=1.0)
    g = LogOddsGrid(opt)
    g.insert_scan(Pose2D(0.05, 0.05, 0.0), np.array([[1.0, 0.0]]))  # a person stood there
    g.insert_scan(Pose2D(0.05, 0.05, 0.0), np.array([[3.0, 0.0]]))  # now the wall behind is seen
    r, c = g.cells(np.array([[1.05, 0.05], [2.05, 0.05]]))
    assert g.logodds[r[0], c[0]] == pytest.approx(opt.l_occ + opt.l_free, abs=1e-6)
    assert g.logodds[r[1], c[1]] == pytest.approx(opt.l_free, abs=1e-6)


def ring_scan(radius: float, dropouts: list[int], beams: int = 360) -> LaserScan:
    r = np.full(beams, radius)
    r[dropouts] = np.inf
    return LaserScan(0.0, -math.pi, 2 * math.pi / beams, r, 0.15, 6.0)


def test_dropout_in_a_round_room_clears_nothing_behind_the_wall() -> None:
    """The first scan of a session has nothing mapped yet: the dropouts' neighbours vouch for the
    wall, so a dropout may only clear in front of it."""
    slam = GraphSlam(SlamOptions())
    slam.add_scan(ring_scan(2.0, [10, 100, 200, 201]), Pose2D())
    grid = slam.map()
    rows, cols = np.nonzero(grid.data >= 0)
    centres = grid.geometry.cell_to_world(rows, cols)
    assert np.hypot(centres[:, 0], centres[:, 1]).max() < 2.0 + 2 * grid.geometry.resolution
    free = grid.data[rows, cols] < 50  # one scan: passed-through cells read 40
    assert np.hypot(centres[free, 0], centres[free, 1]).max() < 2.0


def test_new_submap_does_not_clear_past_walls_the_older_one_holds() -> None:
    """A run of return-less beams (no neighbour returns) at the start of a new submap: the older
    submap holds the wall, so the new one stops there too."""
    opts = SlamOptions(submap_num_range_data=3, minimum_travel_distance=0.0, minimum_time_interval=0.0)
    slam = GraphSlam(opts)
    for k in range(7):  # submaps 0, 1 (from node 3) and 2 (from node 6)
        slam.add_scan(replace(ring_scan(2.0, []), stamp=k), Pose2D(0.0, 0.0, 0.01 * k))
    slam.add_scan(replace(ring_scan(2.0, list(range(80, 100))), stamp=8), Pose2D(0.0, 0.0, 0.08))
    grid = slam.map()
    rows, cols = np.nonzero(grid.data >= 0)
    centres = grid.geometry.cell_to_world(rows, cols)
    assert np.hypot(centres[:, 0], centres[:, 1]).max() < 2.0 + 2 * grid.geometry.resolution


@pytest.mark.parametrize("rotated", [False, True])
def test_costmap_no_return_beam_clears_the_first_obstacle_but_nothing_behind(rotated: bool) -> None:
    theta = 1e-9 if rotated else 0.0  # any rotation takes the numpy path
    geo = GridGeometry(0.05, 100, 40, Pose2D(0.0, 0.0, theta))
    layer = ObstacleLayer(geo, ObstacleLayerOptions(raytrace_max_range=4.0), track_unknown_space=True)
    origin = np.array([0.52, 1.02])

    def cell(x: float) -> tuple[int, int]:
        r, c = geo.world_to_cell(np.array([[x, 1.02]]))
        return int(r[0]), int(c[0])

    def cost(x: float) -> int:
        return int(layer.costs[cell(x)])

    layer.costs[cell(1.52)] = layer.costs[cell(2.52)] = LETHAL_OBSTACLE  # two marks on one line
    layer.update(np.zeros((0, 2)), origin, np.array([[4.52, 1.02]]))  # a dropout along it

    assert cost(1.02) == 0 and cost(1.52) == 0  # in front and the first mark: cleared
    assert cost(2.02) == NO_INFORMATION and cost(2.52) == LETHAL_OBSTACLE  # behind it: untouched
    assert cost(3.52) == NO_INFORMATION


@pytest.mark.parametrize("name", ["apartment", "office", "greenhouse"])
def test_simulated_lidar_never_sees_through_a_wall(name: str) -> None:
    """Rays from random free points of each stock world, at every heading: no cell the ray crosses
    before its return is occupied, and the return lies on an occupied cell."""
    world = World.from_yaml(stock_world_path(name))
    geo = world.geometry
    rng = np.random.default_rng(16)
    free = np.argwhere(world.clearance_map > 0.2)
    pick = free[rng.choice(len(free), 40, replace=False)]
    origins = geo.cell_to_world(pick[:, 0], pick[:, 1]) + rng.uniform(-0.02, 0.02, (40, 2))
    angles = rng.uniform(-math.pi, math.pi, 720)
    ranges = world.raycaster.cast(origins, angles, 12.0)
    org = np.repeat(origins, len(angles), axis=0)
    ang = np.tile(angles, len(origins))
    r = ranges.ravel()
    hit = np.isfinite(r)
    unit = np.column_stack((np.cos(ang), np.sin(ang)))
    before = org + unit * np.where(hit, r - 1e-6, 12.0)[:, None]
    rows, cols, _ = traversed_cells(geo, org, before, include_end=True)
    assert not world.static_occupied[rows, cols].any()
    inside = org[hit] + unit[hit] * (r[hit] + 1e-6)[:, None]
    hr, hc = geo.world_to_cell(inside)
    assert world.static_occupied[hr, hc].all()


def test_apartment_loop_map_has_no_ghost_free_space() -> None:
    """The CI-sized loop (around the living-room table, ~55 s simulated on a virtual clock)."""
    drive, grid = map_after_loop("apartment", APARTMENT_START, APARTMENT_LOOP)
    r = ghost_report(grid, drive.world.static_occupied, drive.world.geometry, drive.start_truth)
    assert r.outside == 0, r
    assert r.deeper_than_half_cell == 0, r
    assert r.extent_error_m <= 1.0, r
    assert r.free_cells > 10_000  # the living room, kitchen and bedroom floor are there


def _heading_error_with_gyro_bias(options: SlamOptions, bias: float = 0.005) -> float:
    """Largest front-end heading error (rad) over a loop of the 12 m box world (0.25 m/s, 10 deg
    turns in place, 1 cm range noise) with odometry whose heading drifts at ``bias`` rad/s (the
    skid4 profile's is 0.002; an MPU6050's runs to 0.01 after calibration)."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS)
    rng = np.random.default_rng(3)
    slam = GraphSlam(options)
    odom = Pose2D.from_array(truth[0])
    for k in range(len(truth)):
        if k:
            step = Pose2D.from_array(truth[k]).relative_to(Pose2D.from_array(truth[k - 1]))
            odom = odom.compose(Pose2D(step.x, step.y, step.theta + bias * 0.4))
        pose = Pose2D.from_array(truth[k])
        slam.add_scan(cast_scan(grid, res, pose, 360, 2 * math.pi, 6.0, 0.01, rng, 0.4 * k), odom)
    stamps, poses = slam.front_end_nodes()
    k = np.rint(stamps / 0.4).astype(int)
    start = Pose2D.from_array(truth[0])  # the front end's local frame starts there
    true_rel = np.array([Pose2D.from_array(truth[i]).relative_to(start).theta for i in k])
    return float(np.abs(np.remainder(poses[:, 2] - true_rel + math.pi, math.tau) - math.pi).max())


def test_front_end_heading_does_not_follow_a_gyro_bias() -> None:
    """The office's full loop (bench mapping.ghost): the skid4 gyro's 0.002 rad/s bias became 2.8
    deg of front-end heading drift (a prediction offset below the 0.5 deg lattice is kept by the
    match: the likelihood field is flat at the optimum), which bent the 25 m corridor's walls
    0.1-0.27 m off and put ~1,500 free cells on true walls. The drift is estimated and removed
    (measured: 0.19 deg largest error with the estimate, 0.57 deg without)."""
    with_estimate = _heading_error_with_gyro_bias(SlamOptions())
    without = _heading_error_with_gyro_bias(SlamOptions(heading_drift_time_constant=0.0))
    assert with_estimate < math.radians(0.35), math.degrees(with_estimate)
    assert without > 2 * with_estimate, (math.degrees(without), math.degrees(with_estimate))


def test_map_cell_straddling_a_submaps_wall_is_not_free() -> None:
    """The map's lattice and a submap's are offset (here by 0.6 cell): the map cell from 1.00 to
    1.05 m holds the wall's first 2 cm (the wall starts at 1.03 m) but its centre lies over the
    submap's free cell in front of the wall. Nearest-neighbour resampling made it free (a free cell
    on the wall's face in every live map); a cell with a surface in it is occupied."""
    opt = SlamOptions().grid_options()
    anchor = np.full((4, 4), opt.l_min, dtype=np.float32)  # a free patch that fixes the lattice
    room = np.full((20, 30), opt.l_min, dtype=np.float32)  # free up to x = 1.0 in its frame
    room[:, 20:] = opt.l_max  # the wall: x 1.0-1.5 in its frame, 1.03-1.53 in the map
    layers = [
        (Pose2D(), np.array([0.0, 0.0]), anchor, np.ones_like(anchor, dtype=bool)),
        (Pose2D(0.03, 0.0, 0.0), np.array([0.0, 0.0]), room, np.ones_like(room, dtype=bool)),
    ]
    grid = render_submaps(layers, opt).to_occupancy_grid()
    r, c = grid.geometry.world_to_cell(np.array([[1.04, 0.5], [0.9, 0.5], [1.2, 0.5]]))
    straddling, in_front, inside = grid.data[r, c]
    assert straddling > 50, grid.data[r[0], c[0] - 2 : c[0] + 2]
    assert in_front < 25 and inside > 50


def test_loop_closure_the_optimized_graph_rejects_is_dropped(monkeypatch: pytest.MonkeyPatch) -> None:
    """The office's full loop (bench mapping.ghost): 16 local closures of corridor nodes matched
    1.5-2.5 m along the corridor (the walls look the same there; the +-2 m window admits it).
    Huber only bounded their pull: together they shifted the corridor 0.05 m and put free cells
    on its end walls and door jambs. A closure whose error in the optimized graph stays above
    ``loop_max_residual`` is dropped and the graph optimized without it. Here one real closure
    of the box-world loop is moved 1.5 m along its submap's x axis, as the office's were."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS)
    rng = np.random.default_rng(5)
    moved: list[tuple[int, int]] = []
    real_find = system_module.find_loop_closure

    def aliased(*args: object, **kwargs: object) -> LoopCandidate | None:
        cand = real_find(*args, **kwargs)
        if cand is not None and not moved and cand.node > len(truth) // 2:
            moved.append((cand.node, cand.submap))
            r = cand.relative
            return replace(cand, relative=Pose2D(r.x + 1.5, r.y, r.theta))
        return cand

    monkeypatch.setattr(system_module, "find_loop_closure", aliased)
    slam = GraphSlam(SlamOptions(submap_num_range_data=10))
    for k in range(len(truth)):
        pose = Pose2D.from_array(truth[k])
        slam.add_scan(cast_scan(grid, res, pose, 360, 2 * math.pi, 6.0, 0.01, rng, 0.4 * k), pose)
        if k % 30 == 29:
            slam.run_backend()
    slam.run_backend()
    assert moved, "no loop closure was found to move"
    kept = [(lc.node, lc.submap) for lc in slam._loops]
    assert moved[0] not in kept
    assert slam.rejected_local >= 1
    assert slam.num_loop_closures > 5  # the real closures are kept
    stamps, _ = slam.front_end_nodes()
    start = Pose2D.from_array(truth[0])
    true_xy = np.array(
        [
            Pose2D.from_array(truth[k]).relative_to(start).as_array()[:2]
            for k in np.rint(stamps / 0.4).astype(int)
        ]
    )
    assert np.hypot(*(slam.node_poses()[:, :2] - true_xy).T).max() < 0.05


def test_surface_in_one_submap_wins_over_free_in_others_when_asked() -> None:
    """``surface_wins_across_submaps``: a wall cell one submap holds occupied (one return) and two
    others saw as free (rays passing it at a glancing angle) stays occupied in the map; by default
    the log-odds sum decides (free), so a walker one submap saw does not stay in the map."""
    opt = SlamOptions().grid_options()
    wall = np.full((10, 10), opt.l_free, dtype=np.float32)
    wall[5, 5] = opt.l_occ  # one return landed here, in this submap only
    passed = np.full((10, 10), 3 * opt.l_free, dtype=np.float32)
    seen = np.ones((10, 10), dtype=bool)
    layers = [(Pose2D(), np.zeros(2), g, seen) for g in (wall, passed, passed)]
    probe = np.array([[0.275, 0.275], [0.125, 0.125]])  # the wall cell's centre, a free cell

    def values(across: bool) -> np.ndarray:
        grid = render_submaps(layers, opt, across).to_occupancy_grid()
        r, c = grid.geometry.world_to_cell(probe)
        return grid.data[r, c]

    assert values(True)[0] > 50 and values(True)[1] < 25
    assert values(False)[0] < 25


GRAZING_RAY_MARGIN = 0.025
"""The grazing-ray rule's measured setting (``SlamOptions.grazing_ray_margin``, off by default)."""


def _grazing_scan(face: float, degrees: tuple[float, float] = (2.0, 14.0), n: int = 60) -> np.ndarray:
    """Returns on a face ``y = face`` (laser frame) from beams ``degrees`` above the x axis: the
    face seen along its length, as a plant row's face is seen down an aisle from the headland."""
    a = np.radians(np.linspace(*degrees, n))
    r = face / np.sin(a)
    return np.column_stack((r * np.cos(a), r * np.sin(a)))


@pytest.mark.parametrize("margin", [0.0, GRAZING_RAY_MARGIN])
def test_grazing_rays_do_not_clear_a_face_cell_a_return_marked(margin: float) -> None:
    """The greenhouse's full loop (bench mapping.ghost): free cells on the plant rows' faces, seen
    only down the aisles from the headlands. The lattice straddles a face (here the cell from 0.60
    to 0.65 m holds the face at 0.61 m); rays grazing the face on their way to returns further
    along pass through the cell's free sliver and outvoted the return that marked it occupied.
    Within ``grazing_ray_margin`` of the surface they hit, returns' rays leave occupied cells
    alone (``margin`` 0: the rule off, the face cell is cleared)."""
    g = LogOddsGrid(LogOddsOptions(resolution=0.05, grow_margin=1.0))
    g.ensure_contains(np.array([[-1.0, -1.0], [25.0, 2.0]]))
    r, c = g.cells(np.array([[10.025, 0.625]]))
    g.insert_scan(Pose2D(10.025, 0.0, math.pi / 2), np.array([[0.61, 0.0]]))  # seen head-on once
    assert g.logodds[r[0], c[0]] > 0.0
    pts = _grazing_scan(0.605)  # ~1 cm of pose error between the scans
    for _ in range(5):
        g.insert_scan(Pose2D(), pts, None, grazing_shortening(pts, margin))
    if margin > 0.0:
        assert g.logodds[r[0], c[0]] > 0.0
    else:
        assert g.logodds[r[0], c[0]] < 0.0


def test_grazing_rule_still_clears_a_walker_seen_once() -> None:
    """A walker one scan saw (an occupied cell in the open) is cleared by later rays that pass
    through its place on their way to a wall: they are far from the surface they hit, so the
    grazing rule does not hold them back (the reason ``surface_wins_across_submaps`` is off)."""
    opt = SlamOptions(grazing_ray_margin=GRAZING_RAY_MARGIN)
    g = LogOddsGrid(LogOddsOptions(resolution=0.05, grow_margin=1.0))
    walker = np.array([[2.0, 0.0]])
    g.insert_scan(Pose2D(0.025, 0.025, 0.0), walker)
    r, c = g.cells(walker + 0.025)
    assert g.logodds[r[0], c[0]] > 0.0
    # the walker left: three scans of the wall 4 m behind it, rays through the walker's cell
    pts = np.column_stack((np.full(41, 4.0), np.linspace(-1.0, 1.0, 41)))
    for _ in range(3):
        g.insert_scan(Pose2D(0.025, 0.025, 0.0), pts, None, grazing_shortening(pts, opt.grazing_ray_margin))
    assert g.logodds[r[0], c[0]] < 0.0


def test_grazing_shortening_follows_the_angle_to_the_surface() -> None:
    """Half a cell for a head-on return, ``margin / sin(a)`` for one at angle ``a`` to its
    surface, the whole ray at most; no line through the neighbours (a post): head-on."""
    wall = np.column_stack((np.full(21, 2.0), np.linspace(-0.2, 0.2, 21)))  # head-on, 2 m ahead
    assert grazing_shortening(wall, 0.025)[10] == pytest.approx(0.025, rel=0.01)
    pts = _grazing_scan(0.5, (5.0, 6.0), 21)
    a = np.radians(5.5)  # the middle return: the beam meets the face at 5.5 deg
    assert grazing_shortening(pts, 0.025)[10] == pytest.approx(0.025 / math.sin(a), rel=0.01)
    post = np.array([[1.0, 0.0]])
    assert grazing_shortening(post, 0.025)[0] == pytest.approx(0.025)
    assert grazing_shortening(pts, 0.0).max() == 0.0


def test_extent_is_the_observed_cells_not_a_rotated_grids_corners() -> None:
    """The map frame starts at the robot's start pose: a generated office started at -83 deg,
    its map grid (axis-aligned in that frame) was rotated 7 deg off the walls and its corners'
    box in the world was 27.5 x 19.4 m around a 24.35 x 13.6 m building mapped within centimetres
    (extent error 2.95 m in ``mapping.ghost_family``). The extent is the observed cells'."""
    res = 0.05
    world = np.zeros((60, 100), dtype=bool)  # a 5 x 3 m building with 0.1 m walls
    world[:2], world[-2:], world[:, :2], world[:, -2:] = True, True, True, True
    world_geo = GridGeometry(res, 100, 60, Pose2D())
    start = Pose2D(2.5, 1.5, math.radians(-83.0))
    side = 160  # a map grid wide enough for the building in any rotation, most of it unobserved
    geo = GridGeometry(res, side, side, Pose2D(-4.0, -4.0, 0.0))
    rows, cols = np.mgrid[0:side, 0:side]
    pts = start.transform_points(geo.cell_to_world(rows.ravel(), cols.ravel()))
    wr, wc = world_geo.world_to_cell(pts)
    inside = world_geo.in_bounds(wr, wc)
    occ = inside & world[np.clip(wr, 0, 59), np.clip(wc, 0, 99)]
    data = np.where(occ, 100, np.where(inside, 0, -1)).astype(np.int8).reshape(side, side)
    r = ghost_report(OccupancyGrid(geo, data), world, world_geo, start)
    assert r.extent_error_m < 0.1, r
    assert r.built_size_m == pytest.approx((5.0, 3.0), abs=0.1)


@pytest.mark.parametrize("margin", [0.0, SlamOptions().view_grazing_margin])
def test_map_view_keeps_a_face_cell_only_grazing_rays_cleared(margin: float) -> None:
    """The greenhouse's rows seen down the aisles (bench mapping.ghost): the grazing rays clear the
    face cell's log-odds (the grids the matcher aligns to keep the plain evidence), but the map users
    get shows it occupied: its last firm evidence is the return, the rays since ran within
    ``view_grazing_margin`` of the surface they hit (``margin`` 0: the rule off, the map shows it free)."""
    opt = LogOddsOptions(resolution=0.05, grow_margin=1.0)
    g = LogOddsGrid(opt, track_view=True)
    g.ensure_contains(np.array([[-1.0, -1.0], [25.0, 2.0]]))
    r, c = g.cells(np.array([[10.025, 0.625]]))
    g.insert_scan(Pose2D(10.025, 0.0, math.pi / 2), np.array([[0.61, 0.0]]))  # seen head-on once
    pts = _grazing_scan(0.605)
    for _ in range(5):
        g.insert_scan(Pose2D(), pts, None, None, grazing_shortening(pts, margin))
    assert g.logodds[r[0], c[0]] < 0.0  # the evidence: cleared
    shown = view_logodds(g.logodds, g.view, opt.l_occ, edge=False)[r[0], c[0]]
    if margin > 0.0:
        assert g.view[r[0], c[0]] == VIEW_HIT and shown > 0.0
    else:
        assert g.view[r[0], c[0]] == VIEW_CLEARED and shown < 0.0
        # the edge rule alone: the face cell borders the row behind the face, which no ray observed
        assert view_logodds(g.logodds, g.view, opt.l_occ)[r[0], c[0]] >= 0.0
    free = (g.logodds < 0.0) & (g.view == VIEW_CLEARED)  # the aisle's middle stays free in the view
    assert free[r[0] - 3, c[0] - 30 : c[0] + 30].all()


def test_map_view_still_clears_a_walker_seen_once() -> None:
    """A walker one scan saw is cleared in the map users get by later rays through its place on
    their way to a wall 4 m behind (far from the surface they hit), unlike
    ``surface_wins_across_submaps``."""
    opt = LogOddsOptions(resolution=0.05, grow_margin=1.0)
    margin = SlamOptions().view_grazing_margin
    g = LogOddsGrid(opt, track_view=True)
    walker = np.array([[2.0, 0.0]])
    g.insert_scan(Pose2D(0.025, 0.025, 0.0), walker, None, None, grazing_shortening(walker, margin))
    r, c = g.cells(walker + 0.025)
    assert g.view[r[0], c[0]] == VIEW_HIT
    pts = np.column_stack((np.full(41, 4.0), np.linspace(-1.0, 1.0, 41)))
    for _ in range(3):
        g.insert_scan(Pose2D(0.025, 0.025, 0.0), pts, None, None, grazing_shortening(pts, margin))
    assert g.view[r[0], c[0]] == VIEW_CLEARED
    assert view_logodds(g.logodds, g.view, opt.l_occ)[r[0], c[0]] < 0.0


def test_map_view_rule_does_not_change_the_trajectory() -> None:
    """The view states are kept beside the log-odds, never read by matching or loop closure: the
    box-world loop gives bit-identical poses with the rule on and off (stop 30's grazing rule in
    the matched grids moved FR079's trajectory), and the rendered map differs only by cells the
    rule made not free."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS)[:150]
    runs = []
    for margin in (0.0, SlamOptions().view_grazing_margin):
        rng = np.random.default_rng(5)
        slam = GraphSlam(SlamOptions(view_grazing_margin=margin))
        for k in range(len(truth)):
            pose = Pose2D.from_array(truth[k])
            slam.add_scan(cast_scan(grid, res, pose, 360, 2 * math.pi, 6.0, 0.01, rng, 0.4 * k), pose)
        runs.append((slam.trajectory(), slam.map(), slam.evidence_map()))
    (traj_off, map_off, ev_off), (traj_on, map_on, ev_on) = runs
    assert np.array_equal(traj_off, traj_on)
    assert np.array_equal(ev_off.data, ev_on.data)  # the evidence the consistency checks read
    assert map_off.data.shape == map_on.data.shape
    free_off, free_on = ((m.data >= 0) & (m.data <= 25) for m in (map_off, map_on))
    assert not (free_on & ~free_off).any()  # the rule never makes a cell free
    assert free_on.sum() > 0.9 * free_off.sum()


def test_view_shortening_takes_a_grazing_angle_from_a_neighbour_across_a_gap() -> None:
    """Looking down an aisle: the beams near its axis go out of range (no return), so the returns
    nearest the gap, the most grazing ones, have a seven-return window spanning both faces and no
    line fits. Head-on was the fallback (their rays cleared the face cells); with ``neighbours``
    the segment to the next return on the same face gives the angle."""
    left = _grazing_scan(0.605, (4.0, 14.0), 30)
    right = _grazing_scan(-0.6, (-14.0, -4.0), 30)
    pts = np.vstack((right, left))  # beam order, the gap between -4 and 4 deg
    k = 30  # the first return on the left face, at 4 deg to it
    margin = 0.025
    assert grazing_shortening(pts, margin)[k] == pytest.approx(margin)  # no line: head-on
    # the face runs along x; the beam at 4 deg: margin / sin(4 deg)
    got = grazing_shortening(pts, margin, neighbours=True)[k]
    assert got == pytest.approx(margin / math.sin(math.radians(4.0)), rel=0.1)
    # where a line fits, the neighbours do not change it; the margin grows with the range
    assert grazing_shortening(pts, margin, neighbours=True)[45] == pytest.approx(
        grazing_shortening(pts, margin)[45]
    )
    r = float(np.hypot(*pts[45]))
    grown = grazing_shortening(pts, margin, neighbours=True, heading_sigma=0.01)[45]
    assert grown == pytest.approx(min(grazing_shortening(pts, margin)[45] * (margin + 0.01 * r) / margin, r))


def test_greenhouse_map_view_has_no_free_cells_deep_in_the_rows() -> None:
    """The greenhouse's full loop (bench mapping.ghost) with the default options: the rows' faces
    seen down the aisles from the headlands kept 44 free cells deeper than half a cell in the rows
    (the map view rule off, ``view_grazing_margin=0``); 3 measured with it (stop 32)."""
    report, end_error = measure("greenhouse")
    assert end_error < 0.2, end_error
    assert report.outside == 0, report
    assert report.deeper_than_half_cell <= 10, report


def _seen_through_a_door() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A submap (log-odds, seen, view; 0.05 m cells, origin (0, 0)) as the office's corridor submaps
    hold the corridor's south wall (bench mapping.ghost, stop 33): the wall fills y 1.00-1.10 m for
    x < 1.0 m (a door from x = 1.0 m); the lidar saw it from the corridor (y > 1.1 m) only. Its
    corridor face (row 21) holds returns, its room face (row 20) no ray reached, and the room (rows
    0-19) was cleared by rays through the door, the row under the wall by the ones that passed the
    jamb's corner. One cell of the room (row 10, column 30) lies between beams, never crossed."""
    opt = SlamOptions().grid_options()
    view = np.full((40, 40), VIEW_CLEARED, dtype=np.uint8)
    view[21, :20] = VIEW_HIT
    view[20, :19] = VIEW_UNSURE  # the wall's room face: never observed
    view[20, 19] = VIEW_HIT  # the jamb's end, seen through the door
    view[10, 30] = VIEW_UNSURE
    seen = view != VIEW_UNSURE
    lo = np.where(view == VIEW_HIT, opt.l_max, np.where(seen, opt.l_min, 0.0)).astype(np.float32)
    return lo, seen, view


def test_cleared_edge_facing_space_no_ray_observed_is_not_free() -> None:
    """The office's last free cells in walls (stop 33): the room face of the corridor's south wall
    next to door jambs, cleared by rays from the corridor that passed the jamb's corner, with the
    corridor's submaps placed 4-5 cm north of the truth (pose error). A firmly cleared cell next to
    unobserved space two cells deep (``render.unsure_edge``) is at least unknown in the map; with
    the old rule (``edge=False``) the wall's room-face cell is drawn free."""
    opt = SlamOptions().grid_options()
    lo, seen, view = _seen_through_a_door()
    shown = view_logodds(lo, view, opt.l_occ)
    assert (shown[19, :19] >= 0.0).all()  # the row under the unobserved face: not free
    assert (shown[22, 2:20] < 0.0).all()  # in front of the face its returns marked: still free
    assert shown[19, 25] < 0.0 and shown[18, 5] < 0.0  # the door's middle, the room: still free
    around_hole = shown[[9, 11, 10, 10], [30, 30, 29, 31]]
    assert (around_hole < 0.0).all()  # a cell between beams erodes nothing
    assert view_logodds(lo, view, opt.l_occ, edge=False)[19, 5] < 0.0  # the old rule: free

    def room_face(edge: bool) -> np.ndarray:  # the map cells y 1.00-1.05, the wall's room face
        layer = view_logodds(lo, view, opt.l_occ, edge)
        grid = render_submaps([(Pose2D(0.0, 0.045, 0.0), np.zeros(2), layer, seen)], opt)
        occ = grid.to_occupancy_grid()
        r, c = occ.geometry.world_to_cell(np.column_stack((np.arange(0.125, 0.9, 0.05), np.full(16, 1.025))))
        return occ.data[r, c]

    assert (room_face(False) <= 25).all()  # free cells in the wall
    assert (room_face(True) > 25).all()
