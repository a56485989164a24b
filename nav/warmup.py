"""Warm the navigation pipeline's compiled kernels before the first goal.

Every hot kernel is a numba function compiled on first use (``cache=True`` keeps the machine code
on disk, but a fresh checkout has none, and even a cached kernel takes a while to load and link).
Without a warm-up the first goal paid for all of it: the first global plan compiled the A* search
on the worker while the dashboard said "waiting for a path", then the first DWA cycle compiled the
trajectory, footprint and projection kernels on the control-loop thread, which stalled the loop.
``warm_up_navigation`` runs each stage once on a small synthetic room with the same types as the
real run (so numba compiles the same signatures) and with its own planner and controllers, so it can
run on a worker thread while the loop uses the real ones.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from nav.costmap import Costmap2D, CostmapOptions
from nav.navigator import CONTROLLERS, make_controller
from nav.planning import make_planner
from nav.types import GridGeometry, LaserScan, OccupancyGrid, Pose2D, Twist2D

ROOM_SIZE = 4.0
"""Side of the synthetic square room (m): room for a plan and a controller horizon."""


def warm_up_navigation(
    profile: Any,
    planner: str,
    global_options: CostmapOptions,
    local_options: CostmapOptions,
    resolution: float,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, float]:
    """Run the costmap updates, one global plan and one cycle of every local controller once in a
    synthetic room; returns the seconds each stage took (its compile or cache-load time).
    ``overrides`` maps a controller name to its option overrides, as the real run gets them."""
    timings: dict[str, float] = {}
    grid = _room(resolution)
    pose = Pose2D(1.0, 1.0, math.pi / 4)

    t = time.perf_counter()
    local = Costmap2D.rolling(replace(local_options, resolution=resolution), pose, grid)
    local.update_from_scan(pose, _scan(), Pose2D())
    local.costmap()
    # the global costmap without the scan: its ring of returns would enclose the robot
    costmap = Costmap2D.from_map(grid, global_options).costmap()
    timings["costmaps"] = time.perf_counter() - t

    t = time.perf_counter()
    path = make_planner(planner).plan(costmap, pose, Pose2D(ROOM_SIZE - 1.0, ROOM_SIZE - 1.0, 0.0))
    timings["plan"] = time.perf_counter() - t

    for name in CONTROLLERS:
        t = time.perf_counter()
        controller = make_controller(name, profile, **dict((overrides or {}).get(name, {})))
        controller.set_path(path)
        controller.compute(pose, Twist2D(0.1, 0.0, 0.1), costmap)
        timings[name] = time.perf_counter() - t
    return timings


def _room(resolution: float) -> OccupancyGrid:
    """A walled square room with a pillar in the middle (lethal cells near the path and the scan)."""
    n = round(ROOM_SIZE / resolution)
    data = np.zeros((n, n), dtype=np.int8)
    wall = max(round(0.1 / resolution), 1)
    data[:wall, :] = data[-wall:, :] = data[:, :wall] = data[:, -wall:] = 100
    mid, half = n // 2, max(round(0.2 / resolution), 1)
    data[mid - half : mid + half, mid - half : mid + half] = 100
    return OccupancyGrid(GridGeometry(resolution, n, n, Pose2D()), data)


def _scan() -> LaserScan:
    """A 360-beam scan with returns, a no-return beam (+inf) and an invalid one (nan)."""
    ranges = np.full(360, 1.5)
    ranges[0], ranges[1] = np.inf, np.nan
    return LaserScan(0.0, -math.pi, 2 * math.pi / 360, ranges, 0.15, 6.0)
