"""Simulator benchmarks for people, scenarios and idle time (the moving-robot RTF is ``sim.realtime``).

- ``sim2.idle_rtf``: real-time factor of a robot standing still in the office (a server waiting for
  an operator): the physics skips substeps at rest, the lidar still scans.
- ``sim2.people_rtf``: real-time factor of the ``sim.realtime`` weave with the office scenario's four
  people walking (lidar, IR and collision checks against their discs).
"""

from __future__ import annotations

import math
import time

from bench.core import Benchmark, Figure


def _rtf(profile_name: str, seconds: float, scenario: bool, moving: bool) -> float:
    from nav.types import Twist2D
    from robot.clock import VirtualClock
    from robot.odometry import WheelOdometry
    from robot.profiles import load_profile
    from robot.sim import SimDriver, World

    profile = load_profile(profile_name)
    clock = VirtualClock()
    world = World.stock("office", scenario=scenario)
    _ = world.raycaster, world.clearance_map
    driver = SimDriver(world, profile, clock, seed=0)
    odom = WheelOdometry(profile)
    period = 0.05
    cpu0 = time.process_time()
    for k in range(round(seconds / period)):
        frame = driver.read()
        if frame.ticks is not None:
            odom.update(frame.ticks, frame.imu)
        if moving:
            driver.command(Twist2D(min(profile.limits.max_vel_x, 0.5), 0.0, 0.6 * math.sin(k * period * 1.3)))
        clock.advance(period)
    return seconds / (time.process_time() - cpu0)


def idle_rtf() -> list[Figure]:
    figs = []
    for name in ("skid4", "omni4"):
        rtf = _rtf(name, 60.0, scenario=False, moving=False)
        figs.append(
            Figure(f"real-time factor, {name} standing still, office", rtf, "x", ">= 50x", rtf >= 50.0)
        )
    return figs


def people_rtf() -> list[Figure]:
    rtf = _rtf("skid4", 60.0, scenario=True, moving=True)
    return [Figure("real-time factor, skid4 weave, office + 4 people", rtf, "x", ">= 50x", rtf >= 50.0)]


BENCHMARKS = [
    Benchmark(name="sim2.idle_rtf", run=idle_rtf),
    Benchmark(name="sim2.people_rtf", run=people_rtf),
]
