"""Safety-layer benchmarks: the filter's cost per control cycle and what it achieves in the simulator.

- ``safety.filter``: CPU time of one ``SafetyFilter`` call with a fresh 360-beam scan (the worst
  case: a scan is parsed and the approach simulated) in the office corridor, skid4 and omni4.
- ``safety.stop``: full speed at a wall through a Session on a virtual clock (the base's own IR
  motor stop off): collisions and the gap left to the wall.
- ``safety.step_in`` (slow): source A's moving-obstacle trial without a planner: a person steps in
  about 0.3 m ahead of a robot driving at full speed, 20 trials with random timing; collisions.
"""

from __future__ import annotations

import math
import time
from functools import partial

import numpy as np

from bench.core import Benchmark, Figure


def _best(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def filter_cost() -> list[Figure]:
    from nav.types import Pose2D, Twist2D
    from robot.base import SensorFrame
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.safety import SafetyFilter
    from robot.sim import SimDriver, World

    world = World.stock("office")
    figs = []
    for name in ("skid4", "omni4"):
        profile = load_profile(name)
        # near the corridor's pillar so that every zone has readings to work on
        driver = SimDriver(world, profile, VirtualClock(), seed=0, start_pose=Pose2D(14.55, 9.7, 0.0))
        scan = driver.read().scan
        cmd = Twist2D(profile.limits.max_vel_x, 0.0, 0.3)
        f = SafetyFilter(profile)
        now = scan.stamp + 0.05  # same stamp every call: the scan stays fresh, no shift to add
        with_scan = _best(partial(f, cmd, SensorFrame(stamp=now, scan=scan)), 30) * 1e3
        without = _best(partial(f, cmd, SensorFrame(stamp=now)), 30) * 1e3
        figs.append(
            Figure(f"filter call with a new scan, {name}", with_scan, "ms", "< 1 ms", with_scan < 1.0)
        )
        figs.append(Figure(f"filter call between scans, {name}", without, "ms", "< 1 ms", without < 1.0))
    return figs


def _wall_run(name: str, ir: bool) -> tuple[int, float]:
    import dataclasses

    from app.session import Session
    from nav.types import Pose2D, Twist2D
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.safety import SafetyFilter
    from robot.sim import SimDriver, SimOptions, World

    profile = load_profile(name)
    if not ir:
        profile = dataclasses.replace(profile, ir=())
    clock = VirtualClock()
    world = World.box(6.0, 4.0)
    start = Pose2D(6.0 - 0.1 - 1.5, 2.0, 0.0)
    driver = SimDriver(world, profile, clock, seed=1, start_pose=start, options=SimOptions(ir_stop=False))
    s = Session(driver, clock=clock, grid=world.grid, start_pose=start)
    s.safety = SafetyFilter(profile)
    s.request_mode("teleop")
    for _ in range(round(12.0 / s.period)):
        s.set_teleop(Twist2D(profile.limits.max_vel_x, 0.0, 0.0), "bench")
        s.run_for(s.period)
    front = float(np.max(profile.footprint_polygon(32)[:, 0]))
    return s.collisions, 6.0 - 0.1 - (driver.truth_pose.x + front)


def stop_at_wall() -> list[Figure]:
    figs = []
    for name, ir in (("skid4", True), ("skid4", False), ("omni4", False)):
        collisions, gap = _wall_run(name, ir)
        label = f"{name}{'' if ir else ', lidar only'}"
        figs.append(
            Figure(f"collisions at full speed into a wall, {label}", collisions, "", "0", collisions == 0)
        )
        figs.append(Figure(f"gap left to the wall, {label}", gap, "m", "0-0.08 m", 0.0 < gap <= 0.08))
    return figs


def step_in_trials(trials: int = 20) -> list[Figure]:
    from app.session import Session
    from nav.types import Pose2D, Twist2D
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.safety import SafetyFilter
    from robot.sim import SimDriver, SimOptions, World

    rng = np.random.default_rng(5)
    collisions, min_gaps = 0, []
    profile = load_profile("skid4")
    for k in range(trials):
        clock = VirtualClock()
        world = World.box(12.0, 4.0)
        start = Pose2D(1.0, 2.0, 0.0)
        driver = SimDriver(world, profile, clock, seed=k, start_pose=start, options=SimOptions(ir_stop=False))
        trigger = float(rng.uniform(1.0, 2.5))
        standby_x = float(rng.uniform(3.0, 6.0))
        driver.people.add_step_in(standby_x, 2.0 + float(rng.uniform(0.6, 1.2)), trigger, dwell=3.0)
        s = Session(driver, clock=clock, grid=world.grid, start_pose=start)
        s.safety = SafetyFilter(profile)
        s.request_mode("teleop")
        gap = math.inf
        for _ in range(round(10.0 / s.period)):
            s.set_teleop(Twist2D(profile.limits.max_vel_x, 0.0, 0.0), "bench")
            s.run_for(s.period)
            p = driver.people.xy[0]
            t = driver.truth_pose
            gap = min(gap, math.hypot(p[0] - t.x, p[1] - t.y) - 0.15 - profile.circumscribed_radius)
        collisions += s.collisions > 0
        min_gaps.append(gap)
    return [
        Figure(f"trials with a collision (of {trials})", collisions, "", "0", collisions == 0),
        Figure("closest approach to the person (median, circumscribed)", float(np.median(min_gaps)), "m"),
    ]


BENCHMARKS = [
    Benchmark(name="safety.filter", run=filter_cost),
    Benchmark(name="safety.stop", run=stop_at_wall),
    Benchmark(name="safety.step_in", run=step_in_trials, group="slow"),
]
