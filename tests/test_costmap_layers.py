"""Costmap layers: Nav2 inflation formula, static interpretation, obstacle marking/clearing, rolling
window, footprint costs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from nav.costmap import (
    Costmap2D,
    CostmapOptions,
    InflationOptions,
    ObstacleLayerOptions,
    StaticLayerOptions,
    circle_footprint,
    footprint_radii,
    inflate,
    inflation_cost,
    local_costmap_options,
    static_costs,
)
from nav.costmap.inflation import cell_inflation_radius
from nav.types import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    GridGeometry,
    LaserScan,
    OccupancyGrid,
    Pose2D,
)

RES = 0.05


def nav2_cost(d: float, inscribed: float, csf: float = 10.0) -> int:
    """Nav2 InflationLayer::computeCost, written out as in the C++ source."""
    if d == 0:
        return 254
    if d <= inscribed:
        return 253
    return int(252 * math.exp(-1.0 * csf * (d - inscribed)))  # (unsigned char) truncation


def test_inflation_matches_nav2_formula_at_sample_distances() -> None:
    costs = np.zeros((61, 61), dtype=np.uint8)
    costs[30, 30] = LETHAL_OBSTACLE
    inscribed = 0.12
    opts = InflationOptions()
    out = inflate(costs, RES, inscribed, opts)
    r_cells = cell_inflation_radius(RES, opts)
    assert r_cells == math.ceil(0.55 / 0.05) == 11  # Nav2 cellDistance
    for dr, dc in [
        (0, 0),
        (0, 1),
        (1, 1),
        (0, 2),
        (2, 1),
        (0, 3),
        (2, 2),
        (3, 4),
        (0, 7),
        (5, 5),
        (0, 11),
        (0, 12),
        (8, 7),
    ]:
        d = math.hypot(dr, dc) * RES
        expected = nav2_cost(d, inscribed) if math.hypot(dr, dc) <= r_cells else 0
        assert out[30 + dr, 30 + dc] == expected, (dr, dc)
        assert out[30 - dc, 30 - dr] == expected  # symmetric
    assert out[30, 30 + 13] == 0  # beyond the cell inflation radius
    # The vectorized formula agrees with the scalar one.
    ds = np.linspace(0.0, 0.6, 121)
    np.testing.assert_array_equal(inflation_cost(ds, inscribed, opts), [nav2_cost(d, inscribed) for d in ds])


def test_inflation_equals_exact_edt_reference_on_random_map() -> None:
    rng = np.random.default_rng(1)
    costs = np.zeros((300, 400), dtype=np.uint8)
    costs[rng.integers(0, 300, 300), rng.integers(0, 400, 300)] = LETHAL_OBSTACLE
    costs[150, 20:380] = LETHAL_OBSTACLE
    costs[10:60, 300:360] = NO_INFORMATION
    opts = InflationOptions(inflation_radius=0.4, cost_scaling_factor=5.0)
    out = inflate(costs, RES, 0.1, opts)
    d = ndimage.distance_transform_edt(costs != LETHAL_OBSTACLE) * RES
    r = cell_inflation_radius(RES, opts)
    ref = np.where(d <= r * RES + 1e-9, inflation_cost(d, 0.1, opts), 0).astype(np.uint8)
    expected = np.where(costs == NO_INFORMATION, np.where(ref >= 253, ref, 255), np.maximum(costs, ref))
    np.testing.assert_array_equal(out, expected)


def test_inflate_unknown_options() -> None:
    costs = np.full((21, 21), NO_INFORMATION, dtype=np.uint8)
    costs[10, 10] = LETHAL_OBSTACLE
    base = inflate(costs, RES, 0.1, InflationOptions())
    assert base[10, 12] == INSCRIBED_INFLATED_OBSTACLE  # d = 0.1 <= inscribed
    assert base[10, 15] == NO_INFORMATION  # unknown keeps 255 unless inflate_unknown
    more = inflate(costs, RES, 0.1, InflationOptions(inflate_unknown=True))
    assert more[10, 15] == nav2_cost(0.25, 0.1)
    costs2 = np.zeros((21, 21), dtype=np.uint8)
    costs2[0, :] = NO_INFORMATION
    around = inflate(costs2, RES, 0.1, InflationOptions())
    a = inflate(costs2, RES, 0.1, InflationOptions(inflate_around_unknown=True))
    assert a[3, 5] == nav2_cost(3 * RES, 0.1) and around[3, 5] == 0


def test_static_layer_interpretation() -> None:
    data = np.array([[-1, 0, 50], [99, 100, 65]], dtype=np.int8)
    grid = OccupancyGrid(GridGeometry(RES, 3, 2), data)
    out = static_costs(grid)
    np.testing.assert_array_equal(out, [[255, 0, 0], [0, 254, 0]])
    out = static_costs(grid, StaticLayerOptions(lethal_cost_threshold=65), track_unknown_space=False)
    np.testing.assert_array_equal(out, [[0, 0, 0], [254, 254, 254]])
    out = static_costs(grid, StaticLayerOptions(trinary_costmap=False))
    assert out[0, 2] == int(50 / 100 * 254) and out[1, 0] == int(99 / 100 * 254) and out[1, 1] == 254


def _empty_map(w: int = 100, h: int = 100) -> OccupancyGrid:
    return OccupancyGrid(GridGeometry(RES, w, h), np.zeros((h, w), dtype=np.int8))


def test_obstacle_layer_marks_and_clears() -> None:
    cm = Costmap2D.from_map(_empty_map(), CostmapOptions(use_inflation_layer=False))
    robot = Pose2D(1.0, 1.0, 0.0)
    cm.update(robot, np.array([[2.0, 1.02], [1.0, 2.52]]))
    c = cm.costmap()
    assert c.cost_at(np.array([[2.0, 1.02]]))[0] == LETHAL_OBSTACLE
    # 1.52 m away: marked (obstacle_max_range 2.5); the beam's cells are free.
    assert c.cost_at(np.array([[1.0, 2.52]]))[0] == LETHAL_OBSTACLE
    assert np.all(c.cost_at(np.column_stack((np.linspace(1.1, 1.9, 9), np.full(9, 1.02)))) == 0)
    # Out of marking range: not marked.
    far = Costmap2D.from_map(_empty_map(120, 120), CostmapOptions(use_inflation_layer=False))
    far.update(Pose2D(0.2, 0.2), np.array([[2.9, 0.21]]))
    assert far.costmap().cost_at(np.array([[2.9, 0.21]]))[0] == 0
    # The obstacle moved: a later beam through its cell clears it.
    cm.update(robot, np.array([[2.5, 1.02]]))
    c = cm.costmap()
    assert c.cost_at(np.array([[2.0, 1.02]]))[0] == 0
    assert c.cost_at(np.array([[2.5, 1.02]]))[0] == LETHAL_OBSTACLE
    # Non-finite points are ignored; beams without a return clear without marking.
    cm.update(robot, np.array([[np.nan, 1.0], [np.inf, 2.0]]), no_return_points_world=np.array([[1.0, 3.5]]))
    c = cm.costmap()
    assert (
        c.cost_at(np.array([[1.0, 2.52]]))[0] == 0
        and c.cost_at(np.array([[2.5, 1.02]]))[0] == LETHAL_OBSTACLE
    )
    # clear() forgets every observation.
    cm.clear()
    assert int(cm.costmap().costs.max()) == 0


def test_clearing_respects_raytrace_max_range_and_unknown_tracking() -> None:
    grid = OccupancyGrid(GridGeometry(RES, 200, 40), np.full((40, 200), -1, dtype=np.int8))
    cm = Costmap2D.from_map(grid, CostmapOptions(use_inflation_layer=False))
    origin = np.array([0.52, 1.02])
    cm.update(Pose2D(0.52, 1.02), np.array([[9.0, 1.02]]), origin)  # far return: clears to 3 m only
    c = cm.costmap()
    line = c.cost_at(np.column_stack((np.linspace(0.8, 3.4, 27), np.full(27, 1.02))))
    assert np.all(line == 0)
    assert c.cost_at(np.array([[3.7, 1.02]]))[0] == NO_INFORMATION
    assert c.cost_at(np.array([[9.0, 1.02]]))[0] == NO_INFORMATION


def test_global_update_is_incremental_and_consistent() -> None:
    rng = np.random.default_rng(5)
    data = np.zeros((160, 200), dtype=np.int8)
    data[rng.integers(0, 160, 100), rng.integers(0, 200, 100)] = 100
    grid = OccupancyGrid(GridGeometry(RES, 200, 160), data)
    opts = CostmapOptions(robot_radius=0.15)
    cm = Costmap2D.from_map(grid, opts)
    cm.costmap()
    a = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    pts = np.column_stack((5.0 + 1.5 * np.cos(a), 4.0 + 1.5 * np.sin(a)))
    cm.update(Pose2D(5.0, 4.0), pts)
    incremental = cm.costmap().costs
    # Recompute from scratch: static + obstacles, then inflation of the whole grid.
    master = static_costs(grid)
    obs = cm.obstacle_costs
    assert obs is not None
    take = (obs != NO_INFORMATION) & ((master == NO_INFORMATION) | (master < obs))  # Nav2 updateWithMax
    master[take] = obs[take]
    assert take.any()
    full = inflate(master, RES, 0.15, opts.inflation_layer)
    np.testing.assert_array_equal(incremental, full)


def test_rolling_window_follows_robot_and_keeps_obstacles() -> None:
    lc = Costmap2D.rolling(local_costmap_options(use_inflation_layer=False))
    assert lc.geometry.width == 60 and lc.geometry.height == 60
    lc.update(Pose2D(0.0, 0.0), np.array([[1.0, 0.0]]))
    assert lc.costmap().cost_at(np.array([[1.0, 0.0]]))[0] == LETHAL_OBSTACLE
    lc.update(Pose2D(0.53, 0.21))
    c = lc.costmap()
    ox, oy = c.geometry.origin.x, c.geometry.origin.y
    assert ox == pytest.approx(math.floor((0.53 - 1.5) / RES) * RES)
    assert oy == pytest.approx(math.floor((0.21 - 1.5) / RES) * RES)
    assert c.cost_at(np.array([[1.0, 0.0]]))[0] == LETHAL_OBSTACLE  # shifted with the window
    lc.update(Pose2D(5.0, 0.0))  # the obstacle left the window
    assert int(lc.costmap().costs.max()) == 0


def test_rolling_window_samples_static_map() -> None:
    data = np.zeros((100, 100), dtype=np.int8)
    data[:, 60] = 100  # wall at x = 3.0..3.05
    grid = OccupancyGrid(GridGeometry(RES, 100, 100), data)
    lc = Costmap2D.rolling(local_costmap_options(use_static_layer=True), Pose2D(2.5, 2.5), static_map=grid)
    c = lc.costmap()
    assert c.cost_at(np.array([[3.02, 2.5]]))[0] == LETHAL_OBSTACLE
    assert c.cost_at(np.array([[2.95, 2.5]]))[0] == INSCRIBED_INFLATED_OBSTACLE


def test_footprint_cost_vectorized() -> None:
    data = np.zeros((100, 100), dtype=np.int8)
    data[50, :] = 100  # wall along y = 2.5
    grid = OccupancyGrid(GridGeometry(RES, 100, 100), data)
    square = np.array([[0.15, 0.15], [-0.15, 0.15], [-0.15, -0.15], [0.15, -0.15]])
    inscribed, circumscribed = footprint_radii(square)
    assert inscribed == pytest.approx(0.15) and circumscribed == pytest.approx(math.hypot(0.15, 0.15))
    cm = Costmap2D.from_map(grid, CostmapOptions(footprint=tuple(map(tuple, square))))
    ys = np.array([1.0, 2.0, 2.3, 2.4, 2.6])
    poses = np.column_stack((np.full(5, 2.0), ys, np.zeros(5)))
    fc = cm.footprint_cost(poses)
    assert fc.shape == (5,)
    assert fc[0] == 0 and fc[3] == LETHAL_OBSTACLE and fc[4] == LETHAL_OBSTACLE
    assert 0 < fc[1] < INSCRIBED_INFLATED_OBSTACLE <= fc[2]
    # Rotating a square by 45 degrees brings its corners closer to the wall.
    rot = cm.footprint_cost(np.array([[2.0, 2.0, 0.0], [2.0, 2.0, math.pi / 4]]))
    assert rot[1] > rot[0]
    # Circular robot: centre cell cost.
    circ = Costmap2D.from_map(grid, CostmapOptions(robot_radius=0.2))
    np.testing.assert_array_equal(circ.footprint_cost(poses), circ.cost_at(poses[:, :2]))
    # Off the map reads unknown.
    assert circ.footprint_cost(np.array([-1.0, -1.0, 0.0]))[0] == NO_INFORMATION
    assert circle_footprint(0.2).shape == (16, 2)


def test_footprint_clearing() -> None:
    cm = Costmap2D.from_map(_empty_map(), CostmapOptions(use_inflation_layer=False, robot_radius=0.2))
    cm.update(Pose2D(1.0, 1.0), np.array([[1.05, 1.0], [1.5, 1.0]]))  # one return inside the robot
    assert cm.costmap().cost_at(np.array([[1.05, 1.0]]))[0] == 0
    assert cm.costmap().cost_at(np.array([[1.5, 1.0]]))[0] == LETHAL_OBSTACLE
    cm.update(Pose2D(1.5, 1.0))  # the robot drove onto the old return: its cell is cleared
    assert cm.costmap().cost_at(np.array([[1.5, 1.0]]))[0] == 0
    no_clear = Costmap2D.from_map(
        _empty_map(),
        CostmapOptions(
            use_inflation_layer=False, obstacle_layer=ObstacleLayerOptions(footprint_clearing_enabled=False)
        ),
    )
    no_clear.update(Pose2D(1.0, 1.0), np.array([[1.05, 1.0]]))
    no_clear.update(Pose2D(1.0, 1.0))
    assert no_clear.costmap().cost_at(np.array([[1.05, 1.0]]))[0] == LETHAL_OBSTACLE


def test_update_from_scan_uses_laser_pose_and_no_return_beams() -> None:
    grid = OccupancyGrid(GridGeometry(RES, 120, 120), np.full((120, 120), -1, dtype=np.int8))
    cm = Costmap2D.from_map(grid, CostmapOptions(use_inflation_layer=False))
    # Four beams: ahead 1 m, left no return, behind NaN, right below range_min.
    scan = LaserScan(
        stamp=0.0,
        angle_min=0.0,
        angle_increment=math.pi / 2,
        ranges=np.array([1.0, np.inf, np.nan, 0.05]),
        range_min=0.15,
        range_max=6.0,
    )
    robot = Pose2D(3.0, 3.0, math.pi / 2)  # facing +y
    cm.update_from_scan(robot, scan, laser_offset=Pose2D(0.1, 0.0, 0.0))
    c = cm.costmap()

    def at(dx: float, dy: float) -> int:  # cost at an offset from the laser (3.0, 3.1)
        return int(c.cost_at(np.array([[3.0 + dx, 3.1 + dy]]))[0])

    assert at(0.0, 1.0) == LETHAL_OBSTACLE  # ahead of the laser
    assert at(0.0, 0.5) == 0  # cleared on the way
    assert at(-2.5, 0.0) == 0  # no return: cleared to 3 m
    assert at(-3.2, 0.0) == NO_INFORMATION
    assert at(0.0, -1.0) == NO_INFORMATION  # NaN beam ignored


def test_compiled_obstacle_update_equals_the_numpy_path() -> None:
    from nav.costmap.obstacle_layer import ObstacleLayer

    rng = np.random.default_rng(9)
    geo = GridGeometry(RES, 70, 60, Pose2D(-1.05, 0.35, 0.0))
    for opts in (
        ObstacleLayerOptions(),
        ObstacleLayerOptions(raytrace_min_range=0.2, obstacle_min_range=0.3),
    ):
        a, b = ObstacleLayer(geo, opts, True), ObstacleLayer(geo, opts, True)
        for _ in range(6):
            origin = np.array([rng.uniform(-0.5, 2.5), rng.uniform(0.8, 3.0)])
            ang = rng.uniform(-np.pi, np.pi, 200)
            r = rng.uniform(0.05, 4.0, 200)
            pts = origin + r[:, None] * np.column_stack((np.cos(ang), np.sin(ang)))
            pts[:5] = np.nan
            far = origin + 5.0 * np.column_stack((np.cos(ang[:20]), np.sin(ang[:20])))
            assert a.update(pts, origin, far) == b._update_numpy(pts, origin, far)
            assert np.array_equal(a.costs, b.costs)


def test_sample_costs_whole_cell_shift_equals_cell_lookup() -> None:
    from nav.costmap.static_layer import sample_costs

    rng = np.random.default_rng(2)
    static = rng.integers(0, 256, (80, 120)).astype(np.uint8)
    sg = GridGeometry(RES, 120, 80, Pose2D(-1.0, -2.35, 0.0))
    for _ in range(40):
        ox, oy = math.floor(rng.uniform(-4, 6) / RES) * RES, math.floor(rng.uniform(-5, 3) / RES) * RES
        tg = GridGeometry(RES, 60, 50, Pose2D(ox, oy, 0.0))
        rr, cc = np.mgrid[0:50, 0:60]
        rows, cols = sg.world_to_cell(tg.cell_to_world(rr.ravel(), cc.ravel()))
        inside = sg.in_bounds(rows, cols)
        want = np.full(rows.shape, NO_INFORMATION, dtype=np.uint8)
        want[inside] = static[rows[inside], cols[inside]]
        assert np.array_equal(sample_costs(static, sg, tg), want.reshape(50, 60))


def test_cells_in_polygon_equals_point_in_polygon_of_cell_centres() -> None:
    from nav.costmap.footprint import cells_in_polygon
    from robot.sim.world import points_in_polygon

    rng = np.random.default_rng(6)
    geo = GridGeometry(RES, 40, 40, Pose2D(0.3, -0.2, 0.0))
    for _ in range(30):
        ang = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(3, 9)))
        poly = np.array([1.3, 0.8]) + rng.uniform(0.1, 0.6, ang.size)[:, None] * np.column_stack(
            (np.cos(ang), np.sin(ang))
        )
        rows, cols = cells_in_polygon(geo, poly)
        rr, cc = np.mgrid[0:40, 0:40]
        inside = points_in_polygon(geo.cell_to_world(rr.ravel(), cc.ravel()), poly)
        want = set(zip(rr.ravel()[inside].tolist(), cc.ravel()[inside].tolist(), strict=True))
        assert set(zip(rows.tolist(), cols.tolist(), strict=True)) == want


def test_in_mapped_obstacle_reads_the_static_map_only() -> None:
    grid = _empty_map()
    grid.data[:, 50] = 100  # a wall along x = 2.5 m
    skid = ((0.12, 0.1), (-0.12, 0.1), (-0.12, -0.1), (0.12, -0.1))
    cm = Costmap2D.from_map(grid, CostmapOptions(footprint=skid))
    assert cm.in_mapped_obstacle(Pose2D(2.45, 1.0, 0.0))  # the front edge is in the wall
    assert cm.in_mapped_obstacle(Pose2D(2.45, 1.0, math.pi / 2))  # and a side, turned
    assert not cm.in_mapped_obstacle(Pose2D(2.3, 1.0, 0.0))  # inflated cost, but clear of it
    cm.update(Pose2D(1.0, 1.0), np.array([[1.5, 1.0]]))  # a sensor mark is not the map
    assert not cm.in_mapped_obstacle(Pose2D(1.5, 1.0, 0.0))
    assert not Costmap2D(grid.geometry, CostmapOptions(footprint=skid)).in_mapped_obstacle(Pose2D(2.5, 1.0))
