"""Synthetic worlds and scans for tests and benchmarks: a box world with a few pillars, a
vectorized ray caster over a boolean grid, and a drifting odometry model.

The caster marches all beams at once in sub-cell steps and takes, per beam, the first occupied
sample (``argmax`` over the step axis), so it has no per-beam Python loop.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import LaserScan, Pose2D


def box_world(size: float = 12.0, resolution: float = 0.05) -> tuple[np.ndarray, float]:
    """A ``size`` m square room (walls 0.1 m) with a wall, a shelf and pillars; returns (occupied
    bool grid with origin at (0, 0), resolution). Asymmetric, so matches are unique. The square
    loop 1.5 m inside the walls (:data:`LOOP_WAYPOINTS` x size/12) is free."""
    n = round(size / resolution)
    g = np.zeros((n, n), dtype=bool)
    t = 2
    g[:t, :] = g[-t:, :] = g[:, :t] = g[:, -t:] = True

    def rect(x0: float, y0: float, x1: float, y1: float) -> None:
        g[
            round(y0 / resolution) : round(y1 / resolution), round(x0 / resolution) : round(x1 / resolution)
        ] = True

    rect(size * 0.45, size * 0.33, size * 0.47, size * 0.58)  # free-standing wall
    rect(size * 0.2, size * 0.6, size * 0.35, size * 0.62)  # shelf
    for cx, cy, r in ((0.25, 0.25, 0.3), (0.75, 0.7, 0.4), (0.7, 0.3, 0.2), (0.3, 0.75, 0.25)):
        rect(size * cx - r, size * cy - r, size * cx + r, size * cy + r)
    rect(size * 0.92, size * 0.45, size * 0.96, size * 0.55)
    return g, resolution


LOOP_WAYPOINTS = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 10.5], [1.5, 10.5], [1.5, 1.5]])
"""A loop around the 12 m box world, clear of every obstacle."""


def cast_scan(
    occupied: np.ndarray,
    resolution: float,
    pose: Pose2D,
    beams: int = 360,
    fov: float = 2 * math.pi,
    range_max: float = 8.0,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    stamp: float = 0.0,
) -> LaserScan:
    """A LaserScan from ``pose`` (laser = base_link) over the grid (origin (0, 0)); +inf = no return."""
    angle_min = -fov / 2 if fov < 2 * math.pi else -math.pi
    inc = fov / beams if fov >= 2 * math.pi else fov / (beams - 1)
    a = pose.theta + angle_min + inc * np.arange(beams)
    step = resolution * 0.25
    r = np.arange(1, int(range_max / step) + 1) * step
    x = pose.x + np.cos(a)[:, None] * r[None, :]
    y = pose.y + np.sin(a)[:, None] * r[None, :]
    col = np.floor(x / resolution).astype(np.int64)
    row = np.floor(y / resolution).astype(np.int64)
    h, w = occupied.shape
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    occ = np.zeros_like(inside)
    occ[inside] = occupied[row[inside], col[inside]]
    first = occ.argmax(axis=1)
    rng_out = np.where(occ.any(axis=1), r[first], np.inf)
    if noise > 0 and rng is not None:
        rng_out = rng_out + rng.normal(0.0, noise, beams)
    return LaserScan(stamp, angle_min, inc, rng_out, 0.05, range_max)


def loop_trajectory(
    waypoints: np.ndarray, step: float = 0.1, turn_step: float = math.radians(10)
) -> np.ndarray:
    """(N, 3) poses driving through ``waypoints`` (M, 2) in straight segments, turning in place."""
    poses: list[tuple[float, float, float]] = []
    th = math.atan2(waypoints[1, 1] - waypoints[0, 1], waypoints[1, 0] - waypoints[0, 0])
    for k in range(len(waypoints) - 1):
        p, q = waypoints[k], waypoints[k + 1]
        heading = math.atan2(q[1] - p[1], q[0] - p[0])
        dth = (heading - th + math.pi) % (2 * math.pi) - math.pi
        for f in np.linspace(0, 1, max(2, int(abs(dth) / turn_step) + 1))[1:]:
            poses.append((float(p[0]), float(p[1]), th + f * dth))
        th = heading
        n = max(1, int(np.hypot(*(q - p)) / step))
        for f in np.arange(n) / n:
            xy = p + f * (q - p)
            poses.append((float(xy[0]), float(xy[1]), th))
    return np.array(poses)


def drifting_odometry(truth: np.ndarray, yaw_drift: float, scale: float = 1.0) -> np.ndarray:
    """Odometry from (N, 3) true poses with a per-metre heading bias (rad/m) and a scale error."""
    odom = np.zeros_like(truth)
    odom[0] = truth[0]
    for k in range(1, len(truth)):
        rel = Pose2D.from_array(truth[k]).relative_to(Pose2D.from_array(truth[k - 1]))
        dist = math.hypot(rel.x, rel.y)
        noisy = Pose2D(rel.x * scale, rel.y * scale, rel.theta + yaw_drift * dist)
        odom[k] = Pose2D.from_array(odom[k - 1]).compose(noisy).as_array()
    return odom
