"""Cylinder forests: a walled 10-16 x 7-10 m field of 0.15 m cylinders (0.3-0.9 per square metre,
placed uniformly at random), a clear start area on the west side and a clear goal area on the east,
and a route between them, a random polyline, kept free of cylinders for the robot's footprint plus
margin: every forest has a passable way through, wherever else the trees stand."""

from __future__ import annotations

import numpy as np

from maps.stock.generate import Canvas
from robot.profiles import load_profile
from robot.sim.worldgen.base import GeneratedWorld, Zone, disc_mask

PROFILE = "skid4"
CYLINDER_RADIUS = 0.075
ZONE_RADIUS = 0.8
ROUTE_MARGIN = 0.15
"""Metres beyond footprint and cylinder kept free along the guaranteed route."""


def _distance_to_polyline(pts: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(N,) distance of each point to the nearest segment of ``line`` ((K, 2))."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = ((pts[:, None, :] - a[None]) * ab[None]).sum(-1) / np.maximum((ab**2).sum(-1), 1e-12)[None]
    t = np.clip(t, 0.0, 1.0)
    near = a[None] + t[..., None] * ab[None]
    return np.hypot(*(pts[:, None, :] - near).transpose(2, 0, 1)).min(axis=1)


def generate(seed: int) -> GeneratedWorld:
    rng = np.random.default_rng(seed)
    c = Canvas(float(rng.uniform(10.0, 16.0)), float(rng.uniform(7.0, 10.0)))
    width, height = c.w * 0.05, c.h * 0.05
    c.outline()
    start = Zone(1.3, float(rng.uniform(1.5, height - 1.5)), ZONE_RADIUS)
    goal = Zone(width - 1.3, float(rng.uniform(1.5, height - 1.5)), ZONE_RADIUS)
    bends = int(rng.integers(1, 4))
    mid = np.column_stack(
        (np.sort(rng.uniform(2.5, width - 2.5, bends)), rng.uniform(1.2, height - 1.2, bends))
    )
    route = np.vstack(([start.x, start.y], mid, [goal.x, goal.y]))
    density = float(rng.uniform(0.3, 0.9))
    count = round(density * (width - 0.4) * (height - 0.4))
    trees = np.column_stack((rng.uniform(0.2, width - 0.2, count), rng.uniform(0.2, height - 0.2, count)))
    keep_route = load_profile(PROFILE).circumscribed_radius + CYLINDER_RADIUS + ROUTE_MARGIN
    keep = _distance_to_polyline(trees, route) > keep_route
    for z in (start, goal):
        keep &= np.hypot(trees[:, 0] - z.x, trees[:, 1] - z.y) > z.radius + keep_route
    trees = trees[keep]
    grid = c.grid()
    grid.data[disc_mask(grid.geometry, trees, CYLINDER_RADIUS)] = 100
    return GeneratedWorld(
        family="forest",
        seed=seed,
        grid=grid,
        profile=PROFILE,
        params={
            "width_m": width,
            "height_m": height,
            "density_per_m2": density,
            "cylinders": int(trees.shape[0]),
            "route_bends": bends,
        },
        items={"cylinder": [tuple(t) for t in trees.tolist()], "route": [tuple(p) for p in route.tolist()]},
        start_zone=start,
        goal_zone=goal,
    )
