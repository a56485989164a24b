"""Benchmarks of the TEB local planner: one band optimization (<= 60 poses) must take < 50 ms so
the controller runs at 10 Hz with room to spare (issue 5).

Scenes (shared with tests/test_teb_controller.py): a 2 m wide corridor with a 0.15 m round obstacle
on the straight global path; the skid4 robot's 3 m look-ahead band bending around it (40 poses), a
60-pose band (the cap: 4.5 m at 0.075 m spacing) and the omni4 robot's band. Figures are medians of
the thread's CPU time (meaningful on a loaded machine where wall time is not) over cold-started
cycles (the worst case: warm starts begin near the optimum), plus the default solver's speed-up
over ``solver="scipy"`` measured in the same run, which the machine's load does not skew.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from bench.core import Benchmark, Figure

if TYPE_CHECKING:
    from nav.control.teb import TebController
    from nav.control.teb_options import TebOptions
    from nav.types import Costmap, Path

TARGET_MS = 50.0
RES = 0.05
OBSTACLE = (1.5, 0.0, 0.15)  # x, y, radius (m) of the bench scenes' obstacle


def skid_options(**overrides) -> TebOptions:
    """TebOptions of the skid4 profile (diff drive, 0.26 m/s), as the server builds them."""
    return _profile_options("skid4", overrides)


def omni_options(**overrides) -> TebOptions:
    """TebOptions of the omni4 profile (holonomic, 1.5 m/s, round 0.25 m), as the server builds them."""
    return _profile_options("omni4", overrides)


def _profile_options(profile: str, overrides: dict) -> TebOptions:
    from nav.control.teb_options import TebOptions
    from robot.profiles import load_profile

    return TebOptions.for_robot(load_profile(profile), **overrides)


def corridor(
    obstacle: tuple[float, float, float] | None = None, width: float = 2.0, length: float = 6.0
) -> Costmap:
    """A corridor along +x from x = -0.5 (``length`` m of grid) with 2-cell lethal walls at its
    edges, ``width`` m apart, optionally a round obstacle (x, y, radius) of lethal cells."""
    import numpy as np

    from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Pose2D

    w, h = round(length / RES), round(width / RES) + 4
    geo = GridGeometry(RES, w, h, Pose2D(-0.5, -(h * RES) / 2, 0.0))
    costs = np.zeros((h, w), np.uint8)
    costs[:2, :] = costs[-2:, :] = LETHAL_OBSTACLE
    if obstacle is not None:
        rows, cols = np.indices((h, w))
        xy = geo.cell_to_world(rows.ravel(), cols.ravel())
        d = np.hypot(xy[:, 0] - obstacle[0], xy[:, 1] - obstacle[1]).reshape(h, w)
        costs[d <= obstacle[2]] = LETHAL_OBSTACLE
    return Costmap(geo, costs)


def straight_path(length: float = 5.0, n: int = 101) -> Path:
    """A straight global path along +x from the origin."""
    import numpy as np

    from nav.types import Path

    xs = np.linspace(0.0, length, n)
    return Path(np.column_stack((xs, np.zeros(n), np.zeros(n))))


def _scene(kind: str, solver: str = "lm_banded") -> tuple[TebController, Path, Costmap]:
    from nav.control.teb import TebController

    if kind == "omni":
        o = omni_options(solver=solver)
    else:
        o = skid_options(solver=solver, max_global_plan_lookahead_dist=4.5 if kind == "skid60" else 3.0)
    return TebController(o), straight_path(6.0, 121), corridor(OBSTACLE, length=7.0)


def _cold_cycles(kind: str, solver: str, cycles: int) -> tuple[list[float], list[float], int, int]:
    """(CPU s, wall s, band size, solver evaluations) of ``cycles`` cold-started cycles."""
    import numpy as np

    from nav.types import Pose2D, Twist2D

    ctl, path, cm = _scene(kind, solver)
    pose, vel = Pose2D(), Twist2D(0.1, 0.0, 0.0)
    ctl.set_path(path)
    ctl.compute(pose, vel, cm)  # warm-up (imports, caches)
    cpu, wall, size, evals = [], [], 0, []
    for _ in range(cycles):
        ctl.reset()
        ctl.set_path(path)
        c0, w0 = time.thread_time(), time.perf_counter()
        _, dbg = ctl.compute(pose, vel, cm)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
        size = max(size, len(dbg.band))
        evals.append(dbg.nfev)
    return cpu, wall, size, int(np.median(evals))


def _measure(kind: str, cycles: int = 15) -> list[Figure]:
    import numpy as np

    cpu, wall, size, evals = _cold_cycles(kind, "lm_banded", cycles)
    ref_cpu, _, _, ref_evals = _cold_cycles(kind, "scipy", max(cycles // 3, 3))
    cpu_ms = float(np.median(cpu)) * 1e3
    return [
        Figure(f"{kind} cycle CPU ({size} poses)", cpu_ms, "ms", f"< {TARGET_MS:g} ms", cpu_ms < TARGET_MS),
        Figure(f"{kind} cycle wall", float(np.median(wall)) * 1e3, "ms"),
        Figure(f"{kind} residual + Jacobian evaluations", evals, "calls"),
        Figure(f"{kind} scipy solver cycle CPU (same run)", float(np.median(ref_cpu)) * 1e3, "ms"),
        Figure(f"{kind} scipy solver residual evaluations", ref_evals, "calls"),
        Figure(f"{kind} speed-up over scipy", float(np.median(ref_cpu) / np.median(cpu)), "x"),
    ]


def _warm(kind: str, seconds: float = 12.0, dt: float = 0.1) -> list[Figure]:
    """Closed loop through the scene at 10 Hz with ideal tracking: the steady-state (warm-started)
    cycle, and its worst case."""
    import math

    import numpy as np

    from nav.types import Pose2D, Twist2D, wrap_angle

    ctl, path, cm = _scene(kind)
    ctl.set_path(path)
    pose, vel = Pose2D(), Twist2D()
    cpu = []
    for _ in range(round(seconds / dt)):
        c0 = time.thread_time()
        cmd, _ = ctl.compute(pose, vel, cm)
        cpu.append(time.thread_time() - c0)
        ct, st = math.cos(pose.theta), math.sin(pose.theta)
        pose = Pose2D(
            pose.x + (cmd.vx * ct - cmd.vy * st) * dt,
            pose.y + (cmd.vx * st + cmd.vy * ct) * dt,
            float(wrap_angle(pose.theta + cmd.wz * dt)),
        )
        vel = cmd
    ms = np.array(cpu[1:]) * 1e3
    return [
        Figure(
            f"{kind} warm cycle CPU median",
            float(np.median(ms)),
            "ms",
            f"< {TARGET_MS:g} ms",
            bool(np.median(ms) < TARGET_MS),
        ),
        Figure(f"{kind} warm cycle CPU p95", float(np.percentile(ms, 95)), "ms"),
    ]


def bench_skid() -> list[Figure]:
    return _measure("skid") + _warm("skid")


def bench_skid60() -> list[Figure]:
    return _measure("skid60")


def bench_omni() -> list[Figure]:
    return _measure("omni") + _warm("omni", seconds=5.0)


BENCHMARKS = [
    Benchmark(name="teb.skid_cycle", run=bench_skid),
    Benchmark(name="teb.skid_60_poses", run=bench_skid60),
    Benchmark(name="teb.omni_cycle", run=bench_omni),
]
