"""The ``GlobalPlanner`` role and the shared grid planner (Nav2 ``nav2_core::GlobalPlanner``).

``GridPlanner`` does everything both concrete planners share: validate start and goal (typed
errors), pick a goal cell within ``tolerance``, run the compiled 8-connected search under a
wall-clock budget (``nav.planning.kernel`` picks the kernel), fall back to the nearest reached cell
within tolerance, smooth, and add headings.
A* and Dijkstra differ only in the heuristic weight.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from nav.planning.errors import (
    GoalOccupied,
    GoalOutsideMap,
    NoValidPathFound,
    PlannerTimedOut,
    StartOccupied,
    StartOutsideMap,
)
from nav.planning.escape import descent_from_start
from nav.planning.grid_search import BUDGET, EXHAUSTED, FOUND
from nav.planning.kernel import make_search
from nav.planning.smoothing import SmootherOptions, orientations, path_is_traversable, smooth_cells
from nav.types import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION, Costmap, Path, Pose2D


@runtime_checkable
class GlobalPlanner(Protocol):
    """Plans a path over a costmap; raises ``PlannerError`` subclasses on failure."""

    def plan(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> Path: ...


@dataclass(frozen=True)
class PlannerOptions:
    """Grid planner parameters (names and defaults of Nav2's Smac Planner 2D unless noted)."""

    tolerance: float = 0.25
    """Goal tolerance (m): if the goal cell cannot be reached, plan to the nearest reachable cell
    within this distance of it. Smac 2D default 0.125, NavFn 0.5; 0.25 = 5 cells at 0.05 m."""
    allow_unknown: bool = True
    """Whether unknown (255) cells are traversable. Nav2 default true."""
    unknown_cost: int = NO_INFORMATION
    """Cost (0..255) an unknown cell counts with in the step cost when ``allow_unknown``: 255 keeps
    the raw value (as Smac does), 0 treats unknown as free space (navdeck, issue 18)."""
    max_cost: int = INSCRIBED_INFLATED_OBSTACLE - 1
    """Highest known cost a path may enter (0..252): 252 is Nav2's rule (below inscribed); lower
    values keep paths out of gaps the footprint cannot pass with a margin (navdeck, issue 18; the
    navigation feature derives it from ``gap_margin``)."""
    cost_travel_multiplier: float = 2.0
    """Step cost = (1 or sqrt2) * (1 + cost_travel_multiplier * cost / 252): 0 is shortest-distance
    geometry, larger values keep the path in the middle of free space. Smac 2D default 2.0
    (the CLI's ``--cost-weight``)."""
    max_iterations: int = -1
    """Expansion limit before failing with ``NoValidPathFound``; -1 disables it. Smac default is
    1000000; unlimited here because ``max_planning_time`` already bounds the work."""
    max_planning_time: float = 2.0
    """Wall-clock budget (s) before ``PlannerTimedOut``. Smac 2D default 2.0."""
    use_final_approach_orientation: bool = False
    """If true the last pose faces along the final approach instead of the goal heading
    (Nav2 name and default)."""
    smooth_path: bool = True
    """Run the simple smoother on the grid path (NavFn/Smac ``smooth_path``; default true)."""
    smoother: SmootherOptions = field(default_factory=SmootherOptions)
    """Smoother parameters (Nav2 ``SimpleSmoother`` names)."""

    def __post_init__(self) -> None:
        if not 0 <= self.unknown_cost <= NO_INFORMATION:
            raise ValueError(f"unknown_cost must be 0..255, got {self.unknown_cost}")
        if not 0 <= self.max_cost <= INSCRIBED_INFLATED_OBSTACLE - 1:
            raise ValueError(f"max_cost must be 0..252, got {self.max_cost}")


@dataclass(frozen=True)
class PlanStats:
    """What one search did: for benchmarks, logs and the CLI."""

    expansions: int
    search_cost: float
    """Accumulated step cost of the grid path, in cells (equals the octile length when
    ``cost_travel_multiplier`` is 0)."""
    goal_cell: tuple[int, int]
    goal_reached_exactly: bool
    time_s: float


def traversable_mask(
    costs: np.ndarray, allow_unknown: bool, max_cost: int = INSCRIBED_INFLATED_OBSTACLE - 1
) -> np.ndarray:
    """Cells a path may enter: cost <= ``max_cost`` (below inscribed by default), plus unknown ones
    if allowed."""
    ok = costs <= min(max_cost, INSCRIBED_INFLATED_OBSTACLE - 1)
    if allow_unknown:
        ok |= costs == NO_INFORMATION
    return ok


def _nearest_in_radius(
    mask: np.ndarray, cell: tuple[int, int], radius_cells: float
) -> tuple[int, int] | None:
    """The cell of ``mask`` nearest to ``cell`` within ``radius_cells`` (vectorized over a window)."""
    h, w = mask.shape
    r0, c0 = cell
    k = math.floor(radius_cells)
    rlo, rhi = max(r0 - k, 0), min(r0 + k + 1, h)
    clo, chi = max(c0 - k, 0), min(c0 + k + 1, w)
    if rlo >= rhi or clo >= chi:
        return None
    rr, cc = np.mgrid[rlo:rhi, clo:chi]
    d2 = (rr - r0) ** 2 + (cc - c0) ** 2
    ok = mask[rlo:rhi, clo:chi] & (d2 <= radius_cells * radius_cells + 1e-9)
    if not ok.any():
        return None
    d2 = np.where(ok, d2, np.iinfo(np.int64).max)
    i = int(np.argmin(d2))
    return int(rr.flat[i]), int(cc.flat[i])


class GridPlanner:
    """8-connected grid planner; ``heuristic_weight`` 1 is A*, 0 is Dijkstra."""

    heuristic_weight: float = 1.0
    name: str = "grid"
    _budget: int = 200_000  # expansions between wall-clock checks (~5-10 ms of search)

    def __init__(self, options: PlannerOptions | None = None) -> None:
        self.options = options or PlannerOptions()

    def plan(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> Path:
        """Plan from ``start`` to ``goal`` (map frame); see ``plan_with_stats``."""
        return self.plan_with_stats(costmap, start, goal)[0]

    def plan_with_stats(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> tuple[Path, PlanStats]:
        """Plan and report search statistics. Raises ``StartOutsideMap``, ``GoalOutsideMap``,
        ``StartOccupied``, ``GoalOccupied``, ``NoValidPathFound`` or ``PlannerTimedOut``."""
        t0 = time.perf_counter()
        opts = self.options
        geo = costmap.geometry
        costs = costmap.costs
        if not start.is_finite():
            raise StartOutsideMap(f"start {start} is not finite")
        if not goal.is_finite():
            raise GoalOutsideMap(f"goal {goal} is not finite")
        sr, sc = (int(v[0]) for v in geo.world_to_cell(np.array([start.x, start.y])))
        gr, gc = (int(v[0]) for v in geo.world_to_cell(np.array([goal.x, goal.y])))
        if not (0 <= sr < geo.height and 0 <= sc < geo.width):
            raise StartOutsideMap(f"start ({start.x:.2f}, {start.y:.2f}) is outside the costmap")
        if not (0 <= gr < geo.height and 0 <= gc < geo.width):
            raise GoalOutsideMap(f"goal ({goal.x:.2f}, {goal.y:.2f}) is outside the costmap")
        if costs[sr, sc] == LETHAL_OBSTACLE:
            raise StartOccupied(f"start ({start.x:.2f}, {start.y:.2f}) is in a lethal obstacle")
        passable = traversable_mask(costs, opts.allow_unknown, opts.max_cost)
        # a start nearer an obstacle than max_cost allows (a robot pressed against it) leaves downhill
        passable |= descent_from_start(costs, (sr, sc), opts.max_cost)
        if opts.allow_unknown and opts.unknown_cost != NO_INFORMATION:
            costs = np.where(costs == NO_INFORMATION, np.uint8(opts.unknown_cost), costs)
        tol_cells = max(opts.tolerance, 0.0) / geo.resolution
        target = (gr, gc)
        if not passable[gr, gc] and (sr, sc) != (gr, gc):
            near = _nearest_in_radius(passable, (gr, gc), tol_cells)
            if near is None:
                raise GoalOccupied(
                    f"goal ({goal.x:.2f}, {goal.y:.2f}) is not traversable (cost {int(costs[gr, gc])}) "
                    f"and no free cell lies within tolerance {opts.tolerance} m"
                )
            target = near

        # the pruned kernel on a uniform-cost grid, the bucket kernel on every real costmap
        state = make_search(
            passable,
            costs,
            (sr, sc),
            target,
            heuristic_weight=self.heuristic_weight,
            cost_travel_multiplier=opts.cost_travel_multiplier,
        )
        deadline = t0 + opts.max_planning_time
        while True:
            budget = self._budget
            if opts.max_iterations >= 0:
                budget = min(budget, opts.max_iterations - state.expansions)
            status = state.run(budget) if budget > 0 else BUDGET
            if status != BUDGET:
                break
            if opts.max_iterations >= 0 and state.expansions >= opts.max_iterations:
                status = EXHAUSTED
                break
            if time.perf_counter() > deadline:
                raise PlannerTimedOut(
                    f"{self.name} exceeded max_planning_time {opts.max_planning_time} s "
                    f"after {state.expansions} expansions"
                )

        exact = status == FOUND and target == (gr, gc)
        if status != FOUND:
            near = _nearest_in_radius(state.closed, (gr, gc), tol_cells)
            if near is None:
                raise NoValidPathFound(
                    f"{self.name}: no path from ({start.x:.2f}, {start.y:.2f}) to ({goal.x:.2f}, "
                    f"{goal.y:.2f}) after {state.expansions} expansions"
                )
            target = near

        rows, cols = state.cells_to(*target)
        cells_xy = np.column_stack((cols + 0.5, rows + 0.5))
        # Endpoints at the exact start pose and (when its cell was reached) the exact goal pose.
        local_start = geo.origin.inverse().transform_points(np.array([[start.x, start.y]]))[0]
        cells_xy[0] = local_start / geo.resolution
        if exact:
            local_goal = geo.origin.inverse().transform_points(np.array([[goal.x, goal.y]]))[0]
            cells_xy[-1] = local_goal / geo.resolution
        if opts.smooth_path and cells_xy.shape[0] > 2:
            smoothed = smooth_cells(cells_xy, costs, opts.smoother)
            world_s = geo.origin.transform_points(smoothed * geo.resolution)
            limit = min(opts.max_cost, INSCRIBED_INFLATED_OBSTACLE - 1)
            if path_is_traversable(costmap, world_s[1:-1], max_cost=limit):
                cells_xy = smoothed
        world = geo.origin.transform_points(cells_xy * geo.resolution)
        if world.shape[0] == 1:
            world = np.vstack((world, world))
        final = goal.theta
        if opts.use_final_approach_orientation:
            d = world[-1] - world[-2]
            final = math.atan2(d[1], d[0]) if np.hypot(*d) > 0 else goal.theta
        theta = orientations(world, final)
        path = Path(np.column_stack((world, theta)))
        stats = PlanStats(
            expansions=state.expansions,
            search_cost=state.cost_to(*target),
            goal_cell=target,
            goal_reached_exactly=exact,
            time_s=time.perf_counter() - t0,
        )
        return path, stats
