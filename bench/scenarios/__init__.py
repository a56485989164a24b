"""Navigation scenario suite: the whole stack (simulator, AMCL, costmaps, A*, DWA, navigator) driven
through goal sets on a virtual clock, reported as success rates against the issue's targets and
source A's trial results. Benchmarks are registered in ``bench/navigation.py`` (``navdeck bench
scenarios``); this package holds the trial sets and runners only."""

from bench.scenarios.suite import (
    SetResult,
    TrialResult,
    fixed_obstacle_trials,
    random_goal_trials,
    straight_trials,
    turn_trials,
)

__all__ = [
    "SetResult",
    "TrialResult",
    "fixed_obstacle_trials",
    "random_goal_trials",
    "straight_trials",
    "turn_trials",
]
