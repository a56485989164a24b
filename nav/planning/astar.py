"""A* global planner (Hart, Nilsson & Raphael 1968), the counterpart of Nav2's Smac Planner 2D.

The octile-distance heuristic is consistent on this grid because every step costs at least its
geometric length (cost factors are >= 1), so the returned grid path is optimal for the step costs.
"""

from __future__ import annotations

from nav.planning.base import GridPlanner


class AStarPlanner(GridPlanner):
    """8-connected A* over a ``Costmap``; ``AStarPlanner(PlannerOptions(...)).plan(costmap, start, goal)``."""

    heuristic_weight = 1.0
    name = "astar"
