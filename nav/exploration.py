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
``goal_reach`` of the frontier. Cells within ``blacklist_radius`` of a goal that failed, and of the
frontier cluster that goal was chosen from (its cells on the map it failed on), are not goals
(``explore_lite``'s blacklist): a frontier is skipped when none of its cells is left. A frontier that
grows past the banned cells (the map saw more of it) is a goal again from its new cells.

Pure numpy/scipy over whole grids: no per-cell Python loop; the one loop is over frontiers (tens).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from nav.planning.grid_search import SearchState
from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, GridGeometry, OccupancyGrid, Pose2D

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
    """Frontier cells within this distance (m) of a failed goal, or of the cells of the frontier it
    was chosen from, are not goals again (a short gap in a wall is one frontier: banning a circle
    around its goal left its next cell a goal, and the gap was visited again and again)."""
    max_attempts: int = 2
    """Goals tried at one place (within ``blacklist_radius``) before it is given up for good: once no
    other frontier is left, places that failed fewer times are forgiven (``forgive``) and tried
    again from where the robot now is, on the map as it has grown since."""
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
    """Reachable frontiers skipped because every cell that could be their goal is near a failed one."""
    unobservable: list[tuple[float, float]] = field(default_factory=list)
    """Goals of better-ranked frontiers skipped because the robot stands at them already."""
    unobservable_cells: list[np.ndarray] = field(default_factory=list)
    """The cells of those frontiers (parallel to ``unobservable``): what the caller blacklists."""
    travel: np.ndarray | None = None
    """The distance field (m) the frontiers were scored with; None when the map had no frontier."""
    geometry: GridGeometry | None = None

    @property
    def reachable(self) -> list[Frontier]:
        return [f for f in self.frontiers if f.reachable]

    def travel_to(self, xy: tuple[float, float]) -> float:
        """Travel (m) from the robot to ``xy`` along the distance field (inf if unreachable)."""
        if self.travel is None or self.geometry is None:
            return math.inf
        rows, cols = self.geometry.world_to_cell(np.array([xy]))
        if not self.geometry.in_bounds(rows, cols)[0]:
            return math.inf
        return float(self.travel[rows[0], cols[0]])


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
    """Finds and ranks frontiers; remembers failed goals (the blacklist).

    The blacklist bans *cells*: those within ``blacklist_radius`` of a failed goal and of the cells
    its frontier had on the map the goal failed on (explore_lite bans the frontier). Cells the map
    adds to the frontier later are goals: a room seen further through its doorway is not lost to
    one goal that failed there, while a gap no reachable spot sees through keeps its cells."""

    options: FrontierOptions = field(default_factory=FrontierOptions)
    blacklist: list[tuple[float, float]] = field(default_factory=list)
    attempts: list[int] = field(default_factory=list)
    """Failures at each blacklist place (parallel to ``blacklist``)."""
    forgiven: list[bool] = field(default_factory=list)
    """Places forgiven by ``forgive`` (their cells are goals again until they fail once more)."""
    clusters: list[np.ndarray] = field(default_factory=list)
    """(K, 2) world x, y of the frontier cells banned with each place (K = 0 without a frontier)."""

    def mark_failed(self, goal: tuple[float, float], cells: np.ndarray | None = None) -> None:
        """Ban the cells near ``goal`` and near ``cells`` (the frontier it was chosen from) as goals:
        it could not be reached or seen past. A failure at a known place (near its goal or its
        frontier) counts as another attempt there."""
        xy = (float(goal[0]), float(goal[1]))
        new = np.empty((0, 2)) if cells is None else np.asarray(cells, dtype=float).reshape(-1, 2)
        r = self.options.blacklist_radius
        for i, (place, known) in enumerate(zip(self.blacklist, self.clusters, strict=True)):
            near = math.hypot(xy[0] - place[0], xy[1] - place[1]) <= r
            if not near and len(known):
                near = bool(np.hypot(known[:, 0] - xy[0], known[:, 1] - xy[1]).min() <= r)
            if near:
                self.attempts[i] += 1
                self.forgiven[i] = False
                self.clusters[i] = np.vstack([known, new])
                return
        self.blacklist.append(xy)
        self.attempts.append(1)
        self.forgiven.append(False)
        self.clusters.append(new)

    def forgive(self) -> int:
        """Lift the ban on places that failed fewer than ``max_attempts`` times (a goal can fail for
        the way the robot came or a map that has grown since); returns how many were lifted."""
        n = 0
        for i, tries in enumerate(self.attempts):
            if not self.forgiven[i] and tries < self.options.max_attempts:
                self.forgiven[i] = True
                n += 1
        return n

    def clear_blacklist(self) -> None:
        self.blacklist.clear()
        self.attempts.clear()
        self.forgiven.clear()
        self.clusters.clear()

    @property
    def banned_places(self) -> list[tuple[float, float]]:
        return [xy for xy, f in zip(self.blacklist, self.forgiven, strict=True) if not f]

    def banned_mask(self, geo: GridGeometry) -> np.ndarray:
        """(H, W) bool: cells within ``blacklist_radius`` of a banned goal or of its frontier's cells."""
        r = self.options.blacklist_radius
        kept = self._banned_clusters()
        out = disk_mask(geo, self.banned_places, r)
        if kept:
            out |= cells_near_mask(geo, np.vstack(kept), r)
        return out

    def is_banned(self, goal: tuple[float, float]) -> bool:
        """``goal`` lies within ``blacklist_radius`` of a banned place or of its frontier's cells (as
        ``find`` bans cells)."""
        r = self.options.blacklist_radius
        if any(math.hypot(goal[0] - x, goal[1] - y) <= r for x, y in self.banned_places):
            return True
        return any(np.hypot(c[:, 0] - goal[0], c[:, 1] - goal[1]).min() <= r for c in self._banned_clusters())

    def _banned_clusters(self) -> list[np.ndarray]:
        return [c for c, f in zip(self.clusters, self.forgiven, strict=True) if not f and len(c)]

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
        banned = self.banned_mask(geo)
        sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        keep = np.nonzero(sizes * res >= o.min_frontier_size)[0] + 1
        reach_cells = max(1, math.ceil(o.goal_reach / res))
        objects = ndimage.find_objects(labels)
        frontiers: list[Frontier] = []
        skipped, unobservable, unobservable_cells = 0, [], []
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
            # Candidates: the frontier's own reachable cells, else (all too close to walls for the
            # footprint) the reachable cells within reach of it. Only now the disk around it (a
            # Euclidean distance transform of the window: a dilation by a 25 x 25 disk for every
            # frontier took a fifth of the CPU of exploring the office).
            # Banned cells are no part of it: a frontier whose cells are all banned has no goal.
            banned_win = banned[r0:r1, c0:c1]
            open_own = own & ~banned_win
            region = open_own
            if open_own.any() and _first_reachable(d_win, (open_own,)) is None:
                region = ndimage.distance_transform_edt(~open_own) <= reach_cells
            # The goal: a candidate not near a failed goal; low-cost cells first.
            allowed = region & ~banned_win
            on = _first_reachable(d_win, (allowed & low, allowed))
            if on is None and banned_win.any() and _could_reach(d_win, own, reach_cells):
                skipped += 1  # reachable, but every candidate is near a failed goal
            goal, travel = None, math.inf
            if on is not None:
                i = int(np.argmin(on))
                travel = float(on.ravel()[i])
                goal = _argmin_world(geo, on, r0, c0)
            length = float(rows.size) * res
            cost = o.potential_scale * travel - o.gain_scale * length if goal is not None else math.inf
            cx, cy = cells.mean(axis=0)
            frontiers.append(Frontier(cells, length, (float(cx), float(cy)), goal, travel, cost))
        frontiers.sort(key=lambda f: f.cost)
        chosen = None
        for f in frontiers:
            if f.goal is None:
                break  # sorted: the rest are unreachable too
            if math.hypot(f.goal[0] - robot.x, f.goal[1] - robot.y) < o.min_goal_distance:
                unobservable.append(f.goal)  # the robot stands there and does not see past it
                unobservable_cells.append(f.cells)
                continue
            chosen = f
            break
        return FrontierReport(
            frontiers,
            chosen,
            int(np.count_nonzero(mask)),
            free_area,
            skipped,
            unobservable,
            unobservable_cells,
            dist,
            geo,
        )


def disk_mask(geo: GridGeometry, points: list[tuple[float, float]], radius: float) -> np.ndarray:
    """(H, W) bool: cells whose centre is within ``radius`` of any of ``points`` (one small window
    per point: tens of points)."""
    out = np.zeros((geo.height, geo.width), dtype=bool)
    if not points:
        return out
    k = math.ceil(radius / geo.resolution) + 1
    rows, cols = geo.world_to_cell(np.asarray(points, dtype=float))
    for (px, py), r, c in zip(points, rows, cols, strict=True):
        r0, r1 = max(int(r) - k, 0), min(int(r) + k + 1, geo.height)
        c0, c1 = max(int(c) - k, 0), min(int(c) + k + 1, geo.width)
        if r0 >= r1 or c0 >= c1:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        xy = geo.cell_to_world(rr.ravel(), cc.ravel())
        near = np.hypot(xy[:, 0] - px, xy[:, 1] - py) <= radius
        out[r0:r1, c0:c1] |= near.reshape(r1 - r0, c1 - c0)
    return out


def cells_near_mask(geo: GridGeometry, cells: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) bool: cells within ``radius`` of any of ``cells`` ((K, 2) world x, y of cell centres;
    hundreds of them: one distance transform over their bounding window, not a disk per cell)."""
    out = np.zeros((geo.height, geo.width), dtype=bool)
    rows, cols = geo.world_to_cell(np.asarray(cells, dtype=float))
    inside = geo.in_bounds(rows, cols)
    if not inside.any():
        return out
    rows, cols = rows[inside].astype(int), cols[inside].astype(int)
    k = math.ceil(radius / geo.resolution) + 1
    r0, r1 = max(int(rows.min()) - k, 0), min(int(rows.max()) + k + 1, geo.height)
    c0, c1 = max(int(cols.min()) - k, 0), min(int(cols.max()) + k + 1, geo.width)
    seeds = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    seeds[rows - r0, cols - c0] = True
    out[r0:r1, c0:c1] = ndimage.distance_transform_edt(~seeds) * geo.resolution <= radius
    return out


def _could_reach(dist: np.ndarray, own: np.ndarray, reach_cells: int) -> bool:
    """Would the frontier ``own`` have a goal with no cell banned (its cells, else those in reach)?"""
    if _first_reachable(dist, (own,)) is not None:
        return True
    return _first_reachable(dist, (ndimage.distance_transform_edt(~own) <= reach_cells,)) is not None


def _argmin_world(geo: GridGeometry, on: np.ndarray, r0: int, c0: int) -> tuple[float, float]:
    gr, gc = divmod(int(np.argmin(on)), on.shape[1])
    gxy = geo.cell_to_world(np.array([gr + r0]), np.array([gc + c0]))[0]
    return (float(gxy[0]), float(gxy[1]))


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
