"""Simulator benchmarks: lidar ray casting and the headless real-time factor.

Timings are the best of several repeats (like ``timeit``) and CPU time of this process, so a busy
machine shared with other jobs does not inflate them.
"""

from __future__ import annotations

import math
import time

import numpy as np

from bench.core import Benchmark, Figure


def _best(fn, repeats: int) -> float:
    """Best CPU time of ``repeats`` calls (seconds)."""
    best = math.inf
    for _ in range(repeats):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def raycast() -> list[Figure]:
    """360 beams from one origin in the office world, 6 m (RPLidar A1) and 10 m (source C) range,
    from 20 random free poses; CPU time, best of 20 per pose, median over poses."""
    from nav.raycast import RayCaster, cast_rays
    from robot.sim import World

    world = World.stock("office")
    caster = RayCaster(world.occupied, world.geometry, clearance=True)  # what the simulator uses
    plain = RayCaster(world.occupied, world.geometry)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    rng = np.random.default_rng(0)
    free_r, free_c = np.nonzero(~world.occupied)
    pick = rng.integers(0, free_r.size, 20)
    origins = world.geometry.cell_to_world(free_r[pick], free_c[pick])
    figs = []
    for rmax in (6.0, 10.0):
        per = [_best(lambda o=o, r=rmax: caster.cast(o, angles, r), 20) for o in origins]
        ms = float(np.median(per)) * 1e3
        figs.append(
            Figure(f"360 beams, {rmax:g} m, office (median over 20 poses)", ms, "ms", "< 2 ms", ms < 2.0)
        )
    plain_ms = float(np.median([_best(lambda o=o: plain.cast(o, angles, 6.0), 20) for o in origins])) * 1e3
    figs.append(Figure("360 beams, 6 m, office, no clearance skip", plain_ms, "ms", "< 2 ms", plain_ms < 2.0))
    fn_ms = _best(lambda: cast_rays(world.occupied, world.geometry, origins[0], angles, 6.0), 20) * 1e3
    figs.append(Figure("cast_rays() incl. table build, 6 m", fn_ms, "ms"))
    particles = rng.uniform([1, 9.2], [29, 10.8], size=(500, 2))
    beams = np.linspace(-np.pi, np.pi, 30, endpoint=False)[None, :] + rng.uniform(-np.pi, np.pi, (500, 1))
    amcl_ms = _best(lambda: caster.cast(particles, beams, 6.0), 3) * 1e3
    figs.append(Figure("500 particles x 30 beams, 6 m (AMCL beam model)", amcl_ms, "ms"))
    return figs


def realtime_factor(profile_name: str = "skid4", seconds: float = 60.0) -> list[Figure]:
    """Drive a weaving pattern (at most 0.5 m/s) in the office world headless with a virtual clock,
    reading the driver and integrating odometry at 20 Hz like the control loop."""
    from nav.types import Twist2D
    from robot.clock import VirtualClock
    from robot.odometry import WheelOdometry
    from robot.profiles import load_profile
    from robot.sim import SimDriver, World

    profile = load_profile(profile_name)
    clock = VirtualClock()
    world = World.stock("office")
    _ = world.raycaster, world.clearance_map  # built once per world, at load time in real use
    driver = SimDriver(world, profile, clock, seed=0)
    odom = WheelOdometry(profile)
    period = 0.05
    collisions = 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(round(seconds / period)):
        frame = driver.read()
        if frame.ticks is not None:
            odom.update(frame.ticks, frame.imu)
        collisions += frame.collision
        # weave down the corridor, turning around every 20 s
        heading_back = (k * period // 20.0) % 2 == 1
        wz = 0.6 * math.sin(k * period * 1.3) + (1.0 if heading_back and (k * period % 20.0) < 3.2 else 0.0)
        if profile.is_omni:  # holonomic: slalom sideways, reverse along the corridor every 20 s
            direction = -1.0 if (k * period // 20.0) % 2 == 1 else 1.0
            driver.command(Twist2D(0.5 * direction, 0.3 * math.sin(k * period * 1.3), 0.0))
        else:
            driver.command(Twist2D(min(profile.limits.max_vel_x, 0.5), 0.0, wz))
        clock.advance(period)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    rtf_cpu = seconds / cpu
    return [
        Figure(
            f"real-time factor, {profile_name}, office (CPU time)", rtf_cpu, "x", ">= 50x", rtf_cpu >= 50.0
        ),
        Figure(f"real-time factor, {profile_name}, office (wall time)", seconds / wall, "x"),
        Figure("collisions during the pattern (frames)", float(collisions), "frames"),
    ]


BENCHMARKS = [
    Benchmark(name="sim.raycast", run=raycast),
    Benchmark(name="sim.realtime", run=realtime_factor),
    Benchmark(name="sim.realtime_omni", run=lambda: realtime_factor("omni4"), group="slow"),
]
