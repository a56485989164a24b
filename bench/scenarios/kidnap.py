"""Issue 5's kidnapped robot: while navigating, the simulated robot is carried 5 m away (its wheels
and gyro do not notice, as when someone picks it up); it must find out that it is lost, relocalize
and get back on its way to the goal within 30 s.

Each trial is a fresh robot in a stock world (office by default), localized with AMCL from the true
start, sent to a reachable goal 6-12 m away. ``kidnap_after`` simulated seconds after the goal was
sent the body is teleported to a free spot ``distance`` (+- 0.25) m from where it is, with a random
heading, from which the goal is still reachable. Figures per trial:

* ``relocalized_s``: from the kidnapping to the first moment the estimate is within 0.25 m and
  0.2 rad of the truth and stays there for ``hold_s`` (the filter has found the robot again);
* ``back_on_way_s``: from the kidnapping to the first moment, after that, the robot is navigating
  (not in a recovery) along a path requested after the relocalization: the robot drives to its
  goal from where it really is;
* the goal's outcome (a robot that relocalized but never got there is a failure too).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from app.commands.sim_nav import SimStack, drive
from bench.scenarios.suite import (
    OnTrial,
    SetOptions,
    SetResult,
    TrialResult,
    _timed,
    fresh_stack,
)
from nav.types import OccupancyGrid, Pose2D

RELOCALIZED_XY = 0.25
"""Estimate within this distance (m) of the truth counts as relocalized..."""
RELOCALIZED_YAW = 0.2
"""...and within this heading error (rad)."""


@dataclass
class KidnapWatch:
    """``drive``'s per-step hook: teleports the robot once and times its way back."""

    kidnap_after: float
    target: Pose2D
    hold_s: float = 1.0
    kidnapped_at: float | None = None
    relocalized_at: float | None = None
    back_on_way_at: float | None = None
    _good_since: float | None = None
    _plans_at_reloc: int = 0
    errors: list[float] = field(default_factory=list)

    def __call__(self, stack: SimStack, t: float) -> None:
        if self.kidnapped_at is None:
            if t >= self.kidnap_after:
                stack.driver.teleport(self.target)
                self.kidnapped_at = t
            return
        truth, est = stack.driver.truth_pose, stack.session.pose
        err = est.distance_to(truth)
        yaw = abs(math.remainder(est.theta - truth.theta, 2.0 * math.pi))
        self.errors.append(err)
        if self.relocalized_at is None:
            good = err < RELOCALIZED_XY and yaw < RELOCALIZED_YAW
            if not good:
                self._good_since = None
            elif self._good_since is None:
                self._good_since = t
            done = stack.navigation.navigator.state.value == "succeeded"  # no time left to hold
            if good and (done or t - self._good_since >= self.hold_s):
                self.relocalized_at = self._good_since
                self._plans_at_reloc = stack.navigation.plans
            if not done:
                return
        if self.back_on_way_at is None:
            nav = stack.navigation
            if nav.navigator.state.value == "succeeded":
                self.back_on_way_at = t
                return
            following = nav.navigator.state.value == "following"
            if (
                following
                and stack.session.modes.mode.value == "navigating"
                and nav.plans > self._plans_at_reloc
            ):
                self.back_on_way_at = t

    def seconds(self, at: float | None) -> float | None:
        return None if at is None or self.kidnapped_at is None else at - self.kidnapped_at


@dataclass(frozen=True)
class KidnapTrial:
    result: TrialResult
    relocalized_s: float | None
    back_on_way_s: float | None
    distance_m: float
    """How far the robot was carried (m)."""
    final_error_m: float
    """True distance from the goal at the end (m): a goal "reached" on a wrong estimate is not."""
    recoveries: tuple[tuple[str, str], ...] = ()
    """(trigger, behaviour) of each recovery attempt, in order."""

    @property
    def ok(self) -> bool:
        """Reached the goal for real (within the goal checker's 0.25 m plus 0.05 m)."""
        return self.result.result.reached and self.final_error_m <= 0.30


@dataclass
class KidnapSet:
    runs: SetResult
    trials: list[KidnapTrial] = field(default_factory=list)

    @property
    def reached(self) -> int:
        return sum(t.ok for t in self.trials)

    def back_on_way(self) -> list[float]:
        """Seconds to back-on-its-way per trial (inf where it never was)."""
        return [math.inf if t.back_on_way_s is None else t.back_on_way_s for t in self.trials]


def _reachable_spots(grid: OccupancyGrid, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) of cells at least ``clearance`` from walls, and their connected-region label."""
    from scipy.ndimage import distance_transform_edt, label

    clear = distance_transform_edt(grid.free_mask()) * grid.resolution
    ok = clear > clearance
    labels, _ = label(ok)
    r, c = np.nonzero(ok)
    return grid.geometry.cell_to_world(r, c), labels[r, c]


def kidnap_trials(
    n: int = 20,
    seed: int = 0,
    world_name: str = "apartment",
    distance: float = 5.0,
    kidnap_after: float = 8.0,
    timeout: float = 150.0,
    on_trial: OnTrial | None = None,
    **kw,
) -> KidnapSet:
    """``n`` kidnapped-robot trials in a stock world (see the module doc). Keywords: those of
    :class:`SetOptions` (controller, safety, only, profile)."""
    from maps.stock import stock_world_path
    from robot.sim import World

    path = stock_world_path(world_name)
    grid = World.from_yaml(path).grid
    xy, region = _reachable_spots(grid, 0.5)
    rng = np.random.default_rng(seed)
    o = SetOptions(seed, on_trial, **kw)

    def draw() -> Iterator[tuple[Pose2D, Pose2D]]:
        while True:
            i = int(rng.integers(len(xy)))
            same = np.flatnonzero(region == region[i])
            d = np.hypot(xy[same, 0] - xy[i, 0], xy[same, 1] - xy[i, 1])
            goals = same[(d > 6.0) & (d < 12.0)]
            if goals.size == 0:
                continue
            j = int(goals[rng.integers(goals.size)])
            start = Pose2D(float(xy[i, 0]), float(xy[i, 1]), float(rng.uniform(-math.pi, math.pi)))
            goal = Pose2D(float(xy[j, 0]), float(xy[j, 1]), float(rng.uniform(-math.pi, math.pi)))
            yield start, goal

    out = KidnapSet(SetResult(""))

    def run(res: SetResult) -> None:
        trials = draw()
        for k in range(n):
            start, goal = next(trials)
            if o.only is not None and k not in o.only:
                continue
            stack = fresh_stack(
                grid,
                start,
                o.seed * 1000 + k,
                controller=o.controller,
                safety=o.safety,
                profile=o.profile,
                world=World.from_yaml(path, start_pose=start),
            )
            try:
                # where the robot will be is not known in advance: the hook picks the spot at the
                # moment of the kidnapping, 5 m from the truth then, in the goal's region
                watch = _KidnapAt(kidnap_after, distance, xy, region, rng_seed=o.seed * 1000 + k)
                result = drive(stack, [goal], timeout, on_step=watch)
                trial = TrialResult(f"kidnap {k}", start, goal, result)
                res.trials.append(trial)
                out.trials.append(
                    KidnapTrial(
                        trial,
                        watch.seconds(watch.relocalized_at),
                        watch.seconds(watch.back_on_way_at),
                        watch.carried,
                        stack.driver.truth_pose.distance_to(goal),
                        tuple(
                            (e["trigger"], e["behavior"])
                            for e in stack.session.events
                            if e["type"] == "recovery" and e.get("kind") == "attempt"
                        ),
                    )
                )
                if on_trial is not None:
                    on_trial(trial)
            finally:
                stack.session.close()

    out.runs = _timed(f"kidnap {distance:g} m ({world_name})", run)
    return out


class _KidnapAt(KidnapWatch):
    """A ``KidnapWatch`` whose target is drawn at the moment of the kidnapping."""

    def __init__(
        self, after: float, distance: float, xy: np.ndarray, region: np.ndarray, rng_seed: int
    ) -> None:
        super().__init__(after, Pose2D())
        self._distance, self._xy, self._region = distance, xy, region
        self._rng = np.random.default_rng(rng_seed)
        self.carried = 0.0

    def __call__(self, stack: SimStack, t: float) -> None:
        if self.kidnapped_at is None and t >= self.kidnap_after:
            here = stack.driver.truth_pose
            d = np.hypot(self._xy[:, 0] - here.x, self._xy[:, 1] - here.y)
            near = int(np.argmin(d))
            ok = np.flatnonzero((np.abs(d - self._distance) < 0.25) & (self._region == self._region[near]))
            if ok.size == 0:  # nothing 5 m away in this region: the farthest spot within 5 m
                ok = np.array([int(np.argmax(np.where(d <= self._distance, d, -1.0)))])
            j = int(ok[self._rng.integers(ok.size)])
            self.target = Pose2D(
                float(self._xy[j, 0]), float(self._xy[j, 1]), float(self._rng.uniform(-math.pi, math.pi))
            )
            self.carried = here.distance_to(self.target)
        super().__call__(stack, t)
