"""Global planners (Nav2 ``nav2_core::GlobalPlanner`` role): 8-connected A* and Dijkstra over a
``nav.types.Costmap``, typed errors, path smoothing and goal helpers."""

from nav.planning.astar import AStarPlanner
from nav.planning.base import GlobalPlanner, GridPlanner, PlannerOptions, PlanStats, traversable_mask
from nav.planning.dijkstra import DijkstraPlanner
from nav.planning.errors import (
    GoalOccupied,
    GoalOutsideMap,
    NoValidPathFound,
    PlannerError,
    PlannerTimedOut,
    StartOccupied,
    StartOutsideMap,
)
from nav.planning.goal import nearest_free_pose
from nav.planning.smoothing import SmootherOptions

PLANNERS: dict[str, type[GridPlanner]] = {"astar": AStarPlanner, "dijkstra": DijkstraPlanner}


def make_planner(name: str, options: PlannerOptions | None = None) -> GridPlanner:
    """A planner by its configuration name (``astar`` or ``dijkstra``)."""
    try:
        return PLANNERS[name](options)
    except KeyError:
        raise ValueError(f"unknown planner {name!r}; choose one of {sorted(PLANNERS)}") from None


__all__ = [
    "PLANNERS",
    "AStarPlanner",
    "DijkstraPlanner",
    "GlobalPlanner",
    "GoalOccupied",
    "GoalOutsideMap",
    "GridPlanner",
    "NoValidPathFound",
    "PlanStats",
    "PlannerError",
    "PlannerOptions",
    "PlannerTimedOut",
    "SmootherOptions",
    "StartOccupied",
    "StartOutsideMap",
    "make_planner",
    "nearest_free_pose",
    "traversable_mask",
]
