"""Dijkstra global planner (Dijkstra 1959), the counterpart of Nav2's NavFn planner.

NavFn propagates a potential from the goal and descends its gradient; here the same uniform-cost
expansion runs from the start with no heuristic and stops when the goal is settled, so it returns
the same optimal grid path as A* while expanding every cell cheaper than the goal. Kept for parity
with Nav2 setups that use NavFn and as a reference for A*.
"""

from __future__ import annotations

from nav.planning.base import GridPlanner


class DijkstraPlanner(GridPlanner):
    """8-connected Dijkstra over a ``Costmap`` (A* with a zero heuristic)."""

    heuristic_weight = 0.0
    name = "dijkstra"
