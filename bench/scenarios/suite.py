"""Trial sets and their runner.

* ``random_goal_trials``: the issue's target, >= 50 random reachable goals per stock world. The robot
  starts at the world's start pose and drives from goal to goal like an operator clicking goals; each
  goal is drawn uniformly over free space at least ``clearance`` from any wall, 1.5..8 m away, and
  kept only if A* finds a path to it from where the robot stands. After a failed goal the robot is
  carried to a random free spot and its pose set (an operator's rescue), so failures do not cascade.
* Source A's four sets (Vietnamese ROS2 thesis, 20 trials each there; issue 5 asks >= 50):
  ``straight_trials`` (no obstacle, goal straight ahead), ``turn_trials`` (no obstacle, the goal
  round a corner of an L-shaped corridor), ``fixed_obstacle_trials`` (a 30 x 30 cm box on the
  straight line that is in the world but not on the map, so only the lidar sees it) and
  ``person_trials`` (a person standing beside the line steps in ~0.3 m ahead of the robot's front
  when it comes near, ``Crowd.add_step_in``, stands there a few seconds and steps back). Each trial
  is a fresh simulated robot; seeds vary the start, the goal, the person, sensor noise and slip.
* ``greenhouse_row_trials`` (source C): the omni robot drives the length of a greenhouse aisle
  whose soil mounds and puddles (``maps/stock/greenhouse.scenario.toml``) are in the world but not
  in the map; the local planner must bend round them without touching one.

Every trial localizes with AMCL from the operator's initial pose (the true start), as a user would.
``controller`` ("dwa" | "teb", None: the profile's) picks the local controller; ``safety`` installs
the server's safety filter (``robot.safety.SafetyFilter``) below it, as ``navdeck serve`` does.
``only`` (trial indices) runs just those trials of the same seeded set, to reproduce a failure.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from app.commands.sim_nav import SimNavResult, SimStack, build_sim_stack, drive
from nav.types import GridGeometry, OccupancyGrid, Pose2D
from robot.safety import SafetyFilter
from robot.sim import World


@dataclass(frozen=True)
class TrialResult:
    name: str
    start: Pose2D
    goal: Pose2D
    result: SimNavResult


@dataclass
class SetResult:
    """The results of one trial set and the figures derived from them."""

    name: str
    trials: list[TrialResult] = field(default_factory=list)
    cpu_s: float = 0.0
    wall_s: float = 0.0

    @property
    def n(self) -> int:
        return len(self.trials)

    @property
    def reached(self) -> int:
        return sum(t.result.reached for t in self.trials)

    @property
    def collisions(self) -> int:
        return sum(t.result.collisions for t in self.trials)

    @property
    def sim_s(self) -> float:
        return sum(t.result.time_s for t in self.trials)

    @property
    def reached_pct(self) -> float:
        return 100.0 * self.reached / max(1, self.n)

    @property
    def localization_rms(self) -> float:
        e = np.array([t.result.localization_error_m for t in self.trials])
        return float(np.sqrt(np.mean(e**2))) if e.size else 0.0

    def failures(self) -> list[str]:
        return [
            f"{t.name}: {t.result.outcome} {t.result.reason} start {t.start} goal {t.goal}"
            for t in self.trials
            if not t.result.reached
        ]


OnTrial = Callable[[TrialResult], None]


def _run(
    stack: SimStack, name: str, start: Pose2D, goal: Pose2D, timeout: float, on_trial: OnTrial | None
) -> TrialResult:
    """One goal on ``stack``; the stack's session is closed by the caller."""
    trial = TrialResult(name, start, goal, drive(stack, [goal], timeout))
    if on_trial is not None:
        on_trial(trial)
    return trial


def _grid_from_mask(occupied: np.ndarray, resolution: float = 0.05) -> OccupancyGrid:
    data = np.where(occupied, 100, 0).astype(np.int8)
    return OccupancyGrid(GridGeometry(resolution, data.shape[1], data.shape[0]), data)


def _box(width: float, height: float) -> OccupancyGrid:
    return World.box(width, height).grid


def _l_corridor() -> OccupancyGrid:
    """An L of 2 m wide corridors: along x at y 0..2 (x 0..8), then up along y at x 0..2 (y 0..8)."""
    res, size = 0.05, 8.0
    n = round(size / res)
    occ = np.ones((n, n), dtype=bool)
    w = round(2.0 / res)
    occ[:w, :] = False
    occ[:, :w] = False
    t = 2  # 10 cm walls round the outside
    occ[:t, :] = occ[-t:, :] = occ[:, :t] = occ[:, -t:] = True
    occ[w:, w : w + t] = True
    occ[w : w + t, w:] = True
    return _grid_from_mask(occ, res)


def fresh_stack(
    grid: OccupancyGrid,
    start: Pose2D,
    seed: int,
    obstacles=(),
    *,
    controller: str | None = None,
    safety: bool = True,
    profile: str = "skid4",
    world: World | None = None,
) -> SimStack:
    """A new simulated robot at ``start`` (AMCL told the true start, the server's safety filter
    unless ``safety`` is off) in ``world`` or a copy of ``grid`` with ``obstacles`` added: every
    trial of every bench set (suite, kidnap, families) and the tests' one-off drives start here."""
    if world is None:
        world = World(OccupancyGrid(grid.geometry, grid.data.copy()), name="trial", start_pose=start)
    for poly in obstacles:
        world.add_polygon(poly)
    stack = build_sim_stack(grid, world, start, seed=seed, controller=controller, profile=profile)
    if safety:
        stack.session.safety = SafetyFilter(stack.driver.profile)
    stack.localization.set_initial_pose(start)
    return stack


def _label(name: str, controller: str | None) -> str:
    return name if controller is None else f"{name} ({controller})"


def _timed(name: str, fn) -> SetResult:
    out = SetResult(name)
    c0, w0 = time.process_time(), time.perf_counter()
    fn(out)
    out.cpu_s, out.wall_s = time.process_time() - c0, time.perf_counter() - w0
    return out


@dataclass(frozen=True)
class Trial:
    """One drawn trial of a fresh-robot set: where it starts and goes, and what its world adds."""

    start: Pose2D
    goal: Pose2D
    obstacles: tuple = ()  # polygons in the world but not on the map
    world: World | None = None  # a prepared world instead of the map's copy
    setup: Callable[[SimStack], None] | None = None  # e.g. a person waiting to step in


@dataclass(frozen=True)
class SetOptions:
    """What every fresh-robot set takes besides its own geometry (see the ``*_trials`` functions)."""

    seed: int = 0
    on_trial: OnTrial | None = None
    controller: str | None = None
    safety: bool = True
    only: frozenset[int] | None = None  # rerun just these trials of the same seeded set
    profile: str = "skid4"


def _run_set(
    label: str, prefix: str, grid: OccupancyGrid, trials: Iterator[Trial], timeout: float, o: SetOptions
) -> SetResult:
    """Drive each drawn trial on a fresh simulated robot. Every trial is drawn (so the random
    stream, and with it each trial, stays the same) even when ``o.only`` skips driving it."""

    def run(out: SetResult) -> None:
        for i, trial in enumerate(trials):
            if o.only is not None and i not in o.only:
                continue
            stack = fresh_stack(
                grid,
                trial.start,
                o.seed * 1000 + i,
                trial.obstacles,
                controller=o.controller,
                safety=o.safety,
                profile=o.profile,
                world=trial.world,
            )
            try:
                if trial.setup is not None:
                    trial.setup(stack)
                out.trials.append(_run(stack, f"{prefix} {i}", trial.start, trial.goal, timeout, o.on_trial))
            finally:
                stack.session.close()

    return _timed(_label(label, o.controller), run)


def straight_trials(
    n: int = 50, seed: int = 0, timeout: float = 60.0, on_trial: OnTrial | None = None, **kw
) -> SetResult:
    """No obstacle, straight: a 10 x 4 m room, goal 2..5 m straight ahead of the start heading.
    Keywords: those of :class:`SetOptions` (controller, safety, only, profile)."""
    rng = np.random.default_rng(seed)

    def draw() -> Iterator[Trial]:
        for _ in range(n):
            d = float(rng.uniform(2.0, 5.0))
            y = float(rng.uniform(1.5, 2.5))
            x0 = float(rng.uniform(1.0, 9.0 - d))
            start, goal = Pose2D(x0, y, 0.0), Pose2D(x0 + d, y, 0.0)
            if rng.random() < 0.5:  # half of them the other way
                start, goal = Pose2D(goal.x, y, math.pi), Pose2D(start.x, y, math.pi)
            yield Trial(start, goal)

    o = SetOptions(seed, on_trial, **kw)
    return _run_set("straight", "straight", _box(10.0, 4.0), draw(), timeout, o)


def turn_trials(
    n: int = 50, seed: int = 0, timeout: float = 90.0, on_trial: OnTrial | None = None, **kw
) -> SetResult:
    """No obstacle, with turns: from the far end of the L's horizontal leg round the corner to the
    vertical leg, facing along it (a left turn of 90 degrees plus the approach)."""
    rng = np.random.default_rng(seed)

    def draw() -> Iterator[Trial]:
        for _ in range(n):
            start = Pose2D(float(rng.uniform(5.0, 7.0)), float(rng.uniform(0.7, 1.3)), math.pi)
            goal = Pose2D(float(rng.uniform(0.7, 1.3)), float(rng.uniform(5.0, 7.0)), math.pi / 2)
            yield Trial(start, goal)

    return _run_set("turns", "turn", _l_corridor(), draw(), timeout, SetOptions(seed, on_trial, **kw))


def fixed_obstacle_trials(
    n: int = 50, seed: int = 0, timeout: float = 90.0, on_trial: OnTrial | None = None, **kw
) -> SetResult:
    """A fixed obstacle the map does not have: a 30 x 30 cm box midway on the straight line."""
    rng = np.random.default_rng(seed)

    def draw() -> Iterator[Trial]:
        for _ in range(n):
            y = float(rng.uniform(1.6, 2.4))
            x0 = float(rng.uniform(1.0, 2.0))
            d = float(rng.uniform(4.0, 6.0))
            cx, cy = x0 + d / 2 + float(rng.uniform(-0.3, 0.3)), y + float(rng.uniform(-0.1, 0.1))
            box = (
                (cx - 0.15, cy - 0.15),
                (cx + 0.15, cy - 0.15),
                (cx + 0.15, cy + 0.15),
                (cx - 0.15, cy + 0.15),
            )
            yield Trial(Pose2D(x0, y, 0.0), Pose2D(x0 + d, y, 0.0), obstacles=(box,))

    o = SetOptions(seed, on_trial, **kw)
    return _run_set("fixed obstacle", "obstacle", _box(10.0, 4.0), draw(), timeout, o)


def person_trials(
    n: int = 50, seed: int = 0, timeout: float = 90.0, on_trial: OnTrial | None = None, **kw
) -> SetResult:
    """Source A's moving obstacle: a person waits 0.8-1.3 m beside the straight line, past its
    middle; when the robot comes within that offset + 0.3-0.6 m of them (so it always does, about
    0.8-1.2 m before passing) they step in ~0.3 m ahead of its front (leading its motion), stand
    2-4 s and step back. The robot must stop or go round, then reach
    the goal, without touching them."""
    rng = np.random.default_rng(seed)

    def draw() -> Iterator[Trial]:
        for _ in range(n):
            y = float(rng.uniform(1.6, 2.4))
            x0 = float(rng.uniform(1.0, 2.0))
            d = float(rng.uniform(5.0, 7.0))
            side = 1.0 if y < 2.0 else -1.0  # the wider side of the room
            px = x0 + d * float(rng.uniform(0.4, 0.6))
            offset = float(rng.uniform(0.8, 1.3))
            trigger = offset + float(rng.uniform(0.3, 0.6))
            dwell, speed = float(rng.uniform(2.0, 4.0)), float(rng.uniform(0.8, 1.2))

            def person(
                stack: SimStack, px=px, py=y + side * offset, trigger=trigger, dwell=dwell, speed=speed
            ):
                stack.driver.people.add_step_in(px, py, trigger_distance=trigger, dwell=dwell, speed=speed)

            yield Trial(Pose2D(x0, y, 0.0), Pose2D(x0 + d, y, 0.0), setup=person)

    o = SetOptions(seed, on_trial, **kw)
    return _run_set("person steps in", "person", _box(10.0, 4.0), draw(), timeout, o)


GREENHOUSE_AISLES = (2.6, 4.4, 6.2, 8.0)
"""Centre lines (y, m) of the stock greenhouse's four aisles; rows run along x from 2.5 to 17.5."""


def greenhouse_row_trials(
    n: int = 50, seed: int = 0, timeout: float = 120.0, on_trial: OnTrial | None = None, **kw
) -> SetResult:
    """Source C's row run (omni4 unless ``profile`` says otherwise): from one headland, down a whole
    aisle (15 m of rows), to the other headland, past the aisle's unmapped mounds / puddles; aisle,
    direction and the exact start and goal vary per trial. The scenario's workers are left out
    (people have their own set)."""
    from maps.stock import stock_world_path
    from robot.sim.scenario import load_scenario, sidecar_path

    path = stock_world_path("greenhouse")
    features = load_scenario(sidecar_path(path)).obstacles
    rng = np.random.default_rng(seed)
    o = SetOptions(seed, on_trial, **{"profile": "omni4", **kw})

    def draw() -> Iterator[Trial]:
        for i in range(n):
            y = GREENHOUSE_AISLES[int(rng.integers(len(GREENHOUSE_AISLES)))] + float(rng.uniform(-0.1, 0.1))
            west, east = float(rng.uniform(1.0, 1.6)), float(rng.uniform(18.2, 18.6))
            start, goal = Pose2D(west, y, 0.0), Pose2D(east, y, 0.0)
            if rng.random() < 0.5:
                start, goal = Pose2D(east, y, math.pi), Pose2D(west, y, math.pi)
            world = None
            if o.only is None or i in o.only:  # loading a world is not free: only for driven trials
                world = World.from_yaml(path, start_pose=start)
                for f in features:
                    world.add_polygon(f.polygon, kind=f.kind)
            yield Trial(start, goal, world=world)

    return _run_set("greenhouse rows", "row", World.from_yaml(path).grid, draw(), timeout, o)


def _free_poses(stack: SimStack, clearance: float, rng: np.random.Generator, k: int) -> np.ndarray:
    from scipy.ndimage import distance_transform_edt

    grid = stack.localization.grid
    assert grid is not None
    clear = distance_transform_edt(grid.free_mask()) * grid.resolution
    r, c = np.nonzero(clear > clearance)
    pick = rng.choice(r.size, k, replace=True)
    return grid.geometry.cell_to_world(r[pick], c[pick])


def random_goal_trials(
    world_name: str,
    n: int = 50,
    seed: int = 0,
    timeout: float = 90.0,
    clearance: float = 0.4,
    on_trial: OnTrial | None = None,
    controller: str | None = None,
) -> SetResult:
    """``n`` random reachable goals in a stock world, driven one after the other (see module doc)."""
    from maps.stock import stock_world_path
    from nav.planning import PlannerError

    world = World.from_yaml(stock_world_path(world_name))
    stack = build_sim_stack(world.grid, world, world.start_pose, seed=seed, controller=controller)
    stack.localization.set_initial_pose(world.start_pose)
    rng = np.random.default_rng(seed)

    def run(out: SetResult) -> None:
        tries = 0
        while out.n < n and tries < 20 * n:
            tries += 1
            here = stack.driver.truth_pose
            cands = _free_poses(stack, clearance, rng, 16)
            d = np.hypot(cands[:, 0] - here.x, cands[:, 1] - here.y)
            ok = np.flatnonzero((d > 1.5) & (d < 8.0))
            if ok.size == 0:
                continue
            x, y = cands[ok[0]]
            goal = Pose2D(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
            cm = stack.navigation.global_costmap
            try:  # reachable from where the robot stands (the "random reachable goals")
                plan = stack.navigation.planner.plan(cm, stack.session.pose, goal)
            except PlannerError:
                continue
            # Goals 1.5-8 m away can be 20+ m apart by corridor (office): a route of L m takes at
            # least L / max_vel_x, so the limit is the larger of ``timeout`` and twice that.
            seg = np.diff(np.asarray(plan.poses)[:, :2], axis=0)
            route = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
            limit = max(timeout, 2.0 * route / stack.driver.profile.limits.max_vel_x)
            trial = _run(stack, f"{world_name} {out.n}", here, goal, limit, on_trial)
            out.trials.append(trial)
            if not trial.result.reached:
                # An operator would rescue a robot that gave up (often wedged against something
                # with no recovery behaviour yet): carry it to a free spot and set its pose, so one
                # failure is counted once instead of failing every later goal from the same place.
                x, y = _free_poses(stack, 0.6, rng, 1)[0]
                rescue = Pose2D(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
                stack.driver.teleport(rescue)
                stack.localization.set_initial_pose(rescue)
                stack.session.run_for(0.5)

    try:
        return _timed(world_name, run)
    finally:
        stack.session.close()
