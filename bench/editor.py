"""Map editor benchmarks (issue 19): zones on big maps and zones at work in the simulator.

- ``editor.zone``: a new keepout zone on a 2000 x 2000 map: rasterize it and apply it to the global
  costmap (the changed region re-inflated), wall-clock ms, median of 7. Target < 100 ms.
- ``editor.edit``: a brush stroke of about 10,000 cells on a 2000 x 2000 map: apply it, update the
  global costmap's static layer in the edited region and re-inflate it, ms, median of 7. < 100 ms.
- ``editor.keepout`` (slow): goals on the stock worlds with a keepout zone drawn across each goal's
  shortest route (seeded); robot poses inside a keepout zone (target 0) and goals reached around it.
- ``editor.speed`` (slow): the navigator through a 30 % speed zone; the highest measured speed inside
  against the limit + 0.02 m/s.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from app.features import localization, navigation, zones
from app.runtime import Runtime
from app.settings import Settings
from app.zone_store import SpeedUnit, ZoneKind, ZoneSpec
from bench.core import Benchmark, Figure
from nav.costmap import Costmap2D
from nav.costmap.filter_layer import points_in_polygon, rasterize_polygons
from nav.map_edit import Stroke, apply_edits
from nav.planning import make_planner
from nav.types import GridGeometry, OccupancyGrid, Pose2D
from robot.clock import VirtualClock

BIG = 2000


def _big_map():
    rng = np.random.default_rng(19)
    data = np.zeros((BIG, BIG), np.int8)
    data[rng.random((BIG, BIG)) < 0.002] = 100  # clutter
    data[::200, :] = 100  # walls every 10 m with doors
    data[:, ::200] = 100
    data[100::200, :][:, np.arange(BIG) % 200 < 20] = 0
    data[:, 100::200][np.arange(BIG) % 200 < 20, :] = 0
    return OccupancyGrid(GridGeometry(0.05, BIG, BIG, Pose2D(0.0, 0.0, 0.0)), data)


def zone_on_big_map() -> list[Figure]:
    grid = _big_map()
    cm = Costmap2D.from_map(grid)
    cm.costmap()
    rng = np.random.default_rng(0)
    times, cells = [], 0
    for _ in range(7):
        # a 24-vertex zone about 8 m across somewhere on the 100 x 100 m map
        cx, cy = rng.uniform(10, 90, 2)
        a = np.sort(rng.uniform(0, 2 * np.pi, 24))
        r = rng.uniform(2.0, 4.0, 24)
        poly = np.column_stack((cx + r * np.cos(a), cy + r * np.sin(a)))
        t = time.perf_counter()
        mask = rasterize_polygons([poly], grid.geometry)
        cm.set_keepout(mask)
        cm.costmap()
        times.append((time.perf_counter() - t) * 1e3)
        cells = max(cells, int(mask.sum()))
        cm.set_keepout(None)
        cm.costmap()
    ms = statistics.median(times)
    return [
        Figure(
            "new keepout zone on a 2000x2000 map + global costmap (median)", ms, "ms", "< 100 ms", ms < 100
        ),
        Figure("cells in the largest zone", cells, "cells"),
    ]


def edit_on_big_map() -> list[Figure]:
    grid = _big_map()
    cm = Costmap2D.from_map(grid)
    cm.costmap()
    rng = np.random.default_rng(1)
    times, cells = [], []
    for _ in range(7):
        # a brush stroke of about 10,000 cells: 25 m long (500 cells), 1 m wide (20 cells)
        x0, y0 = rng.uniform(10, 70, 2)
        stroke = Stroke(np.array([[x0, y0], [x0 + 25.0, y0 + 0.5]]), 0.5, "occupied")
        t = time.perf_counter()
        edited, bounds, n = apply_edits(grid, [stroke])
        cm.update_static(edited, bounds)
        cm.costmap()
        times.append((time.perf_counter() - t) * 1e3)
        cells.append(n)
        cm.update_static(grid, bounds)  # undo, for the next trial
        cm.costmap()
    ms = statistics.median(times)
    return [
        Figure(
            "edit of ~10,000 cells on a 2000x2000 map + global costmap (median)",
            ms,
            "ms",
            "< 100 ms",
            ms < 100,
        ),
        Figure("cells changed per edit (median)", float(np.median(cells)), "cells"),
    ]


def _runtime(world: str, tmp: Path):
    settings = Settings(data_dir=tmp, db_url=f"sqlite:///{tmp / 'navdeck.db'}", viewer=False, world=world)
    rt = Runtime.build(settings, clock=VirtualClock())
    for mod in (localization, navigation, zones):
        rt.features[mod.__name__.rsplit(".", 1)[-1]] = mod.setup(rt)
    rt.on_pose_input("initial_pose", rt.session.driver.truth_pose)
    return rt


def _drive(rt, goal, seconds: float, on_tick=None) -> str:
    nav = rt.features["navigation"]
    rt.on_pose_input("goal", Pose2D(*goal))
    for _ in range(round(seconds / rt.session.period)):
        rt.session.run_for(rt.session.period)
        if on_tick is not None:
            on_tick(rt.session.driver.truth_pose)
        if not nav.active:
            break
    if nav.active:
        nav.cancel()
        rt.session.run_for(0.1)
        return "timeout"
    return (nav.last_outcome or {}).get("kind", "none")


def _barrier(path: np.ndarray) -> np.ndarray:
    """A 1.0 x 0.3 m keepout rectangle across the middle of a path, perpendicular to it."""
    i = len(path) // 2
    p, q = path[max(i - 3, 0), :2], path[min(i + 3, len(path) - 1), :2]
    d = (q - p) / max(np.linalg.norm(q - p), 1e-9)
    n = np.array([-d[1], d[0]])
    c = path[i, :2]
    return np.array(
        [c - 0.15 * d - 0.5 * n, c + 0.15 * d - 0.5 * n, c + 0.15 * d + 0.5 * n, c - 0.15 * d + 0.5 * n]
    )


def keepout_goals(per_world: int = 5) -> list[Figure]:
    figs = []
    for world in ("apartment", "office", "greenhouse"):
        with tempfile.TemporaryDirectory() as tmp:
            rt = _runtime(world, Path(tmp))
            try:
                z, nav = rt.features["zones"], rt.features["navigation"]
                planner = make_planner("astar")
                rng = np.random.default_rng(19)
                cm = nav.global_costmap
                free = np.argwhere(cm.costs == 0)
                tried = reached = inside = 0
                attempts = 0
                while tried < per_world and attempts < 200:
                    attempts += 1
                    r, c = free[rng.integers(len(free))]
                    gx, gy = cm.geometry.cell_to_world(np.array([r]), np.array([c]))[0]
                    start = rt.session.pose
                    try:
                        path = planner.plan(nav.global_costmap, start, Pose2D(gx, gy, 0.0)).poses
                    except Exception:
                        continue
                    if not 3.0 <= np.sum(np.hypot(*np.diff(path[:, :2], axis=0).T)) <= 12.0:
                        continue
                    zone = _barrier(path)
                    try:
                        zone_spec = ZoneSpec("bench", ZoneKind.KEEPOUT, zone.tolist())
                        added = z.store.add(z.map_id, zone_spec)
                    except Exception:
                        continue
                    z.reload(z.map_id)
                    rt.session.run_for(0.1)
                    # is there a way around? (the planner on the costmap with the zone)
                    mask = rasterize_polygons([zone], cm.geometry)
                    if mask[tuple(cm.geometry.world_to_cell(np.array([gx, gy])))].any():
                        z.store.delete(added.id)
                        z.reload(z.map_id)
                        continue
                    try:
                        planner.plan(nav.global_costmap, rt.session.pose, Pose2D(gx, gy, 0.0))
                    except Exception:
                        z.store.delete(added.id)
                        z.reload(z.map_id)
                        continue
                    tried += 1
                    hits = [0]

                    def count(p, zone=zone, hits=hits):
                        hits[0] += int(points_in_polygon(np.array([[p.x, p.y]]), zone)[0])

                    outcome = _drive(rt, (gx, gy, 0.0), 90.0, count)
                    reached += outcome == "reached"
                    inside += hits[0]
                    z.store.delete(added.id)
                    z.reload(z.map_id)
                figs.append(Figure(f"{world}: robot poses inside keepout", inside, "poses", "0", inside == 0))
                figs.append(Figure(f"{world}: goals reached around the zone (of {tried})", reached, "goals"))
            finally:
                rt.close()
    return figs


def speed_zone() -> list[Figure]:
    with tempfile.TemporaryDirectory() as tmp:
        rt = _runtime("apartment", Path(tmp))
        try:
            z = rt.features["zones"]
            zone = np.array([[1.2, 2.9], [2.6, 2.9], [2.6, 4.6], [1.2, 4.6]])  # between start and goal
            z.store.add(z.map_id, ZoneSpec("slow", ZoneKind.SPEED, zone.tolist(), 30.0, SpeedUnit.PERCENT))
            z.reload(z.map_id)
            limit = 0.3 * rt.session.profile.limits.max_vel_x
            prev = [rt.session.driver.truth_pose]
            speeds: list[float] = []

            def measure(p):
                q = prev[0]
                if points_in_polygon(np.array([[p.x, p.y], [q.x, q.y]]), zone).all():
                    speeds.append(math.hypot(p.x - q.x, p.y - q.y) / rt.session.period)
                prev[0] = p

            outcome = _drive(rt, (0.8, 3.5, math.pi), 120.0, measure)
            top = max(speeds) if speeds else float("nan")
            return [
                Figure("navigator in a 30 % speed zone: outcome reached", float(outcome == "reached"), ""),
                Figure(
                    f"highest measured speed inside (limit {limit:.3f} m/s)",
                    top,
                    "m/s",
                    f"<= {limit + 0.02:.3f}",
                    bool(speeds) and top <= limit + 0.02,
                ),
            ]
        finally:
            rt.close()


BENCHMARKS = [
    Benchmark(name="editor.zone", run=zone_on_big_map),
    Benchmark(name="editor.edit", run=edit_on_big_map),
    Benchmark(name="editor.keepout", run=keepout_goals, group="slow"),
    Benchmark(name="editor.speed", run=speed_zone, group="slow"),
]
