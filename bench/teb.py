"""Benchmarks of the TEB local planner: one band optimization (<= 60 poses) must take < 50 ms so
the controller runs at 10 Hz with room to spare (issue 5).

Scenes: the skid4 robot's 3 m look-ahead band bending around an obstacle on its path (40 poses),
a 60-pose band (the cap: 4.5 m at 0.075 m spacing) and the omni4 robot's band. Figures are medians
over cold-started cycles (the worst case: warm starts converge in fewer iterations) and the thread's
CPU time, which stays meaningful on a loaded machine where wall time does not.
"""

from __future__ import annotations

import time

from bench.core import Benchmark, Figure

TARGET_MS = 50.0


def _scene(kind: str):
    import numpy as np

    from nav.control.teb import TebController
    from nav.control.teb_options import TebOptions
    from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Path, Pose2D, Twist2D

    res = 0.05
    w, h = 140, 44
    geo = GridGeometry(res, w, h, Pose2D(-0.5, -1.1, 0.0))
    costs = np.zeros((h, w), np.uint8)
    costs[:2, :] = costs[-2:, :] = LETHAL_OBSTACLE
    rows, cols = np.indices((h, w))
    xy = geo.cell_to_world(rows.ravel(), cols.ravel())
    costs[(np.hypot(xy[:, 0] - 1.5, xy[:, 1]) <= 0.15).reshape(h, w)] = LETHAL_OBSTACLE
    cm = Costmap(geo, costs)
    if kind == "omni":
        o = TebOptions(
            holonomic=True,
            robot_radius=0.25,
            max_vel_x=1.5,
            max_vel_x_backwards=1.5,
            max_vel_y=1.5,
            max_vel_theta=0.5,
            acc_lim_x=1.0,
            acc_lim_y=1.0,
            acc_lim_theta=1.0,
        )
    else:
        o = TebOptions(
            footprint=((0.12, 0.10), (-0.12, 0.10), (-0.12, -0.10), (0.12, -0.10)),
            max_vel_x=0.26,
            max_vel_x_backwards=0.15,
            max_vel_theta=1.0,
            acc_lim_x=2.5,
            acc_lim_theta=3.2,
            max_global_plan_lookahead_dist=4.5 if kind == "skid60" else 3.0,
        )
    xs = np.linspace(0.0, 6.0, 121)
    path = Path(np.column_stack((xs, np.zeros_like(xs), np.zeros_like(xs))))
    return TebController(o), path, cm, Pose2D(), Twist2D(0.1, 0.0, 0.0)


def _measure(kind: str, cycles: int = 15) -> list[Figure]:
    import numpy as np

    ctl, path, cm, pose, vel = _scene(kind)
    ctl.set_path(path)
    ctl.compute(pose, vel, cm)  # warm-up (imports, caches)
    cpu, wall, sizes, nfev = [], [], [], []
    for _ in range(cycles):
        ctl.reset()
        ctl.set_path(path)
        c0, w0 = time.thread_time(), time.perf_counter()
        _, dbg = ctl.compute(pose, vel, cm)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
        sizes.append(len(dbg.band))
        nfev.append(dbg.nfev + dbg.njev)
    cpu_ms = float(np.median(cpu)) * 1e3
    return [
        Figure(
            f"{kind} cycle CPU ({max(sizes)} poses)", cpu_ms, "ms", f"< {TARGET_MS:g} ms", cpu_ms < TARGET_MS
        ),
        Figure(f"{kind} cycle wall", float(np.median(wall)) * 1e3, "ms"),
        Figure(f"{kind} evaluations (f + J)", float(np.median(nfev)), "calls"),
    ]


def bench_skid() -> list[Figure]:
    return _measure("skid")


def bench_skid60() -> list[Figure]:
    return _measure("skid60")


def bench_omni() -> list[Figure]:
    return _measure("omni")


BENCHMARKS = [
    Benchmark(name="teb.skid_cycle", run=bench_skid),
    Benchmark(name="teb.skid_60_poses", run=bench_skid60),
    Benchmark(name="teb.omni_cycle", run=bench_omni),
]
