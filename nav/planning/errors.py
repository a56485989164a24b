"""Typed global-planner failures, named as Nav2's ``nav2_core`` planner exceptions.

The navigator reacts to *why* planning failed (e.g. suggest a free goal on ``GoalOccupied``,
clear the costmap on ``NoValidPathFound``); the API turns them into 4xx details with these names.
"""

from __future__ import annotations


class PlannerError(Exception):
    """Base of every planner failure (``nav2_core::PlannerException``)."""


class StartOccupied(PlannerError):
    """The start cell is a lethal obstacle."""


class GoalOccupied(PlannerError):
    """The goal cell is not traversable and no traversable cell lies within the goal tolerance."""


class StartOutsideMap(PlannerError):
    """The start pose is outside the costmap."""


class GoalOutsideMap(PlannerError):
    """The goal pose is outside the costmap."""


class NoValidPathFound(PlannerError):
    """The search exhausted the reachable space (or its iteration budget) without reaching the goal
    or any cell within the goal tolerance (``NoValidPathCouldBeFound``)."""


class PlannerTimedOut(PlannerError):
    """The search ran longer than ``max_planning_time``."""


__all__ = [
    "GoalOccupied",
    "GoalOutsideMap",
    "NoValidPathFound",
    "PlannerError",
    "PlannerTimedOut",
    "StartOccupied",
    "StartOutsideMap",
]
