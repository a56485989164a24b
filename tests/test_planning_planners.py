"""Planner behaviour: typed errors, goal tolerance, costs, smoothing, headings, real maps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.datasets import ROS_MAPS
from nav.costmap import Costmap2D, CostmapOptions
from nav.planning import (
    AStarPlanner,
    DijkstraPlanner,
    GlobalPlanner,
    GoalOccupied,
    GoalOutsideMap,
    NoValidPathFound,
    PlannerError,
    PlannerOptions,
    PlannerTimedOut,
    StartOccupied,
    StartOutsideMap,
    make_planner,
    nearest_free_pose,
)
from nav.types import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    Costmap,
    GridGeometry,
    OccupancyGrid,
    Pose2D,
)

RES = 0.05
PLANNERS = [AStarPlanner, DijkstraPlanner]
WILLOW = ROS_MAPS / "navigation_stage/willow-full-0.05.yaml"


def room(w: int = 120, h: int = 80) -> Costmap:
    """A walled room with an internal wall (gap at the top) splitting it, inflated for r = 0.1 m."""
    data = np.zeros((h, w), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[: h - 20, w // 2] = 100
    grid = OccupancyGrid(GridGeometry(RES, w, h, Pose2D(-1.0, -0.5, 0.0)), data)
    return Costmap2D.from_map(grid, CostmapOptions(robot_radius=0.1)).costmap()


def samples_along(path: np.ndarray, step: float = 0.01) -> np.ndarray:
    seg = np.diff(path[:, :2], axis=0)
    n = np.maximum(np.ceil(np.hypot(*seg.T) / step).astype(int), 1)
    pts = [path[i, :2] + seg[i] * (np.arange(n[i])[:, None] / n[i]) for i in range(len(seg))]
    return np.vstack([*pts, path[-1:, :2]])


@pytest.mark.parametrize("cls", PLANNERS)
def test_plan_around_wall_never_touches_lethal_or_inscribed(cls: type) -> None:
    cm = room()
    planner = cls()
    assert isinstance(planner, GlobalPlanner)
    start, goal = Pose2D(0.0, 0.0, 0.0), Pose2D(4.0, 0.0, 1.0)
    path = planner.plan(cm, start, goal)
    p = path.poses
    assert p[0, :2] == pytest.approx([0.0, 0.0]) and p[-1, :2] == pytest.approx([4.0, 0.0])
    assert p[-1, 2] == pytest.approx(1.0)  # the goal heading
    costs = cm.cost_at(samples_along(p))
    assert costs.max() < INSCRIBED_INFLATED_OBSTACLE
    # Detour over the wall top (wall ends 1 m below the room's top).
    assert p[:, 1].max() > 2.0
    # Headings follow the path direction.
    d = np.diff(p[:, :2], axis=0)
    mid = np.arctan2(d[:-1, 1] + d[1:, 1], d[:-1, 0] + d[1:, 0])
    err = np.abs((p[1:-1, 2] - mid + np.pi) % (2 * np.pi) - np.pi)
    assert err.max() < 0.3


def test_cost_weight_keeps_path_away_from_walls() -> None:
    cm = room()
    start, goal = Pose2D(0.0, 0.0), Pose2D(4.0, 0.0)
    plain = AStarPlanner(PlannerOptions(cost_travel_multiplier=0.0, smooth_path=False)).plan(cm, start, goal)
    careful = AStarPlanner(PlannerOptions(cost_travel_multiplier=3.0, smooth_path=False)).plan(
        cm, start, goal
    )
    assert careful.length >= plain.length
    c_plain = cm.cost_at(plain.poses[:, :2]).astype(float).mean()
    c_careful = cm.cost_at(careful.poses[:, :2]).astype(float).mean()
    assert c_careful < c_plain


def test_smoothing_shortens_and_stays_in_cost() -> None:
    cm = room()
    start, goal = Pose2D(0.0, 0.0), Pose2D(4.0, 0.0)
    raw = AStarPlanner(PlannerOptions(smooth_path=False)).plan(cm, start, goal)
    smooth = AStarPlanner(PlannerOptions(smooth_path=True)).plan(cm, start, goal)
    assert len(raw) == len(smooth)
    assert smooth.length < raw.length
    # No smoothed point sits in a costlier cell than its grid-path counterpart.
    assert np.all(cm.cost_at(smooth.poses[:, :2]) <= np.maximum(cm.cost_at(raw.poses[:, :2]), 0))
    turn = np.abs(np.diff(np.unwrap(smooth.poses[:-1, 2])))
    turn_raw = np.abs(np.diff(np.unwrap(raw.poses[:-1, 2])))
    assert turn.sum() < turn_raw.sum()


@pytest.mark.parametrize("cls", PLANNERS)
def test_typed_errors(cls: type) -> None:
    cm = room()
    planner = cls(PlannerOptions(tolerance=0.1))
    free = Pose2D(0.0, 0.0)
    with pytest.raises(StartOccupied):
        planner.plan(cm, Pose2D(-1.0 + 0.01, 0.0), free)  # in the outer wall
    with pytest.raises(StartOutsideMap):
        planner.plan(cm, Pose2D(-5.0, 0.0), free)
    with pytest.raises(GoalOutsideMap):
        planner.plan(cm, free, Pose2D(100.0, 0.0))
    with pytest.raises(GoalOutsideMap):
        planner.plan(cm, free, Pose2D(math.nan, 0.0))
    with pytest.raises(StartOutsideMap):
        planner.plan(cm, Pose2D(0.0, math.inf), free)
    with pytest.raises(GoalOccupied):
        planner.plan(cm, free, Pose2D(2.0 + 0.01, 0.0))  # in the internal wall, 0.1 m tolerance
    # An enclosed free pocket: traversable goal, unreachable.
    costs = cm.costs.copy()
    costs[30:41, 90:101] = LETHAL_OBSTACLE
    costs[32:39, 92:99] = 0
    boxed = Costmap(cm.geometry, costs)
    pocket = boxed.geometry.cell_to_world(np.array([35]), np.array([95]))[0]
    with pytest.raises(NoValidPathFound) as info:
        planner.plan(boxed, free, Pose2D(*pocket))
    assert isinstance(info.value, PlannerError)


def test_goal_tolerance_plans_to_nearest_reachable_cell() -> None:
    cm = room()
    start = Pose2D(0.0, 0.0)
    goal = Pose2D(2.0 + 0.01, 0.0, 0.5)  # inside the internal wall
    path, stats = AStarPlanner(PlannerOptions(tolerance=0.3)).plan_with_stats(cm, start, goal)
    assert not stats.goal_reached_exactly
    end = path.poses[-1]
    assert math.hypot(end[0] - goal.x, end[1] - goal.y) <= 0.3 + 1e-9
    assert cm.cost_at(end[None, :2])[0] < INSCRIBED_INFLATED_OBSTACLE
    assert end[2] == pytest.approx(0.5)
    # Unreachable pocket but a reachable cell within tolerance outside its wall.
    costs = cm.costs.copy()
    costs[30:41, 90:101] = LETHAL_OBSTACLE
    costs[33:38, 93:98] = 0
    boxed = Costmap(cm.geometry, costs)
    pocket = boxed.geometry.cell_to_world(np.array([35]), np.array([95]))[0]
    path = DijkstraPlanner(PlannerOptions(tolerance=0.5)).plan(boxed, start, Pose2D(*pocket))
    assert math.hypot(*(path.poses[-1, :2] - pocket)) <= 0.5
    assert boxed.cost_at(path.poses[-1:, :2])[0] < INSCRIBED_INFLATED_OBSTACLE


def test_unknown_space_option() -> None:
    costs = np.zeros((40, 100), dtype=np.uint8)
    costs[:, 50] = NO_INFORMATION
    cm = Costmap(GridGeometry(RES, 100, 40), costs)
    start, goal = Pose2D(0.5, 1.0), Pose2D(4.5, 1.0)
    assert AStarPlanner(PlannerOptions(allow_unknown=True)).plan(cm, start, goal).length > 3.9
    with pytest.raises(NoValidPathFound):
        AStarPlanner(PlannerOptions(allow_unknown=False, tolerance=0.0)).plan(cm, start, goal)


def test_no_corner_cutting() -> None:
    costs = np.zeros((5, 5), dtype=np.uint8)
    costs[2, 1] = LETHAL_OBSTACLE  # blocks the side of the diagonal (1,1) -> (2,2)
    cm = Costmap(GridGeometry(1.0, 5, 5), costs)
    opts = PlannerOptions(cost_travel_multiplier=0.0, smooth_path=False, tolerance=0.0)
    _, stats = AStarPlanner(opts).plan_with_stats(cm, Pose2D(1.5, 1.5), Pose2D(2.5, 2.5))
    assert stats.search_cost == pytest.approx(2.0)  # two straight steps, not one sqrt2 diagonal
    costs[2, 1] = 0
    _, stats = AStarPlanner(opts).plan_with_stats(
        Costmap(cm.geometry, costs), Pose2D(1.5, 1.5), Pose2D(2.5, 2.5)
    )
    assert stats.search_cost == pytest.approx(math.sqrt(2.0))


def test_same_cell_and_start_in_inflation() -> None:
    cm = room()
    p = AStarPlanner().plan(cm, Pose2D(0.0, 0.0), Pose2D(0.01, 0.01, 2.0))
    assert len(p) == 2 and p.poses[-1, 2] == pytest.approx(2.0)
    # A start inside the inscribed zone (not lethal) may leave it.
    start = Pose2D(2.0 - 0.08, 0.0)
    assert cm.cost_at(np.array([[start.x, start.y]]))[0] == INSCRIBED_INFLATED_OBSTACLE
    assert AStarPlanner().plan(cm, start, Pose2D(0.0, 0.0)).length > 1.5


def test_timeout_and_iteration_limit() -> None:
    cm = Costmap(GridGeometry(RES, 1500, 1500), np.zeros((1500, 1500), dtype=np.uint8))
    with pytest.raises(PlannerTimedOut):
        DijkstraPlanner(PlannerOptions(max_planning_time=0.0)).plan(cm, Pose2D(0.1, 0.1), Pose2D(74.0, 74.0))
    with pytest.raises(NoValidPathFound):
        DijkstraPlanner(PlannerOptions(max_iterations=1000, tolerance=0.0)).plan(
            cm, Pose2D(0.1, 0.1), Pose2D(74.0, 74.0)
        )


def test_nearest_free_pose() -> None:
    cm = room()
    inside_wall = Pose2D(2.01, 0.0, 0.7)
    p = nearest_free_pose(cm, inside_wall, 0.5)
    assert p is not None and p.theta == 0.7
    assert cm.cost_at(np.array([[p.x, p.y]]))[0] < INSCRIBED_INFLATED_OBSTACLE
    assert p.x == pytest.approx(-1.0 + 57.5 * RES)  # first cell beyond the wall's inscribed band
    assert nearest_free_pose(cm, Pose2D(0.0, 0.0), 0.5) == Pose2D(0.0, 0.0)
    assert nearest_free_pose(cm, inside_wall, 0.05) is None


def test_make_planner() -> None:
    assert isinstance(make_planner("astar"), AStarPlanner)
    assert isinstance(make_planner("dijkstra"), DijkstraPlanner)
    with pytest.raises(ValueError):
        make_planner("rrt")


@pytest.mark.skipif(not WILLOW.exists(), reason="willow map not available")
def test_willow_corner_to_corner() -> None:
    from maps.mapio import load_map_yaml

    grid = load_map_yaml(WILLOW)
    cm = Costmap2D.from_map(grid, CostmapOptions(robot_radius=0.2)).costmap()
    # Opposite corners of the floor's main free component.
    start = nearest_free_pose(cm, Pose2D(3.675, 1.575), 0.5)
    goal = nearest_free_pose(cm, Pose2D(50.075, 46.675), 0.5)
    assert start is not None and goal is not None
    known_only = PlannerOptions(allow_unknown=False)
    a, sa = AStarPlanner(known_only).plan_with_stats(cm, start, goal)
    d, sd = DijkstraPlanner(known_only).plan_with_stats(cm, start, goal)
    assert sa.goal_reached_exactly and sd.goal_reached_exactly
    assert sa.search_cost == pytest.approx(sd.search_cost, rel=1e-9)
    assert sa.expansions < sd.expansions
    for path in (a, d):
        assert cm.cost_at(samples_along(path.poses)[1:-1]).max() < INSCRIBED_INFLATED_OBSTACLE
    assert a.length > math.hypot(goal.x - start.x, goal.y - start.y)


def test_final_approach_orientation() -> None:
    cm = room()
    opts = PlannerOptions(use_final_approach_orientation=True)
    p = AStarPlanner(opts).plan(cm, Pose2D(0.0, 0.0), Pose2D(1.0, 1.0, -2.0)).poses
    d = p[-1, :2] - p[-2, :2]
    assert p[-1, 2] == pytest.approx(math.atan2(d[1], d[0]))
