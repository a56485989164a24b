"""Family scenario sets (issue 16): every trial draws a NEW world of a family
(``robot.sim.worldgen``) from the set's seed, a start and a goal from its sampler and two walkers
looping on its walkers' paths, and drives a fresh simulated robot (AMCL from the true start, the
family's profile, DWA or TEB, the server's safety filter) to the goal.

Contacts are split by what the robot was doing at the contact tick, from what the simulator reports
(a collision and what it was with) and what the robot was commanded and doing just before it:

* *while moving*: the robot was commanded to move or still moving (its fault: target 0);
* *walker into a stopped robot*: a person touched a robot commanded to stand and standing (reported,
  not the robot's fault);
* a stopped robot touching a static obstacle would be a simulator error and is counted apart.

A contact is counted once per episode (consecutive colliding ticks are one contact) and by kind.
Trial ``i`` of a set is a function of (seed, i) alone, so ``only`` reruns one failure.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from app.commands.sim_nav import SimNavResult, SimStack, drive
from bench.scenarios.suite import fresh_stack
from nav.planning import PlannerError
from nav.types import Pose2D, Twist2D
from robot.sim.people import MAX_SPEED, MIN_SPEED
from robot.sim.worldgen import FAMILIES, GeneratedWorld, generate

WALKERS = 2
MOVING_EPS = 1e-3
"""m/s and rad/s: below this a command or a velocity counts as standing still."""
DISTANCES = {  # straight start-goal distance drawn per family (m)
    "apartment": (3.0, 9.0),
    "office": (4.0, 14.0),
    "greenhouse": (4.0, 16.0),
    "forest": (4.0, 20.0),  # the start and goal areas decide
}


def _moving(t: Twist2D) -> bool:
    return abs(t.vx) > MOVING_EPS or abs(t.vy) > MOVING_EPS or abs(t.wz) > MOVING_EPS


@dataclass
class ContactLog:
    """Contact episodes by kind, fed once per control tick (see module doc)."""

    moving_obstacle: int = 0
    moving_person: int = 0
    walker_into_stopped: int = 0
    stopped_obstacle: int = 0
    ticks: int = 0
    _in_contact: bool = field(default=False, repr=False)
    _was_moving: bool = field(default=False, repr=False)

    @property
    def while_moving(self) -> int:
        return self.moving_obstacle + self.moving_person

    def observe(self, stack: SimStack, collided: bool) -> None:
        """Classify this tick's contact (if any) by the command sent and the velocity measured at
        the end of the previous tick (the physics of this tick ran on them; a collision zeroes the
        velocity, so the present one says nothing)."""
        if collided:
            self.ticks += 1
            if not self._in_contact:
                person = (stack.driver.collision_with or "").startswith("person")
                if self._was_moving:
                    if person:
                        self.moving_person += 1
                    else:
                        self.moving_obstacle += 1
                elif person:
                    self.walker_into_stopped += 1
                else:
                    self.stopped_obstacle += 1
        self._in_contact = collided
        self._was_moving = _moving(stack.session.last_command) or _moving(stack.driver.truth_velocity)


@dataclass(frozen=True)
class FamilyTrial:
    name: str
    world_seed: int
    params: dict[str, float]
    start: Pose2D
    goal: Pose2D
    walkers: int
    result: SimNavResult
    contacts: ContactLog
    fault: str | None

    @property
    def outcome(self) -> str:
        """reached | timeout | fault | failed: <reason>."""
        if self.result.reached:
            return "reached"
        if self.fault is not None:
            return "fault"
        if self.result.outcome == "timeout":
            return "timeout"
        return f"{self.result.outcome}: {self.result.reason}".strip(": ")


@dataclass
class FamilySet:
    family: str
    controller: str
    trials: list[FamilyTrial] = field(default_factory=list)
    cpu_s: float = 0.0
    wall_s: float = 0.0

    @property
    def name(self) -> str:
        return f"{self.family} ({self.controller})"

    @property
    def n(self) -> int:
        return len(self.trials)

    def count(self, outcome: str) -> int:
        return sum(t.outcome == outcome for t in self.trials)

    @property
    def reached(self) -> int:
        return self.count("reached")

    @property
    def contacts_while_moving(self) -> int:
        return sum(t.contacts.while_moving for t in self.trials)

    @property
    def walker_into_stopped(self) -> int:
        return sum(t.contacts.walker_into_stopped for t in self.trials)

    @property
    def sim_s(self) -> float:
        return sum(t.result.time_s for t in self.trials)

    def failure_kinds(self) -> dict[str, int]:
        kinds: dict[str, int] = {}
        for t in self.trials:
            if t.outcome != "reached":
                key = t.outcome if t.fault is None else f"fault: {t.fault}"
                kinds[key] = kinds.get(key, 0) + 1
        return dict(sorted(kinds.items(), key=lambda kv: -kv[1]))


OnTrial = Callable[[FamilyTrial], None]


def _route_timeout(stack: SimStack, start: Pose2D, goal: Pose2D) -> float:
    """Simulated seconds allowed: the A* route at a third of top speed, plus a minute for walkers
    in the way (straight distance when no plan: the navigator reports that failure itself)."""
    route = start.distance_to(goal)
    cm = stack.navigation.global_costmap
    if cm is not None:
        with contextlib.suppress(PlannerError):
            route = stack.navigation.planner.plan(cm, start, goal).length
    return 60.0 + 3.0 * route / stack.driver.profile.limits.max_vel_x


def run_trial(
    family: str,
    i: int,
    seed: int = 0,
    controller: str = "dwa",
    walkers: int = WALKERS,
    profile: str | None = None,
    timeout: float | None = None,
) -> FamilyTrial:
    """Trial ``i`` of the (family, seed) set: its own world, start, goal, walkers and robot noise."""
    rng = np.random.default_rng([seed, i])
    gen: GeneratedWorld = generate(family, int(rng.integers(2**31)))
    start, goal = gen.sample_start_goal(rng, *DISTANCES[family])
    world = gen.world(start)
    paths = gen.walker_paths(rng, walkers, avoid=(start, goal)) if walkers else []
    for path in paths:
        world.people.add_loop(path, speed=float(rng.uniform(MIN_SPEED, min(1.0, MAX_SPEED))))
    stack = fresh_stack(
        gen.grid, start, seed * 1000 + i, controller=controller, profile=profile or gen.profile, world=world
    )
    contacts = ContactLog()
    fault: list[str] = []
    seen = [stack.session.collisions]

    def on_step(st: SimStack, _elapsed: float) -> None:
        n = st.session.collisions
        contacts.observe(st, n > seen[0])
        seen[0] = n
        if st.session.fault is not None and not fault:
            fault.append(st.session.fault)

    try:
        limit = timeout if timeout is not None else _route_timeout(stack, start, goal)
        result = drive(stack, [goal], limit, on_step=on_step)
    finally:
        stack.session.close()
    return FamilyTrial(
        name=f"{family} {i}",
        world_seed=gen.seed,
        params=gen.params,
        start=start,
        goal=goal,
        walkers=len(paths),
        result=result,
        contacts=contacts,
        fault=fault[0] if fault else None,
    )


def family_trials(
    family: str,
    n: int = 200,
    seed: int = 0,
    controller: str = "dwa",
    walkers: int = WALKERS,
    on_trial: OnTrial | None = None,
    only: frozenset[int] | None = None,
    budget_s: float | None = None,
) -> FamilySet:
    """``n`` trials of ``family``, a new world each; ``budget_s`` (CPU seconds) stops early and the
    set reports the trials it ran (its true N)."""
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; one of {', '.join(FAMILIES)}")
    out = FamilySet(family, controller)
    c0, w0 = time.process_time(), time.perf_counter()
    for i in range(n):
        if only is not None and i not in only:
            continue
        if budget_s is not None and time.process_time() - c0 > budget_s:
            break
        trial = run_trial(family, i, seed, controller, walkers)
        out.trials.append(trial)
        if on_trial is not None:
            on_trial(trial)
    out.cpu_s, out.wall_s = time.process_time() - c0, time.perf_counter() - w0
    return out


def describe(t: FamilyTrial) -> str:
    r, c = t.result, t.contacts
    gap = "" if r.min_person_clearance_m is None else f", to walkers {r.min_person_clearance_m:.3f} m"
    return (
        f"{t.name} (world {t.world_seed}): {t.outcome}, {r.time_s:.1f} s sim, contacts moving "
        f"{c.while_moving} (walkers {c.moving_person}), walker into stopped {c.walker_into_stopped}, "
        f"clearance {r.min_clearance_m:.3f} m{gap}; start {t.start} goal {t.goal}"
    )


__all__ = ["ContactLog", "FamilySet", "FamilyTrial", "describe", "family_trials", "run_trial"]
