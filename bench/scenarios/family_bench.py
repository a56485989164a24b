"""Issue 16's family benchmarks: ``navdeck bench scenarios.family.<family>_<controller>`` (e.g.
``scenarios.family.greenhouse_teb``; the prefix ``scenarios.family`` runs all eight), group ``slow``.

Each runs ``NAVDECK_FAMILY_TRIALS`` trials (default 200, the issue's minimum per controller and
family), every one in a new world of the family with two walkers (``bench/scenarios/families.py``).
``NAVDECK_FAMILY_BUDGET_S`` (CPU seconds, optional) stops a set early on a shared machine; the
figures then name the N actually run. ``NAVDECK_FAMILY_FIRST`` starts at that trial index and
``NAVDECK_FAMILY_LOG`` appends every trial to a JSONL file, so a set can run in shards
(``bench/scenarios/shards.py``).

Targets (issue 16): 0 contacts while moving, for DWA and TEB, with walkers, in every family.
Reported without a target: success, timeout and fault rates, walkers into a stopped robot (not the
robot's fault), failure kinds.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from bench.core import Benchmark, Figure
from bench.scenarios.families import FamilySet, FamilyTrial, describe, family_trials
from bench.scenarios.issue5 import CONTROLLERS, trial_count
from bench.scenarios.shards import TrialLog, budget_s, first_trial, only_trials
from robot.sim.worldgen import FAMILIES

TRIALS_VAR = "NAVDECK_FAMILY_TRIALS"
BUDGET_VAR = "NAVDECK_FAMILY_BUDGET_S"
FIRST_VAR = "NAVDECK_FAMILY_FIRST"
LOG_VAR = "NAVDECK_FAMILY_LOG"
ONLY_VAR = "NAVDECK_FAMILY_ONLY"


def _progress(trial: FamilyTrial) -> None:
    print(f"  {'ok ' if trial.result.reached else 'FAIL'} {describe(trial)}", file=sys.stderr, flush=True)


def family_figures(res: FamilySet) -> list[Figure]:
    """Success, contacts by kind (moving against its target of 0), timeouts, faults, clearance to
    walkers and speed; failures are printed with their kinds."""
    n = max(1, res.n)
    moving = res.contacts_while_moving
    gaps = [
        t.result.min_person_clearance_m for t in res.trials if t.result.min_person_clearance_m is not None
    ]
    figs = [
        Figure(f"{res.name} reached ({res.reached}/{res.n})", 100.0 * res.reached / n, "%"),
        Figure(f"{res.name} contacts while moving", float(moving), "count", "0", moving == 0),
        Figure(
            f"{res.name} trials with a contact while moving",
            float(sum(t.contacts.while_moving > 0 for t in res.trials)),
            "count",
            "0",
            moving == 0,
        ),
        Figure(f"{res.name} walker into a stopped robot", float(res.walker_into_stopped), "count"),
        Figure(
            f"{res.name} timeouts ({res.count('timeout')}/{res.n})", 100.0 * res.count("timeout") / n, "%"
        ),
        Figure(f"{res.name} faults ({res.count('fault')}/{res.n})", 100.0 * res.count("fault") / n, "%"),
        Figure(f"{res.name} simulated / CPU time", res.sim_s / max(res.cpu_s, 1e-9), "x"),
    ]
    if gaps:
        figs.append(Figure(f"{res.name} min clearance to a walker", min(gaps), "m"))
    for kind, count in res.failure_kinds().items():
        print(f"  {res.name}: {count} x {kind}")
    for t in res.trials:
        if not t.result.reached or t.contacts.while_moving or t.contacts.walker_into_stopped:
            print(f"  {describe(t)}")
    return figs


def _log_line(log: TrialLog, trial: FamilyTrial, cpu_s: float) -> None:
    r, c = trial.result, trial.contacts
    log.write(
        int(trial.name.rsplit(" ", 1)[1]),
        trial.outcome,
        cpu_s,
        world_seed=trial.world_seed,
        sim_s=round(r.time_s, 3),
        contacts_while_moving=c.while_moving,
        contacts_with_walkers_while_moving=c.moving_person,
        walker_into_stopped=c.walker_into_stopped,
        timeout=int(trial.outcome == "timeout"),
        fault=int(trial.outcome == "fault"),
        recoveries=r.recoveries,
        min_person_clearance_m=r.min_person_clearance_m,
    )


def _bench(family: str, controller: str) -> Callable[[], list[Figure]]:
    def run() -> list[Figure]:
        log = TrialLog(os.environ.get(LOG_VAR), f"family {family} {controller}")
        first = first_trial(FIRST_VAR)

        def on_trial(trial: FamilyTrial) -> None:
            _log_line(log, trial, log.cpu_lap())
            _progress(trial)

        picked = only_trials(ONLY_VAR)
        if picked is None:
            picked = frozenset(range(first, first + trial_count(TRIALS_VAR, 200)))
        res = family_trials(
            family,
            max(picked) + 1,
            controller=controller,
            on_trial=on_trial,
            only=picked,
            budget_s=budget_s(BUDGET_VAR),
        )
        return family_figures(res)

    return run


BENCHMARKS = [
    Benchmark(name=f"scenarios.family.{family}_{c}", run=_bench(family, c), group="slow")
    for family in FAMILIES
    for c in CONTROLLERS
]
