"""Navigation scenario benchmarks (``navdeck bench scenarios``): the whole stack on a virtual clock.

``scenarios.quick`` and ``scenarios.sim_speed`` run with the default group; the full sets (50 random
goals per stock world, source A's 20-trial sets) are in group ``slow`` and run by name.
"""

from __future__ import annotations

import time
from dataclasses import replace

from bench.core import Benchmark, Figure

# Source A (ROS2 + Nav2 thesis), goals reached out of 20.
SOURCE_A = {"straight": 19, "turns": 18, "fixed obstacle": 19}


def _set_figures(res, target_pct: float | None = None, source_a: int | None = None) -> list[Figure]:
    from bench.scenarios import SetResult

    assert isinstance(res, SetResult)
    pct = res.reached_pct
    if source_a is not None:
        target, ok = f">= {source_a}/20 (source A)", pct >= 100.0 * source_a / 20.0
    elif target_pct is not None:
        target, ok = f">= {target_pct:g} %", pct >= target_pct
    else:
        target, ok = "", None
    figs = [
        Figure(f"{res.name} reached ({res.n} goals)", pct, "%", target, ok),
        Figure(f"{res.name} collisions", float(res.collisions), "count", "0", res.collisions == 0),
        Figure(
            f"{res.name} localization RMS", res.localization_rms, "m", "< 0.05 m", res.localization_rms < 0.05
        ),
        Figure(f"{res.name} simulated / CPU time", res.sim_s / max(res.cpu_s, 1e-9), "x"),
    ]
    for line in res.failures():
        print(f"  failed: {line}")
    return figs


def _quick() -> list[Figure]:
    from bench.scenarios import fixed_obstacle_trials, random_goal_trials, straight_trials, turn_trials

    figs: list[Figure] = []
    for res in (
        straight_trials(2, seed=1),
        turn_trials(2, seed=1),
        fixed_obstacle_trials(2, seed=1),
        random_goal_trials("apartment", 4, seed=1),
    ):
        figs += _set_figures(res, target_pct=100.0)
    return figs


def _random(world: str) -> list[Figure]:
    from bench.scenarios import random_goal_trials

    return _set_figures(random_goal_trials(world, 50, seed=0), target_pct=98.0)


def _source_a() -> list[Figure]:
    from bench.scenarios import fixed_obstacle_trials, straight_trials, turn_trials

    figs: list[Figure] = []
    for res in (straight_trials(20), turn_trials(20), fixed_obstacle_trials(20)):
        figs += _set_figures(res, source_a=SOURCE_A[res.name])
    return figs


def _sim_speed() -> list[Figure]:
    """``navdeck sim-nav`` speed: simulated seconds per wall second and per CPU second of one run
    across the office world (AMCL, both costmaps, A*, DWA at 20 Hz). The wall figure depends on
    what else the machine runs; the CPU figure is what one free core would give."""
    from pathlib import Path

    from app.commands import sim_nav
    from app.commands.sim_nav import SimNavConfig, run_sim_nav

    root = Path(__file__).resolve().parents[1]
    cfg = SimNavConfig(root / "maps/stock/office.yaml", (2.0, 10.0, 0.0), ((8.0, 10.0, 0.0),), seed=0)
    run_sim_nav(replace(cfg, goals=((3.0, 10.0, 0.0),)))  # warm-up: imports, numba caches
    drive_cpu: list[float] = []
    inner = sim_nav.drive

    def timed_drive(*args, **kwargs):  # CPU of the simulation loop alone, without start-up
        c = time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            drive_cpu.append(time.process_time() - c)

    sim_nav.drive = timed_drive
    try:
        c0 = time.process_time()
        res = run_sim_nav(cfg)
        cpu = time.process_time() - c0
    finally:
        sim_nav.drive = inner
    loop = drive_cpu[-1]
    return [
        Figure("sim-nav reached", float(res.reached), "bool", "1", res.reached),
        Figure("sim-nav speed (wall)", res.speedup, "x real time", ">= 20x", res.speedup >= 20.0),
        Figure("sim-nav speed (CPU)", res.time_s / cpu, "x real time", ">= 20x", res.time_s / cpu >= 20.0),
        Figure("sim-nav loop speed (CPU, no start-up)", res.time_s / loop, "x real time", ">= 20x"),
        Figure("sim-nav tick CPU", 1e3 * loop / (res.time_s * cfg.rate_hz), "ms", "< 2.5 ms"),
    ]


BENCHMARKS = [
    Benchmark(name="scenarios.quick", run=_quick),
    Benchmark(name="scenarios.sim_speed", run=_sim_speed),
    Benchmark(name="scenarios.random_apartment", run=lambda: _random("apartment"), group="slow"),
    Benchmark(name="scenarios.random_office", run=lambda: _random("office"), group="slow"),
    Benchmark(name="scenarios.random_greenhouse", run=lambda: _random("greenhouse"), group="slow"),
    Benchmark(name="scenarios.source_a", run=_source_a, group="slow"),
]
