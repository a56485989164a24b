"""Navigation scenario suite: the whole stack (simulator, AMCL, costmaps, A*, DWA or TEB, navigator,
safety filter) driven through goal sets on a virtual clock, reported as success rates against the
issue's targets and source A's trial results. The random-goal and quick benchmarks are registered in
``bench/navigation.py``; issue 5's per-controller sets in ``bench/scenarios/issue5.py`` (both run by
``navdeck bench scenarios``); issue 16's family sets (a new generated world per trial) in
``bench/scenarios/family_bench.py`` (``navdeck bench scenarios.family``); issue 18's cylinder forests in
``bench/scenarios/forest.py`` (``navdeck bench scenarios.forest``). ``suite`` and ``families``
hold the trial sets and runners."""

from bench.scenarios import family_bench, forest, issue5
from bench.scenarios.suite import (
    SetResult,
    TrialResult,
    fixed_obstacle_trials,
    greenhouse_row_trials,
    person_trials,
    random_goal_trials,
    straight_trials,
    turn_trials,
)

BENCHMARKS = [*issue5.BENCHMARKS, *family_bench.BENCHMARKS, *forest.BENCHMARKS]

__all__ = [
    "BENCHMARKS",
    "SetResult",
    "TrialResult",
    "fixed_obstacle_trials",
    "greenhouse_row_trials",
    "person_trials",
    "random_goal_trials",
    "straight_trials",
    "turn_trials",
]
