"""Ghost free space on generated worlds (issue 16): ``mapping.ghost``'s measure (:mod:`bench.ghost`)
on seeded members of the apartment and office families (``robot.sim.worldgen``), so the figures
are not those of the three stock worlds the SLAM was diagnosed on.

Each world is mapped along a teleop loop built the way an operator would cover it: the watchman
tour of ``explore.*`` (:func:`bench.explore.greedy_tour`: places that together see every free cell
the lidar can see, in a short order), the legs between places following the shortest path that
keeps away from obstacles (a Dijkstra field over the clearance, descended cell by cell). The start
is :func:`app.commands.explore.random_start` of the world's seed.

Environment: ``NAVDECK_GHOST_FAMILIES`` (default ``apartment,office``), ``NAVDECK_GHOST_SEEDS``
(default ``0,1,2``).
"""

from __future__ import annotations

import os

import numpy as np

from app.commands.explore import random_start
from bench.core import Benchmark, Figure
from bench.explore import greedy_tour, sight
from bench.ghost import GhostReport, ghost_report
from bench.mapping import build_in, teleop_loop
from nav.exploration import distance_field
from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, Pose2D
from robot.profiles import load_profile
from robot.sim.worldgen import generate

PROFILE = "skid4"
WAYPOINT_SPACING = 0.3
"""Metres between the waypoints of a leg (the teleop operator steers straight at the next one)."""
GIVE_UP = 30.0
"""Seconds after which the operator skips a waypoint the robot does not get to (a tight corner)."""
ROOM = 0.4
"""Metres of clearance beyond the robot's radius from which a cell costs nothing to cross."""

_STEPS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)])


def _clearance_costs(world, radius: float) -> Costmap:
    """Free cells cost more the closer they are to an obstacle (so legs keep to the middle of
    doors and aisles); cells the robot does not fit in are lethal."""
    clear = world.clearance_map - (radius + world.geometry.resolution)
    cost = np.clip(
        (1.0 - clear / ROOM) * (INSCRIBED_INFLATED_OBSTACLE - 1), 0, INSCRIBED_INFLATED_OBSTACLE - 1
    )
    cost = np.where(clear >= 0.0, cost, 254)
    return Costmap(world.geometry, cost.astype(np.uint8))


def _leg(costs: Costmap, a: np.ndarray, b: np.ndarray) -> list[tuple[float, float]]:
    """Waypoints from ``a`` to ``b`` down the Dijkstra field of ``b`` (steepest 8-neighbour)."""
    geo = costs.geometry
    field = distance_field(costs, Pose2D(float(b[0]), float(b[1]), 0.0))
    rows, cols = geo.world_to_cell(a[None, :])
    r, c = int(rows[0]), int(cols[0])
    if not np.isfinite(field[r, c]):
        return []  # a place the tour reached by another way (a different component)
    cells = [(r, c)]
    while field[r, c] > 0.0:
        nr, nc = r + _STEPS[:, 0], c + _STEPS[:, 1]
        ok = (nr >= 0) & (nr < geo.height) & (nc >= 0) & (nc < geo.width)
        vals = np.full(len(_STEPS), np.inf)
        vals[ok] = field[nr[ok], nc[ok]]
        k = int(np.argmin(vals))
        if not vals[k] < field[r, c]:
            break
        r, c = int(nr[k]), int(nc[k])
        cells.append((r, c))
    stride = max(1, round(WAYPOINT_SPACING / geo.resolution))
    keep = [*cells[stride::stride], cells[-1]]
    pts = geo.cell_to_world(np.array([p[0] for p in keep]), np.array([p[1] for p in keep]))
    return [(float(x), float(y)) for x, y in pts]


def family_loop(family: str, seed: int):
    """(world, start, waypoints) of a generated world's full teleop loop."""
    world = generate(family, seed).world()
    start = random_start(world, PROFILE, seed)
    tour = greedy_tour(world, start, sight(world, start, PROFILE))
    costs = _clearance_costs(world, load_profile(PROFILE).circumscribed_radius)
    waypoints: list[tuple[float, float]] = []
    here = np.array([start.x, start.y])
    for place in tour.places:
        waypoints.extend(_leg(costs, here, place))
        here = place
    return world, start, waypoints


def measure_family(family: str, seed: int) -> tuple[GhostReport, float, int]:
    """The ghost report after the loop, the SLAM pose error (m) at its end and how many waypoints
    the operator gave up on."""
    world, start, waypoints = family_loop(family, seed)
    drive = build_in(world, start, seed)
    try:
        drive.mapping.start()
        skipped = teleop_loop(drive, waypoints, timeout=3600.0, give_up_after=GIVE_UP)
        drive.mapping.stop()
        grid = drive.mapping.current_map()
        truth = drive.driver.truth_pose.relative_to(drive.start_truth)
        end_error = drive.session.pose.distance_to(truth)
    finally:
        drive.session.close()
    report = ghost_report(grid, world.static_occupied, world.geometry, drive.start_truth)
    return report, end_error, skipped


def _env_list(name: str, default: str) -> list[str]:
    return [v.strip() for v in os.environ.get(name, default).split(",") if v.strip()]


def _all() -> list[Figure]:
    out: list[Figure] = []
    for family in _env_list("NAVDECK_GHOST_FAMILIES", "apartment,office"):
        reports = []
        for seed in (int(s) for s in _env_list("NAVDECK_GHOST_SEEDS", "0,1,2")):
            r, end_error, skipped = measure_family(family, seed)
            reports.append(r)
            tag = f"{family} {seed}"
            out += [
                Figure(f"{tag}: SLAM pose error at the end of the loop", end_error, "m"),
                Figure(f"{tag}: waypoints skipped (not reached in {GIVE_UP:.0f} s)", float(skipped), ""),
                Figure(f"{tag}: free cells in walls", float(r.in_walls), "cells", "0", r.in_walls == 0),
                Figure(
                    f"{tag}: free cells outside the outer walls",
                    float(r.outside),
                    "cells",
                    "0",
                    r.outside == 0,
                ),
                Figure(f"{tag}: of which deeper than half a cell", float(r.deeper_than_half_cell), "cells"),
                Figure(f"{tag}: free cells in the map", float(r.free_cells), "cells"),
                Figure(
                    f"{tag}: map extent vs world extent",
                    r.extent_error_m,
                    "m",
                    "<= 1 m",
                    r.extent_error_m <= 1.0,
                ),
            ]
        ghosts = sum(r.ghosts for r in reports)
        out.append(
            Figure(
                f"{family}: free cells in walls or outside, all worlds",
                float(ghosts),
                "cells",
                "0",
                ghosts == 0,
            )
        )
    return out


BENCHMARKS = [Benchmark(name="mapping.ghost_family", run=_all, group="slow")]
