"""Frontier-based exploration (Yamauchi 1997; the selection rule of ROS's ``explore_lite``).

A *frontier cell* is a known-free cell of the occupancy grid with an unknown 8-neighbour; frontier
cells are clustered into frontiers by 8-connectivity (``scipy.ndimage.label``). Each frontier is
scored from one Dijkstra distance field grown from the robot over the traversable cells of the
global costmap (``nav.planning.grid_search`` with no heuristic and no goal), not from a plan per
frontier:

    cost = potential_scale * travel_distance - gain_scale * frontier_length

(``explore_lite`` names and defaults: potential_scale 3, gain_scale 1, lengths in metres). The
goal sent for a frontier is its reachable cell nearest to the robot by travel, or, when every
frontier cell lies too close to a wall for the robot's footprint, the nearest reachable cell within
``goal_reach`` of the frontier. Frontiers whose goal lies within ``blacklist_radius`` of a goal that
failed are skipped (``explore_lite``'s blacklist).

Pure numpy/scipy over whole grids: no per-cell Python loop; the one loop is over frontiers (tens).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from nav.planning.grid_search import SearchState
from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, OccupancyGrid, Pose2D

EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class FrontierOptions:
    """Frontier detection and selection (``explore_lite`` parameter names where one exists)."""

    potential_scale: float = 3.0
    """Weight of the travel distance (m) in a frontier's cost (explore_lite default 3)."""
    gain_scale: float = 1.0
    """Weight of the frontier's length (m), its information gain (explore_lite default 1)."""
    min_frontier_size: float = 0.3
    """Frontiers shorter than this (m) are ignored: a few unknown cells behind a chair leg or in a
    wall's shadow are not worth a trip (explore_lite: 0.5 m; smaller here so a 0.8 m doorway seen
    edge-on still counts)."""
    free_threshold: int = 64
    """Occupancy values 0..this count as free: known and below map_server's ``occupied_thresh``
    (0.65), as Nav2's static layer reads a trinary map, so a frontier is what the planner may
    enter. (A live SLAM map marks a cell seen free once at 40: map_saver's 0.25 would wait for
    several scans of it.)"""
    goal_reach: float = 0.6
    """A frontier all of whose cells are too close to a wall for the footprint is still a target:
    the robot goes to the nearest traversable cell within this distance (m), from where its lidar
    sees past the frontier."""
    blacklist_radius: float = 0.5
    min_goal_distance: float = 0.5
    """A frontier whose goal is this close to the robot stays unseen from where the robot stands
    (under furniture, in a sensor shadow): it is not chosen, and ``FrontierReport.unobservable``
    lists it for the caller to blacklist. The explorer also takes a goal as reached once the robot
    is this close (the lidar sees the frontier from there). Nav2's progress checker radius
    (``required_movement_radius`` 0.5 m): inside it the last turns and creeping onto the goal count
    as no progress, and that is where frontier goals near furniture ended in ``NoProgress``."""
    goal_max_cost: int = 100
    """Goal cells are taken among those with a cost up to this when the frontier has any (away from
    the steep part of the inflation, where a controller may fail to settle), else among all
    traversable ones."""
    """A frontier whose goal is within this distance (m) of a failed goal is not chosen again."""
    cost_travel_multiplier: float = 2.0
    """Step cost weighting of the distance field, as the planner's (keeps travel costs comparable
    with the paths the planner will return)."""


@dataclass(frozen=True)
class Frontier:
    """One cluster of frontier cells, in the map frame."""

    cells: np.ndarray
    """(K, 2) world x, y of the frontier's cells."""
    length: float
    """Its size in metres (cells x resolution, ``explore_lite``'s ``size``)."""
    centroid: tuple[float, float]
    goal: tuple[float, float] | None
    """Where the robot is sent for it; None when no traversable cell reaches it."""
    travel: float
    """Travel distance (m) from the robot to ``goal`` along the distance field (inf if none)."""
    cost: float
    """``potential_scale * travel - gain_scale * length`` (inf when unreachable)."""

    @property
    def reachable(self) -> bool:
        return self.goal is not None


@dataclass
class FrontierReport:
    """Frontiers of one map, best (lowest cost, reachable, not blacklisted) first."""

    frontiers: list[Frontier]
    chosen: Frontier | None
    frontier_cells: int
    free_area_m2: float
    """Known-free area of the map (m^2): what has been explored."""
    blacklisted: int = 0
    """Better-ranked reachable frontiers skipped because their goal is near a failed one."""
    unobservable: list[tuple[float, float]] = field(default_factory=list)
    """Goals of better-ranked frontiers skipped because the robot stands at them already."""

    @property
    def reachable(self) -> list[Frontier]:
        return [f for f in self.frontiers if f.reachable]


def frontier_mask(grid: OccupancyGrid, free_threshold: int = 64) -> np.ndarray:
    """(H, W) bool: free cells with at least one unknown 8-neighbour. Cells off the grid count as
    unknown: a SLAM map ends where its rays ended, so a free cell on its edge borders the unseen."""
    data = grid.data
    free = (data >= 0) & (data <= free_threshold)
    unknown = np.pad(data < 0, 1, constant_values=True)
    return free & ndimage.binary_dilation(unknown, structure=EIGHT)[1:-1, 1:-1]


def distance_field(costmap: Costmap, start: Pose2D, cost_travel_multiplier: float = 2.0) -> np.ndarray:
    """Travel distance (m) from ``start`` to every cell over the costmap's traversable known cells
    (below the inscribed cost), 8-connected, no corner cutting; inf where unreachable.

    One exhaustive Dijkstra run of the planner's kernel (goal = no cell), so costs match the
    planner's."""
    geo = costmap.geometry
    rows, cols = geo.world_to_cell(np.array([[start.x, start.y]]))
    r, c = int(rows[0]), int(cols[0])
    out = np.full((geo.height, geo.width), np.inf)
    if not geo.in_bounds(rows, cols)[0]:
        return out
    costs = costmap.costs
    passable = costs < INSCRIBED_INFLATED_OBSTACLE
    # The goal index (-1, -1) is a padding cell, never expanded: the search runs to exhaustion.
    state = SearchState.create(
        passable,
        np.where(passable, costs, 0).astype(np.uint8),
        (r, c),
        (-1, -1),
        heuristic_weight=0.0,
        cost_travel_multiplier=cost_travel_multiplier,
    )
    state.run(geo.width * geo.height + 1)
    closed = state.closed
    g = state.g.reshape(geo.height + 2, geo.width + 2)[1:-1, 1:-1]
    out[closed] = g[closed] * geo.resolution
    return out


@dataclass
class FrontierExplorer:
    """Finds and ranks frontiers; remembers failed goals (the blacklist)."""

    options: FrontierOptions = field(default_factory=FrontierOptions)
    blacklist: list[tuple[float, float]] = field(default_factory=list)

    def mark_failed(self, goal: tuple[float, float]) -> None:
        """Never choose a frontier whose goal is near ``goal`` again (it could not be reached)."""
        self.blacklist.append((float(goal[0]), float(goal[1])))

    def clear_blacklist(self) -> None:
        self.blacklist.clear()

    def _blacklisted(self, goal: tuple[float, float]) -> bool:
        if not self.blacklist:
            return False
        b = np.asarray(self.blacklist)
        d = np.hypot(b[:, 0] - goal[0], b[:, 1] - goal[1])
        return bool((d <= self.options.blacklist_radius).any())

    def find(self, grid: OccupancyGrid, costmap: Costmap, robot: Pose2D) -> FrontierReport:
        """Frontiers of ``grid`` ranked for a robot at ``robot``; ``costmap`` must share the grid's
        geometry (the global costmap built from it)."""
        o = self.options
        geo = grid.geometry
        if costmap.costs.shape != grid.data.shape:
            raise ValueError(
                f"costmap {costmap.costs.shape} and map {grid.data.shape} must share one geometry"
            )
        res = geo.resolution
        free = grid.free_mask(o.free_threshold)
        free_area = float(np.count_nonzero(free)) * res * res
        mask = frontier_mask(grid, o.free_threshold)
        labels, n = ndimage.label(mask, structure=EIGHT)
        if n == 0:
            return FrontierReport([], None, 0, free_area)
        dist = distance_field(costmap, robot, o.cost_travel_multiplier)
        sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        keep = np.nonzero(sizes * res >= o.min_frontier_size)[0] + 1
        reach_cells = max(1, math.ceil(o.goal_reach / res))
        objects = ndimage.find_objects(labels)
        frontiers: list[Frontier] = []
        for lab in keep:
            sl = objects[lab - 1]
            assert sl is not None
            # a window around the frontier grown by the reach: the disk around it stays inside
            r0, r1 = max(sl[0].start - reach_cells, 0), min(sl[0].stop + reach_cells, geo.height)
            c0, c1 = max(sl[1].start - reach_cells, 0), min(sl[1].stop + reach_cells, geo.width)
            own = labels[r0:r1, c0:c1] == lab
            rows, cols = np.nonzero(own)
            cells = geo.cell_to_world(rows + r0, cols + c0)
            d_win = dist[r0:r1, c0:c1]
            low = costmap.costs[r0:r1, c0:c1] <= o.goal_max_cost
            # the frontier's own cells, else cells within reach; low-cost cells first in each
            on = _first_reachable(d_win, (own & low, own))
            if on is None:
                # Only now the disk around the frontier (a Euclidean distance transform of the
                # window: a dilation by a 25 x 25 disk for every frontier took a fifth of the CPU
                # of exploring the office).
                near = ndimage.distance_transform_edt(~own) <= reach_cells
                on = _first_reachable(d_win, (near & low, near))
            goal, travel = None, math.inf
            if on is not None:
                i = int(np.argmin(on))
                gr, gc = divmod(i, on.shape[1])
                travel = float(on[gr, gc])
                gxy = geo.cell_to_world(np.array([gr + r0]), np.array([gc + c0]))[0]
                goal = (float(gxy[0]), float(gxy[1]))
            length = float(rows.size) * res
            cost = o.potential_scale * travel - o.gain_scale * length if goal is not None else math.inf
            cx, cy = cells.mean(axis=0)
            frontiers.append(Frontier(cells, length, (float(cx), float(cy)), goal, travel, cost))
        frontiers.sort(key=lambda f: f.cost)
        chosen, skipped, here = None, 0, []
        for f in frontiers:
            if f.goal is None:
                break  # sorted: the rest are unreachable too
            if self._blacklisted(f.goal):
                skipped += 1
                continue
            if math.hypot(f.goal[0] - robot.x, f.goal[1] - robot.y) < o.min_goal_distance:
                here.append(f.goal)
                continue
            chosen = f
            break
        return FrontierReport(frontiers, chosen, int(np.count_nonzero(mask)), free_area, skipped, here)


def _first_reachable(dist: np.ndarray, regions: tuple[np.ndarray, ...]) -> np.ndarray | None:
    """``dist`` inside the first of ``regions`` that holds a reachable cell (inf elsewhere)."""
    for region in regions:
        on = np.where(region, dist, np.inf)
        if np.isfinite(on).any():
            return on
    return None


def goal_pose(goal: tuple[float, float], robot: Pose2D) -> Pose2D:
    """A frontier goal as a pose facing away from the robot (towards the unknown beyond it)."""
    return Pose2D(goal[0], goal[1], math.atan2(goal[1] - robot.y, goal[0] - robot.x))
