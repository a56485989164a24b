"""Benchmarks of the local controller: one DWA/DWB cycle with >= 500 sampled trajectories.

The scene is the common case: a robot in a 6 x 6 m room at cruise speed, one obstacle near its
path, the default critics (footprint check, path and goal critics). Figures are medians of many
cycles after a warm-up; the CPU-time figure is the thread's own time, which stays meaningful on a
loaded machine where wall time does not.
"""

from __future__ import annotations

import time

from bench.core import Benchmark, Figure

TARGET_MS = 10.0


def _scene(kind: str):
    import numpy as np
    from scipy import ndimage

    from nav.control import DwaController, DwaOptions
    from nav.types import Costmap, GridGeometry, Path, Pose2D, Twist2D

    res = 0.05
    occ = np.zeros((120, 120), dtype=bool)
    occ[:2, :] = occ[-2:, :] = occ[:, :2] = occ[:, -2:] = True
    occ[50:60, 70:76] = True  # a block just off the path
    d = ndimage.distance_transform_edt(~occ) * res
    if kind == "skid":
        opts = DwaOptions(
            footprint=((0.12, 0.10), (-0.12, 0.10), (-0.12, -0.10), (0.12, -0.10)),
            min_vel_x=-0.15,
            vx_samples=25,
            vtheta_samples=20,
        )
        vel = Twist2D(0.2, 0.0, 0.3)
    else:
        opts = DwaOptions(
            holonomic=True,
            robot_radius=0.25,
            min_vel_x=-1.5,
            max_vel_x=1.5,
            min_vel_y=-1.5,
            max_vel_y=1.5,
            max_speed_xy=1.5,
            max_vel_theta=0.5,
            acc_lim_x=1.0,
            acc_lim_y=1.0,
            acc_lim_theta=1.0,
            decel_lim_x=-1.0,
            decel_lim_y=-1.0,
            decel_lim_theta=-1.0,
            vx_samples=10,
            vy_samples=5,
            vtheta_samples=10,
        )
        vel = Twist2D(0.8, 0.1, 0.1)
    ins = opts.inscribed_radius
    costs = np.where(d <= 0.55, 252 * np.exp(-3.0 * (d - ins)), 0)
    costs = np.where(d <= ins, 253, costs)
    costs = np.where(occ, 254, costs).astype(np.uint8)
    cm = Costmap(GridGeometry(res, 120, 120, Pose2D()), costs)
    xs = np.linspace(0.5, 5.5, 120)
    path = Path(np.column_stack((xs, np.full(120, 3.0), np.zeros(120))))
    ctl = DwaController(opts)
    ctl.set_path(path)
    return ctl, Pose2D(2.0, 3.0, 0.05), vel, cm


def _cycle(kind: str) -> list[Figure]:
    import numpy as np

    ctl, pose, vel, cm = _scene(kind)
    for _ in range(10):
        ctl.compute(pose, vel, cm)
    times, cpu = [], []
    for _ in range(100):
        t0, c0 = time.perf_counter(), time.thread_time()
        ctl.compute(pose, vel, cm)
        cpu.append(time.thread_time() - c0)
        times.append(time.perf_counter() - t0)
    dbg = ctl.last_debug
    assert dbg is not None
    k, t = dbg.trajectories.shape[:2]
    med = float(np.median(times)) * 1e3
    return [
        Figure(f"{kind} cycle median", med, "ms", target=f"< {TARGET_MS:g} ms", ok=med < TARGET_MS),
        Figure(f"{kind} cycle p90", float(np.percentile(times, 90)) * 1e3, "ms"),
        Figure(f"{kind} cycle CPU median", float(np.median(cpu)) * 1e3, "ms"),
        Figure(f"{kind} samples", float(k), "trajectories", target=">= 500", ok=k >= 500),
        Figure(f"{kind} poses per trajectory", float(t), "poses"),
    ]


def _tb3_route() -> list[Figure]:
    """The skid4 robot drives a four-waypoint loop between the pillars of Nav2's TurtleBot3 world
    map (a real SLAM map), with the project's A*, Nav2 inflation and the navigator ticking at 20 Hz
    (ideal velocity tracking). Reports success, simulated route time and per-tick compute."""
    import math

    import numpy as np

    from bench.datasets import TB3_MAP
    from maps.mapio import load_map_yaml
    from nav.control import DwaController, DwaOptions, GoalChecker, ProgressChecker
    from nav.costmap.inflation import InflationOptions, inflate
    from nav.navigator import Navigator
    from nav.planning import AStarPlanner
    from nav.types import LETHAL_OBSTACLE, NO_INFORMATION, Costmap, Pose2D, Twist2D
    from robot.profiles import load_profile

    if not TB3_MAP.exists():
        return []  # the shared datasets are not here (bench.datasets)
    grid = load_map_yaml(TB3_MAP)
    base = np.where(grid.occupied_mask(), LETHAL_OBSTACLE, np.where(grid.data < 0, NO_INFORMATION, 0))
    profile = load_profile("skid4")
    costs = inflate(base.astype(np.uint8), grid.resolution, profile.inscribed_radius, InflationOptions())
    cm = Costmap(grid.geometry, costs)
    nav = Navigator(
        AStarPlanner(), DwaController(DwaOptions.for_robot(profile)), GoalChecker(), ProgressChecker()
    )
    goals = [
        Pose2D(0.55, -0.55, 0.0),
        Pose2D(1.6, 0.55, math.pi / 2),
        Pose2D(-0.55, 0.55, math.pi),
        Pose2D(-2.0, -0.5, -math.pi / 2),
    ]
    nav.set_goals(goals)
    pose, vel, now, dt = Pose2D(-2.0, -0.5, 0.0), Twist2D(), 0.0, 0.05
    tick_ms: list[float] = []
    outcome = None
    while now < 300.0:
        t0 = time.perf_counter()
        tick = nav.tick(now, pose, vel, cm, cm)
        tick_ms.append((time.perf_counter() - t0) * 1e3)
        if tick.outcome is not None:
            outcome = tick.outcome
            break
        c = tick.cmd
        th = pose.theta + 0.5 * c.wz * dt  # midpoint step of the unicycle
        pose = Pose2D(
            pose.x + (c.vx * math.cos(th) - c.vy * math.sin(th)) * dt,
            pose.y + (c.vx * math.sin(th) + c.vy * math.cos(th)) * dt,
            pose.theta + c.wz * dt,
        )
        vel, now = c, now + dt
    reached = outcome is not None and outcome.kind == "reached"
    n_reached = float(outcome.goals_reached if outcome else 0)
    med = float(np.median(tick_ms))
    return [
        Figure("tb3 route goals reached", n_reached, "of 4", "4", reached),
        Figure("tb3 route simulated time", now, "s"),
        Figure("tb3 tick median", med, "ms", "< 50 ms (one 20 Hz period)", med < 50),
        Figure("tb3 tick p99 (includes 1 Hz replans)", float(np.percentile(tick_ms, 99)), "ms"),
    ]


BENCHMARKS = [
    Benchmark(name="control.dwa_skid", run=lambda: _cycle("skid")),
    Benchmark(name="control.dwa_omni", run=lambda: _cycle("omni")),
    Benchmark(name="control.nav_tb3", run=_tb3_route, group="slow"),
]
