"""Zone polygons: validation, rasterization over cell centres, and the keepout filter in the layered
costmaps (global and rolling) and the planner (issue 19)."""

from __future__ import annotations

import numpy as np
import pytest

from nav.costmap import Costmap2D, local_costmap_options
from nav.costmap.filter_layer import PolygonError, points_in_polygon, rasterize_polygons, validate_polygon
from nav.planning import make_planner
from nav.types import LETHAL_OBSTACLE, GridGeometry, OccupancyGrid, Pose2D

GEO = GridGeometry(0.05, 200, 160, Pose2D(-2.0, -1.0, 0.0))  # 10 x 8 m


def star(rng: np.random.Generator, n: int, cx: float, cy: float, r: float) -> np.ndarray:
    """A random simple polygon: vertices at increasing angles around a centre (star-shaped)."""
    a = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = rng.uniform(0.3 * r, r, n)
    return np.column_stack((cx + rad * np.cos(a), cy + rad * np.sin(a)))


def cell_centres(geo: GridGeometry) -> np.ndarray:
    rr, cc = np.mgrid[0 : geo.height, 0 : geo.width]
    return geo.cell_to_world(rr.ravel(), cc.ravel())


@pytest.mark.parametrize("seed", range(6))
def test_rasterization_is_the_even_odd_test_at_every_cell_centre(seed: int) -> None:
    rng = np.random.default_rng(seed)
    geo = GEO if seed % 2 == 0 else GridGeometry(0.05, 120, 90, Pose2D(1.0, 2.0, 0.6))  # rotated map
    w, h = geo.size_m
    centre = geo.origin.transform_points(np.array([[w / 2, h / 2]]))[0]
    poly = star(rng, int(rng.integers(3, 40)), centre[0], centre[1], 0.45 * min(w, h))
    mask = rasterize_polygons([poly], geo)
    expected = points_in_polygon(cell_centres(geo), poly).reshape(geo.height, geo.width)
    assert mask.sum() > 50
    assert np.array_equal(mask, expected)


def test_rasterization_of_an_axis_aligned_square_is_exact_in_cells() -> None:
    # square from (0, 0) to (1, 0.5) in a grid with origin (-2, -1) at 5 cm: cols 40..59, rows 20..29
    mask = rasterize_polygons([np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]])], GEO)
    rows, cols = np.nonzero(mask)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (20, 29, 40, 59)
    assert mask.sum() == 10 * 20


def test_polygons_partly_off_the_grid_are_clipped() -> None:
    poly = np.array([[-5.0, -5.0], [0.0, -5.0], [0.0, 0.0], [-5.0, 0.0]])
    mask = rasterize_polygons([poly], GEO)
    expected = points_in_polygon(cell_centres(GEO), poly).reshape(GEO.height, GEO.width)
    assert np.array_equal(mask, expected) and mask[0, 0] and not mask[-1, -1]


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ([[0, 0], [1, 0]], "at least 3 vertices"),
        ([[0, 0], [1, 0], [0, 0]], "at least 3 vertices"),  # closing vertex dropped: 2 left
        ([[0, 0], [1, 1], [1, 0], [0, 1]], "intersects itself"),  # bow tie
        ([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]], "intersects itself"),  # a vertex on an edge
        ([[0, 0], [1, 1], [2, 2]], "no area"),
        ([[0, 0], [1, 0], [1, 0], [0, 1]], "consecutive vertices"),
        ([[0, 0], [9.0, 0], [9.0, 1]], "off the map"),
        ([[0, 0], [1, 0], [float("nan"), 1]], "finite"),
        ([1, 2, 3], "a polygon is a list"),
    ],
)
def test_invalid_polygons_are_refused_with_the_reason(points, message: str) -> None:
    with pytest.raises(PolygonError, match=message):
        validate_polygon(points, GEO)


def test_valid_polygon_drops_a_repeated_closing_vertex() -> None:
    p = validate_polygon([[0, 0], [1, 0], [1, 1], [0, 0]], GEO)
    assert p.shape == (3, 2)


def free_map(geo: GridGeometry) -> OccupancyGrid:
    return OccupancyGrid(geo, np.zeros((geo.height, geo.width), dtype=np.int8))


def test_incremental_keepout_equals_a_costmap_built_with_it() -> None:
    rng = np.random.default_rng(7)
    grid = free_map(GEO)
    grid.data[rng.random(grid.data.shape) < 0.01] = 100
    cm = Costmap2D.from_map(grid)
    cm.costmap()
    mask = rasterize_polygons([star(rng, 12, 3.0, 3.0, 1.5)], GEO)
    cm.set_keepout(mask)
    fresh = Costmap2D.from_map(grid)
    fresh.set_keepout(mask)
    fresh._dirty = (0, GEO.height, 0, GEO.width)  # the whole grid, not the changed region
    assert np.array_equal(cm.costmap().costs, fresh.costmap().costs)
    assert (cm.costmap().costs[mask] == LETHAL_OBSTACLE).all()
    cm.set_keepout(None)  # removed: back to the map alone
    assert np.array_equal(cm.costmap().costs, Costmap2D.from_map(grid).costmap().costs)


def test_the_planner_goes_around_a_keepout_zone() -> None:
    geo = GridGeometry(0.05, 160, 100, Pose2D(0.0, 0.0, 0.0))  # 8 x 5 m, free
    cm = Costmap2D.from_map(free_map(geo))
    start, goal = Pose2D(1.0, 2.5, 0.0), Pose2D(7.0, 2.5, 0.0)
    planner = make_planner("astar")
    straight = planner.plan(cm.costmap(), start, goal)
    assert straight.length < 6.2
    zone = np.array([[3.5, 0.8], [4.5, 0.8], [4.5, 4.9], [3.5, 4.9]])  # a gap below y = 0.8 only
    cm.set_keepout(rasterize_polygons([zone], geo))
    around = planner.plan(cm.costmap(), start, goal)
    xy = around.poses[:, :2]
    assert not points_in_polygon(xy, zone).any()
    assert xy[:, 1].min() < 0.8 and around.length > straight.length + 1.0


def test_the_rolling_window_samples_the_keepout_mask() -> None:
    grid = free_map(GEO)
    zone = np.array([[0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0]])
    mask = rasterize_polygons([zone], GEO)
    local = Costmap2D.rolling(local_costmap_options(robot_radius=0.1), Pose2D(0.0, 0.5, 0.0), grid)
    local.set_keepout(mask, GEO)
    costs = local.cost_at(np.array([[0.75, 0.5], [-0.75, 0.5]]))
    assert costs[0] == LETHAL_OBSTACLE and costs[1] < LETHAL_OBSTACLE
    local.update(Pose2D(0.3, 0.5, 0.0))  # the window moves: the mask moves with the map
    assert local.cost_at(np.array([[0.75, 0.5]]))[0] == LETHAL_OBSTACLE
