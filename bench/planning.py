"""Benchmarks of the planning area: global planners, inflation and costmap updates.

Maps: seeded synthetic office floors (4 m rooms, 1 m doors, dense clutter: a stress case) at
0.05 m, and real ones: Nav2's tb3_sandbox (384 x 384) and warehouse (1006 x 1674 at 0.03 m), and
the Willow Garage floor (navigation_stage/willow-full-0.05, 58 x 47 m). Start and goal are the
opposite extreme cells of the largest traversable region. Each figure is the median of
several warm runs (numba functions are compiled or loaded from cache first).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path as FsPath

import numpy as np

from bench.core import Benchmark, Figure
from bench.datasets import ROS_MAPS
from nav.costmap import Costmap2D, CostmapOptions, inflate, local_costmap_options
from nav.planning import AStarPlanner, DijkstraPlanner, GridPlanner, PlannerOptions, nearest_free_pose
from nav.types import Costmap, GridGeometry, OccupancyGrid, Pose2D

RES = 0.05
WILLOW = ROS_MAPS / "navigation_stage/willow-full-0.05.yaml"
TB3_SANDBOX = ROS_MAPS / "nav2_bringup/tb3_sandbox.yaml"  # Nav2's own sandbox, 384 x 384 at 0.05 m
WAREHOUSE = ROS_MAPS / "nav2_bringup/warehouse.yaml"  # Nav2's warehouse, 1006 x 1674 at 0.03 m


def _timed_ms(fn: Callable[[], object], runs: int) -> tuple[float, float]:
    """(minimum CPU ms, median wall ms) over ``runs`` warm calls of a single-threaded ``fn``.

    The target is checked on CPU time (``time.process_time``): on an idle machine it equals wall
    time, and unlike wall time it does not count the time other processes hold the cores (the
    development machine is shared, with load averages of 5-10 on 2 cores)."""
    fn()  # warm-up (numba load / compile, caches)
    cpu, wall = [], []
    for _ in range(runs):
        w, c = time.perf_counter(), time.process_time()
        fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return min(cpu) * 1e3, statistics.median(wall) * 1e3


def _figures(name: str, fn: Callable[[], object], runs: int, target_ms: float) -> list[Figure]:
    cpu, wall = _timed_ms(fn, runs)
    return [
        Figure(name, cpu, "ms", f"< {target_ms:g} ms", cpu < target_ms),
        Figure(f"{name} (wall, median)", wall, "ms"),
    ]


def office_map(cells: int, seed: int = 0) -> OccupancyGrid:
    """A square office floor: walls every 80 cells (4 m rooms), a 20-cell door in each wall segment,
    and random 0.2-0.6 m boxes; the outer wall closed."""
    rng = np.random.default_rng(seed)
    data = np.zeros((cells, cells), dtype=np.int8)
    room = 80
    for k in range(0, cells, room):
        data[k, :] = 100
        data[:, k] = 100
    for a in range(0, cells, room):
        for b in range(0, cells, room):
            # one door in the wall segment on each of row a and column a
            d = b + rng.integers(10, room - 30)
            if a > 0:
                data[a, d : d + 20] = 0
                data[d : d + 20, a] = 0
    n_boxes = cells * cells // 800
    r = rng.integers(2, cells - 14, n_boxes)
    c = rng.integers(2, cells - 14, n_boxes)
    s = rng.integers(4, 12, n_boxes)
    for ri, ci, si in zip(r, c, s, strict=True):
        data[ri : ri + si, ci : ci + si] = 100
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return OccupancyGrid(GridGeometry(RES, cells, cells), data)


def _corners(cm: Costmap) -> tuple[Pose2D, Pose2D]:
    w, h = cm.geometry.size_m
    s = nearest_free_pose(cm, Pose2D(0.4, 0.4), 2.0)
    g = nearest_free_pose(cm, Pose2D(w - 0.4, h - 0.4), 2.0, allow_unknown=False)
    assert s is not None and g is not None
    return s, g


def _component_corners(cm: Costmap) -> tuple[Pose2D, Pose2D]:
    """Opposite extreme cells (min and max row + col) of the largest 8-connected traversable region."""
    from scipy import ndimage

    free = cm.costs < 253
    labels, _ = ndimage.label(free, structure=np.ones((3, 3)))
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    rr, cc = np.nonzero(labels == sizes.argmax())
    a, b = np.argmin(rr + cc), np.argmax(rr + cc)
    xy = cm.geometry.cell_to_world(np.array([rr[a], rr[b]]), np.array([cc[a], cc[b]]))
    return Pose2D(*xy[0]), Pose2D(*xy[1])


def _real_map_costmap(path: FsPath, robot_radius: float) -> Costmap:
    from maps.mapio import load_map_yaml

    return Costmap2D.from_map(load_map_yaml(path), CostmapOptions(robot_radius=robot_radius)).costmap()


def _plan_figures(
    label: str, cm: Costmap, start: Pose2D, goal: Pose2D, target_ms: float, runs: int
) -> list[Figure]:
    figs: list[Figure] = []
    opts = PlannerOptions(allow_unknown=False, max_planning_time=30.0)
    planners: list[GridPlanner] = [AStarPlanner(opts), DijkstraPlanner(opts)]
    for planner in planners:
        path, stats = planner.plan_with_stats(cm, start, goal)
        assert stats.goal_reached_exactly, f"{label}: goal not reached"
        figs += _figures(
            f"{planner.name} {label}", lambda p=planner: p.plan(cm, start, goal), runs, target_ms
        )
        figs.append(Figure(f"{planner.name} {label} expansions", stats.expansions, "nodes"))
        figs.append(Figure(f"{planner.name} {label} length", path.length, "m"))
    return figs


def _office_costmap(cells: int) -> Costmap:
    return Costmap2D.from_map(office_map(cells), CostmapOptions(robot_radius=0.15)).costmap()


def bench_plan_400() -> list[Figure]:
    cm = _office_costmap(400)
    return _plan_figures("400x400 corner", cm, *_corners(cm), 30.0, 9)


def bench_plan_tb3() -> list[Figure]:
    cm = _real_map_costmap(TB3_SANDBOX, 0.15)
    return _plan_figures("tb3_sandbox 384x384 corner", cm, *_component_corners(cm), 30.0, 9)


def bench_plan_willow() -> list[Figure]:
    cm = _real_map_costmap(WILLOW, 0.2)
    return _plan_figures("willow corner", cm, *_component_corners(cm), 300.0, 5)


def bench_plan_warehouse() -> list[Figure]:
    cm = _real_map_costmap(WAREHOUSE, 0.2)
    return _plan_figures("warehouse 1006x1674 corner", cm, *_component_corners(cm), 1000.0, 3)


def bench_plan_2000() -> list[Figure]:
    cm = _office_costmap(2000)
    return _plan_figures("2000x2000 corner", cm, *_corners(cm), 1000.0, 3)


def bench_inflation() -> list[Figure]:
    grid = office_map(2000, seed=1)
    raw = Costmap2D.from_map(grid, CostmapOptions(use_inflation_layer=False)).costmap().costs
    opts = CostmapOptions()
    figs = _figures(
        "inflate 2000x2000 office", lambda: inflate(raw, RES, 0.1, opts.inflation_layer), 7, 100.0
    )
    if WILLOW.exists():
        from maps.mapio import load_map_yaml

        w = load_map_yaml(WILLOW)
        wr = Costmap2D.from_map(w, CostmapOptions(use_inflation_layer=False)).costmap().costs
        big = np.tile(wr, (3, 2))[:2000, :2000].copy()
        figs += _figures(
            "inflate 2000x2000 tiled willow", lambda: inflate(big, RES, 0.1, opts.inflation_layer), 7, 100.0
        )
    return figs


def bench_costmap_update() -> list[Figure]:
    """One control cycle's costmap work: a 360-beam scan into the local 3 x 3 m window and into the
    Willow-sized global costmap (clear + mark + partial re-inflation), and DWA-style footprint costs."""
    rng = np.random.default_rng(0)
    a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    r = rng.uniform(0.5, 4.0, 360)
    local = Costmap2D.rolling(local_costmap_options(robot_radius=0.15))
    grid = office_map(1000)
    glob = Costmap2D.from_map(grid, CostmapOptions(robot_radius=0.15))
    glob.costmap()
    state = {"x": 10.0}

    def cycle(cm: Costmap2D) -> None:
        state["x"] += 0.013
        pose = Pose2D(state["x"], 10.0, 0.0)
        pts = np.column_stack((pose.x + r * np.cos(a), pose.y + r * np.sin(a)))
        cm.update(pose, pts)
        cm.costmap()

    poses = np.column_stack((rng.uniform(9, 11, 2000), rng.uniform(9, 11, 2000), rng.uniform(-3, 3, 2000)))
    square = np.array([[0.12, 0.1], [-0.12, 0.1], [-0.12, -0.1], [0.12, -0.1]])
    return [
        *_figures("local 3x3 m update + snapshot", lambda: cycle(local), 21, 10.0),
        *_figures("global 50x50 m update + snapshot", lambda: cycle(glob), 21, 50.0),
        *_figures("footprint_cost 2000 poses", lambda: local.footprint_cost(poses, square), 21, 10.0),
    ]


BENCHMARKS = [
    Benchmark(name="planning.plan_400", run=bench_plan_400),
    Benchmark(name="planning.plan_tb3", run=bench_plan_tb3),
    Benchmark(name="planning.plan_willow", run=bench_plan_willow),
    Benchmark(name="planning.plan_warehouse", run=bench_plan_warehouse, group="slow"),
    Benchmark(name="planning.plan_2000", run=bench_plan_2000, group="slow"),
    Benchmark(name="planning.inflation", run=bench_inflation),
    Benchmark(name="planning.costmap_update", run=bench_costmap_update),
]
