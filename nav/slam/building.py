"""Seeded large buildings and long drives through them, scored against the simulator's truth.

A building is a grid of long corridors (vertical ones spanning its height, horizontal ones its
width) with rooms and door niches along them, so corridors are long but not featureless, as in an
office or a hospital. A drive loops around the building's west part, spends a long time in the rest
of it (which has loops of its own), then comes back west and loops there again: the loop back closes
only after a long time away, with the odometry drift of the whole excursion in between.

Everything is vectorized: scans are cast for all poses at once by :class:`nav.raycast.RayCaster`
(compiled), odometry errors are applied as cumulative sums. Relations follow Kümmerle et al. 2009:
pairs of poses close in space, from different passes (``far`` apart in time), and short local
relations, each the true pose of the second in the frame of the first.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from nav.raycast import RayCaster
from nav.slam.metric import relative_poses
from nav.types import GridGeometry, LaserScan, wrap_angle


@dataclass(frozen=True)
class Building:
    """Occupied mask (origin (0, 0)), its resolution, and the corridor centrelines."""

    occupied: np.ndarray
    resolution: float
    corridor_x: np.ndarray
    """x of the vertical corridors' centrelines (west to east)."""
    corridor_y: np.ndarray
    """y of the horizontal corridors' centrelines (south to north)."""

    @property
    def size(self) -> tuple[float, float]:
        h, w = self.occupied.shape
        return w * self.resolution, h * self.resolution


@dataclass(frozen=True)
class Drive:
    """A drive: scan stamps (N,), true poses (N, 3), odometry poses (N, 3), scans."""

    stamps: np.ndarray
    truth: np.ndarray
    odometry: np.ndarray
    scans: list[LaserScan]


def _spread(rng: np.random.Generator, lo: float, hi: float, count: int, gap: float) -> np.ndarray:
    """``count`` sorted positions in (lo, hi), at least ``gap`` apart (rejection sampling)."""
    for _ in range(1000):
        v = np.sort(rng.uniform(lo, hi, count))
        if count < 2 or np.diff(v).min() >= gap:
            return v
    return np.linspace(lo, hi, count + 2)[1:-1]


def large_building(
    seed: int, width: float = 110.0, height: float = 64.0, resolution: float = 0.05
) -> Building:
    """A seeded ``width`` x ``height`` m building: 4-5 vertical and 3 horizontal corridors 1.8-2.6 m
    wide, rooms (with a door to the corridor and a box inside) and niches along them."""
    rng = np.random.default_rng(seed)
    h, w = round(height / resolution), round(width / resolution)
    occ = np.ones((h, w), dtype=bool)

    def free(x0: float, y0: float, x1: float, y1: float) -> None:
        r0, r1 = max(round(min(y0, y1) / resolution), 1), min(round(max(y0, y1) / resolution), h - 1)
        c0, c1 = max(round(min(x0, x1) / resolution), 1), min(round(max(x0, x1) / resolution), w - 1)
        occ[r0:r1, c0:c1] = False

    def fill(x0: float, y0: float, x1: float, y1: float) -> None:
        r0, r1 = round(min(y0, y1) / resolution), round(max(y0, y1) / resolution)
        occ[r0:r1, round(min(x0, x1) / resolution) : round(max(x0, x1) / resolution)] = True

    nx = int(rng.integers(4, 6))
    inner_x = _spread(rng, 0.18 * width, 0.82 * width, nx - 2, max(10.0, 0.14 * width))
    xs = np.concatenate(([3.0], inner_x, [width - 3.0]))
    ys = np.concatenate(([3.0], _spread(rng, 0.35 * height, 0.65 * height, 1, 0.0), [height - 3.0]))
    half_x = rng.uniform(0.9, 1.3, len(xs))
    half_y = rng.uniform(0.9, 1.3, len(ys))
    for x, hw in zip(xs, half_x, strict=True):
        free(x - hw, ys[0] - half_y[0], x + hw, ys[-1] + half_y[-1])
    for y, hh in zip(ys, half_y, strict=True):
        free(xs[0] - half_x[0], y - hh, xs[-1] + half_x[-1], y + hh)
    # rooms and niches along both walls of every corridor, skipping the crossings
    wall = 0.2
    for vertical, centres, halves, lo_all, hi_all in (
        (True, xs, half_x, ys[0], ys[-1]),
        (False, ys, half_y, xs[0], xs[-1]),
    ):
        crossings = ys if vertical else xs
        cross_half = half_y if vertical else half_x
        for c, hw in zip(centres, halves, strict=True):
            for side in (-1.0, 1.0):
                edge = c + side * hw  # the corridor wall's inner face
                s = lo_all + 3.0
                while s < hi_all - 3.0:
                    length = rng.uniform(3.0, 8.0)
                    e = min(s + length, hi_all - 3.0)
                    near = np.abs(crossings - 0.5 * (s + e)) < 0.5 * (e - s) + cross_half + 1.5
                    if e - s > 2.0 and not near.any():
                        kind = rng.uniform()
                        if kind < 0.45:  # room behind a wall, with a door and a box inside
                            depth = rng.uniform(3.0, 5.5)
                            a0, a1 = edge + side * wall, edge + side * (wall + depth)
                            door = rng.uniform(s + 0.3, e - 1.3)
                            box = rng.uniform(s + 0.5, max(e - 1.5, s + 0.6))
                            bd = rng.uniform(0.3, depth - 1.5)
                            if vertical:
                                free(a0, s, a1, e)
                                free(edge - side * 0.01, door, a0 + side * 0.01, door + 1.0)
                                fill(a0 + side * bd, box, a0 + side * (bd + 0.8), box + 0.8)
                            else:
                                free(s, a0, e, a1)
                                free(door, edge - side * 0.01, door + 1.0, a0 + side * 0.01)
                                fill(box, a0 + side * bd, box + 0.8, a0 + side * (bd + 0.8))
                        elif kind < 0.75:  # niche (doorway recess, alcove)
                            nw = rng.uniform(0.8, 2.0)
                            n0 = rng.uniform(s, max(e - nw, s + 0.01))
                            nd = rng.uniform(0.25, 0.6)
                            if vertical:
                                free(edge, n0, edge + side * nd, n0 + nw)
                            else:
                                free(n0, edge, n0 + nw, edge + side * nd)
                    s = e + rng.uniform(0.3, 3.0)
    return Building(occ, resolution, xs, ys)


def _route(b: Building, rng: np.random.Generator, speed: float, duration: float) -> np.ndarray:
    """Corridor crossings to visit: a loop around the west part, a long excursion east (random
    walk preferring the least driven corridors, >= half of ``duration``), back west and around
    the same loop, then more random driving until ``duration`` is spent. (M, 2) points."""
    nx, ny = len(b.corridor_x), len(b.corridor_y)

    def xy(node: tuple[int, int]) -> np.ndarray:
        return np.array([b.corridor_x[node[0]], b.corridor_y[node[1]]])

    west = (
        [(0, 0), (1, 0)]
        + [(1, j) for j in range(1, ny)]
        + [(0, ny - 1)]
        + [(0, j) for j in range(ny - 2, -1, -1)]
    )
    visits: dict[tuple[tuple[int, int], tuple[int, int]], int] = {}
    path = list(west)

    def length(p: list[tuple[int, int]]) -> float:
        pts = np.array([xy(n) for n in p])
        return float(np.sum(np.abs(np.diff(pts, axis=0))))

    def walk(until: float, allowed: int) -> None:
        while length(path) < until:
            cur = path[-1]
            nbrs = [
                (cur[0] + dx, cur[1] + dy)
                for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
                if allowed <= cur[0] + dx < nx and 0 <= cur[1] + dy < ny
            ]
            if len(path) > 1 and len(nbrs) > 1 and path[-2] in nbrs:
                nbrs.remove(path[-2])  # no U-turns in a corridor
            counts = np.array([visits.get(tuple(sorted((cur, n))), 0) for n in nbrs], dtype=float)
            pick = nbrs[int(rng.choice(np.flatnonzero(counts == counts.min())))]
            visits[tuple(sorted((cur, pick)))] = visits.get(tuple(sorted((cur, pick))), 0) + 1
            path.append(pick)

    distance = speed * duration  # turns make the drive longer: cut to ``duration`` after
    path.append((1, 0))
    path.append((2, 0))
    walk(length(path) + 0.5 * distance, 2)
    # back west along the south corridor, then the west loop again
    cur = path[-1]
    path.extend((cur[0], j) for j in range(cur[1] - 1, -1, -1))
    path.extend((i, 0) for i in range(path[-1][0] - 1, -1, -1))
    path.extend(west[1:])
    walk(distance, 0)
    return np.array([xy(n) for n in path])


def _sample_drive(waypoints: np.ndarray, speed: float, turn_rate: float, period: float) -> np.ndarray:
    """(N, 3) poses every ``period`` s driving the polyline at ``speed``, turning in place at
    corners at ``turn_rate``. Built as a piecewise-linear (time -> pose) profile, then sampled."""
    keys_t, keys_p = [0.0], [np.array([*waypoints[0], math.atan2(*(waypoints[1] - waypoints[0])[::-1])])]
    for a, c in itertools.pairwise(waypoints):
        d = c - a
        dist = float(np.hypot(*d))
        if dist < 1e-9:
            continue
        heading = math.atan2(d[1], d[0])
        prev = keys_p[-1]
        turn = wrap_angle(heading - prev[2])
        if abs(turn) > 1e-9:
            keys_t.append(keys_t[-1] + abs(turn) / turn_rate)
            keys_p.append(np.array([prev[0], prev[1], prev[2] + turn]))
        keys_t.append(keys_t[-1] + dist / speed)
        keys_p.append(np.array([c[0], c[1], prev[2] + turn]))
    kt, kp = np.array(keys_t), np.array(keys_p)
    t = np.arange(0.0, kt[-1], period)
    poses = np.column_stack([np.interp(t, kt, kp[:, i]) for i in range(3)])
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses


def drift_odometry(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Wheel odometry from (N, 3) true poses: per run a scale error (+-2 %), a turn-scale error
    (+-2 %) and a heading bias (+-0.6 deg/m, unequal wheels), plus per-step noise (1 % of the
    distance, 0.3 deg/m and 1 % of the turn)."""
    c, s = np.cos(truth[:-1, 2]), np.sin(truth[:-1, 2])
    dx, dy = np.diff(truth[:, 0]), np.diff(truth[:, 1])
    fwd, side = c * dx + s * dy, -s * dx + c * dy
    dth = wrap_angle(np.diff(truth[:, 2]))
    dist = np.hypot(fwd, side)
    scale, turn_scale = 1 + rng.uniform(-0.02, 0.02), 1 + rng.uniform(-0.02, 0.02)
    bias = rng.uniform(-0.01, 0.01)
    n = len(dist)
    fwd = fwd * scale + rng.normal(0, 1, n) * 0.01 * dist
    side = side + rng.normal(0, 1, n) * 0.002 * dist
    dth = dth * turn_scale + bias * dist + rng.normal(0, 1, n) * (0.005 * dist + 0.01 * np.abs(dth))
    th = truth[0, 2] + np.concatenate(([0.0], np.cumsum(dth)))
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    x = truth[0, 0] + np.concatenate(([0.0], np.cumsum(c * fwd - s * side)))
    y = truth[0, 1] + np.concatenate(([0.0], np.cumsum(s * fwd + c * side)))
    return np.column_stack((x, y, wrap_angle(th)))


def long_drive(
    building: Building,
    seed: int,
    duration: float = 3600.0,
    rate: float = 2.0,
    speed: float = 0.5,
    beams: int = 181,
    fov: float = math.pi,
    range_max: float = 30.0,
    range_noise: float = 0.01,
) -> Drive:
    """A ``duration`` s drive through ``building`` with a ``beams``-beam ``fov`` laser at ``rate`` Hz
    (laser at base_link), drifting odometry and Gaussian range noise; beams without a wall within
    ``range_max`` read +inf."""
    rng = np.random.default_rng(seed)
    waypoints = _route(building, rng, speed, duration)
    truth = _sample_drive(waypoints, speed, 0.6, 1.0 / rate)
    truth = truth[: int(duration * rate)]
    odom = drift_odometry(truth, rng)
    geometry = GridGeometry(building.resolution, building.occupied.shape[1], building.occupied.shape[0])
    caster = RayCaster(building.occupied, geometry, clearance=True)
    angle_min, inc = -fov / 2, fov / (beams - 1)
    rel = angle_min + inc * np.arange(beams)
    ranges = caster.cast(truth[:, :2], truth[:, 2:3] + rel[None, :], range_max)
    ranges = ranges + rng.normal(0, range_noise, ranges.shape)
    ranges[~(ranges <= range_max)] = np.inf
    stamps = np.arange(len(truth)) / rate
    scans = [
        LaserScan(float(t), angle_min, inc, r, 0.05, range_max) for t, r in zip(stamps, ranges, strict=True)
    ]
    return Drive(stamps, truth, odom, scans)


def truth_relations(
    stamps: np.ndarray,
    truth: np.ndarray,
    seed: int = 0,
    radius: float = 2.0,
    far: float = 300.0,
    local_step: int = 10,
    max_far: int = 3000,
) -> tuple[np.ndarray, np.ndarray]:
    """Relations ``(t1, t2, x, y, yaw)`` (Kümmerle et al. 2009): ``far`` ones between poses within
    ``radius`` m of each other and >= ``far`` s apart (revisits; at most ``max_far``, drawn with
    ``seed``), and local ones between poses ``local_step`` scans apart. Returns (far, local)."""
    tree = cKDTree(truth[:, :2])
    pairs = tree.query_pairs(radius, output_type="ndarray")
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[stamps[pairs[:, 1]] - stamps[pairs[:, 0]] >= far]
    if len(pairs) > max_far:
        pairs = pairs[np.sort(np.random.default_rng(seed).choice(len(pairs), max_far, replace=False))]
    k = np.arange(0, len(stamps) - local_step, local_step)
    local = np.column_stack((k, k + local_step))

    def rel(p: np.ndarray) -> np.ndarray:
        r = relative_poses(truth[p[:, 0]], truth[p[:, 1]])
        return np.column_stack((stamps[p[:, 0]], stamps[p[:, 1]], r))

    return rel(pairs), rel(local)
