"""nav.exploration: frontier cells, clustering, the distance field, selection and the blacklist."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.costmap import Costmap2D, CostmapOptions
from nav.exploration import (
    FrontierExplorer,
    FrontierOptions,
    distance_field,
    frontier_mask,
    goal_pose,
)
from nav.types import Costmap, GridGeometry, OccupancyGrid, Pose2D

RES = 0.05


def _grid(data: np.ndarray) -> OccupancyGrid:
    h, w = data.shape
    return OccupancyGrid(GridGeometry(RES, w, h, Pose2D()), data.astype(np.int8))


def _costmap(grid: OccupancyGrid) -> Costmap:
    opts = CostmapOptions(robot_radius=0.1, use_obstacle_layer=False)
    return Costmap2D.from_map(grid, opts).costmap()


def _walled_left_known(rows: int, cols: int = 130, known_to: int = 45) -> np.ndarray:
    """A room ``rows`` x ``cols`` cells with 5-cell walls on three sides (the east end open),
    known free up to column ``known_to``, unknown beyond."""
    data = np.full((rows, cols), -1, dtype=np.int8)
    data[0:5, :] = 100
    data[rows - 5 : rows, :] = 100
    data[:, 0:5] = 100
    data[5 : rows - 5, 5:known_to] = 0
    return data


def _corridor() -> np.ndarray:
    """A 6 x 1 m corridor (walls around), its left 2 m known free, the rest unknown."""
    return _walled_left_known(30)


def _walled(n: int = 12) -> np.ndarray:
    data = np.full((n, n), 100, dtype=np.int8)
    data[1:-1, 1:-1] = 0
    return data


def test_frontier_cells_are_free_cells_next_to_unknown():
    data = _walled()
    data[1:-1, 7:-1] = -1
    mask = frontier_mask(_grid(data))
    assert mask[1:-1, 6].all()  # the free column touching the unknown
    assert not mask[:, :6].any()
    assert not mask[:, 7:].any()  # unknown and occupied cells are never frontier cells


def test_occupied_cells_next_to_unknown_are_not_frontiers():
    data = _walled()
    data[1:-1, 6] = 100  # a wall between free and unknown
    data[1:-1, 7:-1] = -1
    assert not frontier_mask(_grid(data)).any()


def test_distance_field_grows_with_travel_and_stops_at_walls():
    data = np.zeros((40, 40), dtype=np.int8)
    data[:, 20] = 100  # a wall splitting the room
    grid = _grid(data)
    cm = _costmap(grid)
    d = distance_field(cm, Pose2D(0.25, 1.0), cost_travel_multiplier=0.0)
    geo = grid.geometry
    r, c = geo.world_to_cell(np.array([[0.25, 1.0], [0.75, 1.0], [1.5, 1.0]]))
    assert d[r[0], c[0]] == 0.0
    assert d[r[1], c[1]] == pytest.approx(0.5, abs=1e-6)  # 10 cells straight on
    assert math.isinf(d[r[2], c[2]])  # behind the wall: unreachable


def test_the_corridor_frontier_is_chosen_and_its_goal_is_free_and_reachable():
    grid = _grid(_corridor())
    cm = _costmap(grid)
    rep = FrontierExplorer().find(grid, cm, Pose2D(0.8, 0.75))
    assert len(rep.frontiers) == 1
    f = rep.chosen
    assert f is not None and f.goal is not None
    assert f.length == pytest.approx(20 * RES)
    assert 2.1 < f.goal[0] < 2.3  # the last known column
    r, c = grid.geometry.world_to_cell(np.array([f.goal]))
    assert cm.costs[r[0], c[0]] < 253
    assert rep.free_area_m2 == pytest.approx(20 * 40 * RES * RES)


def test_a_nearer_frontier_wins_over_a_far_one_of_the_same_size():
    data = np.full((30, 200), 100, dtype=np.int8)
    data[5:25, 5:195] = 0
    data[5:25, 5:8] = -1  # unknown at both ends of a long room
    data[5:25, 192:195] = -1
    grid = _grid(data)
    cm = _costmap(grid)
    rep = FrontierExplorer().find(grid, cm, Pose2D(2.0, 0.75))
    assert len(rep.reachable) == 2
    assert rep.chosen is not None and rep.chosen.goal is not None and rep.chosen.goal[0] < 1.0
    # from the other end the other frontier wins
    rep = FrontierExplorer().find(grid, cm, Pose2D(8.0, 0.75))
    assert rep.chosen is not None and rep.chosen.goal is not None and rep.chosen.goal[0] > 9.0


def test_a_bigger_frontier_wins_when_travel_is_equal():
    data = np.full((60, 60), 100, dtype=np.int8)
    data[5:55, 5:55] = 0
    data[5:55, 5:7] = -1  # a 2.5 m frontier on the left
    data[25:35, 53:55] = -1  # a 0.5 m one on the right, in a wall gap
    data[5:25, 53:55] = 100
    data[35:55, 53:55] = 100
    grid = _grid(data)
    rep = FrontierExplorer().find(grid, _costmap(grid), Pose2D(1.5, 1.5))
    assert rep.chosen is not None and rep.chosen.goal is not None and rep.chosen.goal[0] < 1.0


def test_small_frontiers_are_ignored():
    data = np.zeros((40, 40), dtype=np.int8)
    data[:, 0:3] = 100
    data[:, 37:] = 100
    data[0:3, :] = 100
    data[37:, :] = 100
    data[20, 20] = -1  # one unknown cell in the room: a frontier of 8 cells (0.4 m)... too small
    grid = _grid(data)
    opts = FrontierOptions(min_frontier_size=0.5)
    rep = FrontierExplorer(opts).find(grid, _costmap(grid), Pose2D(0.5, 0.5))
    assert rep.frontiers == [] and rep.chosen is None
    assert rep.frontier_cells == 8


def test_a_frontier_behind_a_wall_is_unreachable_and_not_chosen():
    data = np.full((40, 80), 100, dtype=np.int8)
    data[5:35, 5:35] = 0  # the robot's room, closed
    data[5:35, 45:75] = 0  # a room behind a wall with an unknown patch
    data[15:25, 60:70] = -1
    grid = _grid(data)
    rep = FrontierExplorer().find(grid, _costmap(grid), Pose2D(1.0, 1.0))
    assert len(rep.frontiers) == 1
    assert not rep.frontiers[0].reachable and rep.chosen is None


def test_failed_goals_are_blacklisted():
    grid = _grid(_corridor())
    cm = _costmap(grid)
    ex = FrontierExplorer()
    first = ex.find(grid, cm, Pose2D(0.8, 0.75)).chosen
    assert first is not None and first.goal is not None
    ex.mark_failed(first.goal)
    rep = ex.find(grid, cm, Pose2D(0.8, 0.75))
    assert rep.chosen is None and rep.blacklisted == 1
    ex.clear_blacklist()
    assert ex.find(grid, cm, Pose2D(0.8, 0.75)).chosen is not None


def test_a_frontier_too_close_to_walls_gets_a_goal_nearby():
    # a narrow 0.2 m slot of unknown in a wall: its frontier cells are all inscribed for the robot
    data = np.full((40, 60), 100, dtype=np.int8)
    data[5:35, 5:40] = 0
    data[18:22, 40:60] = -1  # unknown beyond a 0.2 m slot
    data[18:22, 38:40] = 0
    grid = _grid(data)
    cm = _costmap(grid)
    rep = FrontierExplorer(FrontierOptions(min_frontier_size=0.1)).find(grid, cm, Pose2D(0.5, 1.0))
    assert rep.chosen is not None and rep.chosen.goal is not None
    r, c = grid.geometry.world_to_cell(np.array([rep.chosen.goal]))
    assert cm.costs[r[0], c[0]] < 253
    assert math.dist(rep.chosen.goal, rep.chosen.centroid) <= 0.6 + 0.1


def test_mismatched_costmap_is_refused():
    grid = _grid(_corridor())
    other = Costmap(GridGeometry(RES, 10, 10, Pose2D()), np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match="one geometry"):
        FrontierExplorer().find(grid, other, Pose2D(0.8, 0.75))


def test_goal_pose_faces_away_from_the_robot():
    p = goal_pose((2.0, 1.0), Pose2D(1.0, 1.0, 2.0))
    assert (p.x, p.y) == (2.0, 1.0) and p.theta == pytest.approx(0.0)


def test_free_cells_on_the_map_edge_border_the_unseen():
    # a SLAM map ends where the rays ended: its free edge cells are frontiers
    data = np.zeros((10, 10), dtype=np.int8)
    data[:, 0] = 100
    mask = frontier_mask(_grid(data))
    assert mask[0, 1:].all() and mask[-1, 1:].all() and mask[:, -1].all()
    assert not mask[1:-1, 1:-1].any() and not mask[:, 0].any()


def test_cells_seen_free_once_count_as_free():
    # a live SLAM map marks a cell seen free by one scan at 40: already a place to go
    data = np.full((12, 12), -1, dtype=np.int8)
    data[:, :6] = 40
    data[0, :6] = 70  # occupied (>= 65) is never free
    mask = frontier_mask(_grid(data))
    assert mask[1:-1, 5].all() and not mask[0].any()


def test_a_frontier_the_robot_stands_at_is_reported_unobservable():
    grid = _grid(_corridor())
    cm = _costmap(grid)
    first = FrontierExplorer().find(grid, cm, Pose2D(0.8, 0.75)).chosen
    assert first is not None and first.goal is not None
    at = Pose2D(first.goal[0] - 0.1, first.goal[1], 0.0)
    rep = FrontierExplorer().find(grid, cm, at)
    assert rep.chosen is None and rep.unobservable == [first.goal]


def test_goals_keep_off_the_walls_when_the_frontier_allows():
    data = _corridor()
    grid = _grid(data)
    cm = _costmap(grid)
    robot = Pose2D(0.8, 0.4)  # close to a wall: by travel alone the goal would hug it (cost 92)
    opts = FrontierOptions(goal_max_cost=50, cost_travel_multiplier=0.0)
    rep = FrontierExplorer(opts).find(grid, cm, robot)
    assert rep.chosen is not None and rep.chosen.goal is not None
    r, c = grid.geometry.world_to_cell(np.array([rep.chosen.goal]))
    assert cm.costs[r[0], c[0]] <= 50


def _room_half_known() -> np.ndarray:
    """A 6 x 4 m room (walls around), its left 2 m known free: one 3.5 m frontier across it."""
    return _walled_left_known(90)


def test_a_failed_goal_bans_its_cells_not_the_whole_frontier():
    # office:1 ended "complete" at 57.7 % with rooms behind frontiers dropped whole after one goal
    # on them failed; the rest of a long frontier is still a goal
    grid = _grid(_room_half_known())
    cm = _costmap(grid)
    ex = FrontierExplorer()
    robot = Pose2D(0.8, 2.2)
    first = ex.find(grid, cm, robot).chosen
    assert first is not None and first.goal is not None
    ex.mark_failed(first.goal)
    rep = ex.find(grid, cm, robot)
    assert rep.chosen is not None and rep.chosen.goal is not None
    assert rep.chosen.length == first.length  # the same frontier
    assert math.dist(rep.chosen.goal, first.goal) > ex.options.blacklist_radius
    assert rep.blacklisted == 0


def test_forgiven_places_are_goals_again_until_they_fail_max_attempts_times():
    grid = _grid(_corridor())
    cm = _costmap(grid)
    robot = Pose2D(0.8, 0.75)
    ex = FrontierExplorer(FrontierOptions(max_attempts=2))
    goal = ex.find(grid, cm, robot).chosen.goal
    ex.mark_failed(goal)
    assert ex.find(grid, cm, robot).chosen is None  # the whole 1 m frontier is near the failed goal
    assert ex.forgive() == 1
    again = ex.find(grid, cm, robot).chosen
    assert again is not None and math.dist(again.goal, goal) <= ex.options.blacklist_radius
    ex.mark_failed(again.goal)  # a second failure at the same place
    assert ex.attempts == [2] and ex.find(grid, cm, robot).chosen is None
    assert ex.forgive() == 0  # given up for good
    assert ex.find(grid, cm, robot).chosen is None


def _room_with_patch() -> np.ndarray:
    """The 6 x 4.5 m room half known (a 4 m frontier at its east side) and an unknown 0.75 x 0.5 m
    patch in its known part (a second, smaller frontier around it)."""
    data = _walled_left_known(90)
    data[60:75, 15:25] = -1
    return data


def test_an_unobservable_goal_bans_its_whole_frontier():
    # office:1 shuttled between gaps in its outer wall: a circle around each unobservable goal left
    # the gap's next cell a goal, and each gap was visited 2-4 times
    grid = _grid(_room_with_patch())
    cm = _costmap(grid)
    ex = FrontierExplorer()
    rep = ex.find(grid, cm, Pose2D(2.1, 2.2))  # at the east frontier, which it does not see past
    assert len(rep.unobservable) == 1 and len(rep.unobservable_cells) == 1
    east = rep.unobservable_cells[0]
    assert len(east) * RES > 4 * ex.options.blacklist_radius  # the frontier is longer than the circle
    for goal, cells in zip(rep.unobservable, rep.unobservable_cells, strict=True):
        ex.mark_failed(goal, cells)
    # a step back: without its cells banned, the long east frontier would be the best pick again
    nxt = ex.find(grid, cm, Pose2D(1.5, 2.2))
    assert nxt.chosen is not None and nxt.chosen.goal is not None
    assert np.hypot(east[:, 0] - nxt.chosen.goal[0], east[:, 1] - nxt.chosen.goal[1]).min() > 0.5
    assert nxt.chosen.centroid[1] > 2.9  # the patch's frontier
    assert nxt.blacklisted == 1 and ex.attempts == [1]
    # a failure on another cell of that frontier is another attempt at the same place
    ex.mark_failed((float(east[-1, 0]), float(east[-1, 1])))
    assert ex.attempts == [2]


def test_cells_the_map_adds_to_a_banned_frontier_are_goals():
    # the robot saw further into the room: the frontier moved on, its new cells are not banned
    grid = _grid(_walled_left_known(90))
    cm = _costmap(grid)
    ex = FrontierExplorer()
    first = ex.find(grid, cm, Pose2D(0.8, 2.2)).chosen
    assert first is not None and first.goal is not None
    ex.mark_failed(first.goal, first.cells)
    assert ex.find(grid, cm, Pose2D(0.8, 2.2)).chosen is None
    grown = _grid(_walled_left_known(90, known_to=75))
    moved = ex.find(grown, _costmap(grown), Pose2D(0.8, 2.2)).chosen
    assert moved is not None and moved.goal is not None and moved.goal[0] > first.goal[0] + 1.0
