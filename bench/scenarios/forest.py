"""Issue 18's cylinder-forest measure: ``navdeck bench scenarios.forest.<map>_<controller>``
(``prior_dwa``, ``prior_teb``, ``noprior_dwa``, ``noprior_teb``; the prefix ``scenarios.forest``
runs all four), group ``slow``.

Every trial draws a new forest (``robot.sim.worldgen.forest``: walled 10-16 x 7-10 m, 0.15 m
cylinders at 0.3-0.9 per square metre, clear start and goal areas, a route kept free for the
footprint plus margin) from (seed, trial), a start in the west area and a goal in the east one, and
drives a fresh simulated robot there with the whole stack (costmaps, A*, DWA or TEB, navigator,
recoveries, the server's safety filter). The robot is skid4 with a 270-degree lidar
(``forest_robot.toml``): its rear 90 degrees are blind, as on the robot of the issue.

- *prior map*: the planner is given the true forest map;
- *no prior map*: it starts from an all-unknown map of the forest's size (``sim-nav
  --no-prior-map``), the goal is sent with ``allow_unknown``; the costmaps fill from the lidar.

Both take the pose from the simulator's truth (the measure is about planning and control; AMCL in
open forests is issue 10's). Strict rules (issue 18): a trial succeeds when the robot's true
position comes within ``GOAL_RADIUS`` (1 m) of the goal in under ``TIME_LIMIT`` (100 s) simulated
seconds with no collision on the way; the run is then cancelled. Targets: success >= 0.97,
collisions 0, no fault. ``NAVDECK_FOREST_TRIALS`` (default 200) sets N per set,
``NAVDECK_FOREST_BUDGET_S`` (CPU seconds per set, optional) stops a set early: the figures name the
N actually run; ``NAVDECK_FOREST_FIRST`` and ``NAVDECK_FOREST_LOG`` run a set in shards
(``bench/scenarios/shards.py``). Trial ``i`` depends on (seed, i) alone.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.commands.sim_nav import SimNavResult, SimStack, build_sim_stack, drive, unknown_grid
from bench.core import Benchmark, Figure
from bench.scenarios.issue5 import CONTROLLERS, trial_count
from bench.scenarios.shards import TrialLog, budget_s, first_trial, only_trials
from nav.types import Pose2D
from robot.safety import SafetyFilter
from robot.sim.worldgen import generate

PROFILE = str(Path(__file__).with_name("forest_robot.toml"))
GOAL_RADIUS = 1.0
"""m: the strict rule's "within 1 m of the goal"."""
TIME_LIMIT = 100.0
"""Simulated seconds allowed (the strict rule's "< 100 s")."""
DISTANCE = (4.0, 20.0)
"""Straight start-goal distance drawn (m); the start and goal areas decide in practice."""
TRIALS_VAR = "NAVDECK_FOREST_TRIALS"
BUDGET_VAR = "NAVDECK_FOREST_BUDGET_S"
FIRST_VAR = "NAVDECK_FOREST_FIRST"
LOG_VAR = "NAVDECK_FOREST_LOG"
ONLY_VAR = "NAVDECK_FOREST_ONLY"


@dataclass(frozen=True)
class ForestTrial:
    index: int
    world_seed: int
    params: dict[str, float]
    start: Pose2D
    goal: Pose2D
    result: SimNavResult
    within_s: float | None
    """Simulated seconds until the robot was first within ``GOAL_RADIUS`` of the goal (None: never)."""
    collisions: int
    fault: str | None

    @property
    def succeeded(self) -> bool:
        return self.within_s is not None and self.within_s < TIME_LIMIT and self.collisions == 0

    @property
    def outcome(self) -> str:
        if self.succeeded:
            return "reached"
        if self.collisions:
            return "collision"
        if self.fault is not None:
            return f"fault: {self.fault}"
        r = self.result
        return "timeout" if r.outcome in ("timeout", "cancelled") else f"{r.outcome}: {r.reason}".strip(": ")


@dataclass
class ForestSet:
    prior_map: bool
    controller: str
    trials: list[ForestTrial] = field(default_factory=list)
    cpu_s: float = 0.0

    @property
    def name(self) -> str:
        return f"forest {'prior map' if self.prior_map else 'no prior map'} ({self.controller})"

    @property
    def n(self) -> int:
        return len(self.trials)

    @property
    def succeeded(self) -> int:
        return sum(t.succeeded for t in self.trials)

    @property
    def collisions(self) -> int:
        return sum(t.collisions for t in self.trials)

    @property
    def faults(self) -> int:
        return sum(t.fault is not None for t in self.trials)

    def failure_kinds(self) -> dict[str, int]:
        kinds: dict[str, int] = {}
        for t in self.trials:
            if not t.succeeded:
                kinds[t.outcome] = kinds.get(t.outcome, 0) + 1
        return dict(sorted(kinds.items(), key=lambda kv: -kv[1]))


def forest_stack(world_seed: int, start: Pose2D, prior_map: bool, controller: str, seed: int) -> SimStack:
    """A fresh robot at ``start`` in forest ``world_seed``: the true map or an all-unknown one."""
    gen = generate("forest", world_seed)
    grid = gen.grid if prior_map else unknown_grid(gen.geometry)
    stack = build_sim_stack(
        grid, gen.world(start), start, profile=PROFILE, localization="truth", seed=seed, controller=controller
    )
    stack.session.safety = SafetyFilter(stack.driver.profile)
    stack.localization.set_initial_pose(start)
    return stack


def forest_trial(i: int, seed: int = 0, controller: str = "dwa", prior_map: bool = True) -> ForestTrial:
    """Trial ``i`` of the (seed, map, controller) set: its own forest, start and goal."""
    rng = np.random.default_rng([seed, i])
    world_seed = int(rng.integers(2**31))
    gen = generate("forest", world_seed)
    start, goal = gen.sample_start_goal(rng, *DISTANCE)
    stack = forest_stack(world_seed, start, prior_map, controller, seed * 1000 + i)
    collisions0 = stack.session.collisions
    within: list[float] = []
    fault: list[str] = []

    def on_step(st: SimStack, elapsed: float) -> None:
        if st.session.fault is not None and not fault:
            fault.append(st.session.fault)
        truth = st.driver.truth_pose
        if not within and math.hypot(truth.x - goal.x, truth.y - goal.y) <= GOAL_RADIUS:
            within.append(elapsed)
            st.navigation.cancel(actor="bench")  # the strict rule is met: no need to drive on

    try:
        result = drive(stack, [goal], TIME_LIMIT, on_step=on_step, allow_unknown=None if prior_map else True)
        collisions = stack.session.collisions - collisions0
    finally:
        stack.session.close()
    return ForestTrial(
        index=i,
        world_seed=world_seed,
        params=gen.params,
        start=start,
        goal=goal,
        result=result,
        within_s=within[0] if within else None,
        collisions=collisions,
        fault=fault[0] if fault else None,
    )


def forest_trials(
    n: int,
    seed: int = 0,
    controller: str = "dwa",
    prior_map: bool = True,
    on_trial: Callable[[ForestTrial], None] | None = None,
    budget_s: float | None = None,
    first: int = 0,
    only: frozenset[int] | None = None,
) -> ForestSet:
    """Trials ``first .. first + n - 1``, or the trials in ``only`` (fewer when ``budget_s`` CPU seconds
    run out: the set keeps its true N)."""
    out = ForestSet(prior_map, controller)
    c0 = time.process_time()
    for i in sorted(only) if only is not None else range(first, first + n):
        if budget_s is not None and time.process_time() - c0 > budget_s:
            break
        trial = forest_trial(i, seed, controller, prior_map)
        out.trials.append(trial)
        if on_trial is not None:
            on_trial(trial)
    out.cpu_s = time.process_time() - c0
    return out


def describe(t: ForestTrial) -> str:
    r = t.result
    at = "never" if t.within_s is None else f"{t.within_s:.1f} s"
    return (
        f"trial {t.index} (forest {t.world_seed}, {t.params.get('cylinders', 0):.0f} cylinders): "
        f"{t.outcome}, "
        f"within 1 m at {at}, {t.collisions} collisions, {r.recoveries} recoveries, "
        f"clearance {r.min_clearance_m:.3f} m; start {t.start} goal {t.goal}"
    )


def forest_figures(res: ForestSet) -> list[Figure]:
    """Success against 0.97, collisions and faults against 0, time to the goal, speed."""
    n = max(1, res.n)
    times = [t.within_s for t in res.trials if t.succeeded and t.within_s is not None]
    rate = res.succeeded / n
    figs = [
        Figure(f"{res.name} success ({res.succeeded}/{res.n})", 100.0 * rate, "%", ">= 97", rate >= 0.97),
        Figure(f"{res.name} collisions", float(res.collisions), "count", "0", res.collisions == 0),
        Figure(f"{res.name} faults", float(res.faults), "count", "0", res.faults == 0),
        Figure(
            f"{res.name} median time to within 1 m",
            float(np.median(times)) if times else math.nan,
            "s",
        ),
        Figure(
            f"{res.name} simulated / CPU time",
            sum(t.result.time_s for t in res.trials) / max(res.cpu_s, 1e-9),
            "x",
        ),
    ]
    for kind, count in res.failure_kinds().items():
        print(f"  {res.name}: {count} x {kind}")
    for t in res.trials:
        if not t.succeeded:
            print(f"  {describe(t)}")
    return figs


def _progress(trial: ForestTrial) -> None:
    print(f"  {'ok ' if trial.succeeded else 'FAIL'} {describe(trial)}", file=sys.stderr, flush=True)


def _bench(prior_map: bool, controller: str) -> Callable[[], list[Figure]]:
    def run() -> list[Figure]:
        log = TrialLog(os.environ.get(LOG_VAR), f"forest {'prior' if prior_map else 'noprior'} {controller}")

        def on_trial(trial: ForestTrial) -> None:
            log.write(
                trial.index,
                trial.outcome,
                log.cpu_lap(),
                world_seed=trial.world_seed,
                succeeded=int(trial.succeeded),
                collisions=trial.collisions,
                fault=int(trial.fault is not None),
                sim_s=round(trial.result.time_s, 3),
                within_s=trial.within_s,
                recoveries=trial.result.recoveries,
            )
            _progress(trial)

        res = forest_trials(
            trial_count(TRIALS_VAR, 200),
            controller=controller,
            prior_map=prior_map,
            on_trial=on_trial,
            budget_s=budget_s(BUDGET_VAR),
            first=first_trial(FIRST_VAR),
            only=only_trials(ONLY_VAR),
        )
        return forest_figures(res)

    return run


BENCHMARKS = [
    Benchmark(name=f"scenarios.forest.{label}_{c}", run=_bench(prior, c), group="slow")
    for label, prior in (("prior", True), ("noprior", False))
    for c in CONTROLLERS
]

__all__ = [
    "BENCHMARKS",
    "ForestSet",
    "ForestTrial",
    "forest_figures",
    "forest_stack",
    "forest_trial",
    "forest_trials",
]
