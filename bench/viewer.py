"""Viewer costs on its own thread: a per-tick scene update, and map re-tiling (one tile vs whole map)."""

from __future__ import annotations

import math
import pathlib
import time

import numpy as np

from app.bus import Snapshot, SnapshotBus
from app.viewer.demo import office_map
from app.viewer.scene import Viewer
from bench.core import Benchmark, Figure
from bench.datasets import ROS_MAPS
from nav.types import GridGeometry, LaserScan, OccupancyGrid, Pose2D, Twist2D


def _snap(
    seq: int, scan: LaserScan | None = None, grid: OccupancyGrid | None = None, version: int = 0
) -> Snapshot:
    return Snapshot(
        stamp=seq * 0.05,
        seq=seq,
        mode="navigating",
        pose=Pose2D(0.01 * seq, 0.5, 0.02 * seq),
        odom_pose=Pose2D(),
        velocity=Twist2D(0.2, 0.0, 0.1),
        command=Twist2D(),
        scan=scan,
        grid=grid,
        grid_version=version,
    )


def bench_scene_update() -> list[Figure]:
    rng = np.random.default_rng(0)
    viewer = Viewer(SnapshotBus())
    viewer.start()
    try:
        cpu, wall = [], []
        for i in range(300):
            ranges = rng.uniform(0.2, 6.0, 360)
            ranges[rng.random(360) < 0.05] = np.inf
            scan = LaserScan(i * 0.05, -math.pi, 2 * math.pi / 360, ranges, 0.15, 6.0)
            snap = _snap(i, scan)
            t0, c0 = time.perf_counter(), time.thread_time()
            viewer.apply_scene(snap)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - t0)
        ms = np.array(cpu[20:]) * 1e3  # CPU time of this thread: the figure a loaded machine cannot inflate
        wall_ms = np.array(wall[20:]) * 1e3
    finally:
        viewer.stop()
    p50, p99 = float(np.median(ms)), float(np.percentile(ms, 99))
    return [
        Figure("scene update p50 CPU (pose + 360-pt scan)", p50, "ms", "< 2 ms", p50 < 2.0),
        Figure("scene update p99 CPU", p99, "ms", "< 5 ms", p99 < 5.0),
        Figure("scene update p50 wall", float(np.median(wall_ms)), "ms"),
        Figure("scene update p99 wall", float(np.percentile(wall_ms, 99)), "ms"),
    ]


def bench_map_tiles() -> list[Figure]:
    grid = office_map()
    viewer = Viewer(SnapshotBus())
    viewer.start()
    try:
        t0 = time.perf_counter()
        n_all = viewer.apply_grids(_snap(0, grid=grid, version=1))
        whole = (time.perf_counter() - t0) * 1e3
        one = []
        for v in range(2, 12):  # a few cells change inside one tile, as a SLAM update would
            g = OccupancyGrid(grid.geometry, grid.data.copy())
            g.data[140 + v, 300 : 300 + v] = 100
            t0 = time.perf_counter()
            n = viewer.apply_grids(_snap(v, grid=g, version=v))
            one.append((time.perf_counter() - t0) * 1e3)
            assert n == 1
            grid = g
    finally:
        viewer.stop()
    tile = float(np.median(one))
    return [
        Figure(f"whole 600x400 map ({n_all} tiles)", whole, "ms", "< 1000 ms", whole < 1000.0),
        Figure("one changed tile (128x128 cells, x4)", tile, "ms", "< 50 ms", tile < 50.0),
        Figure("speed-up one tile vs whole map", whole / tile, "x", "> 10x", whole / tile > 10.0),
    ]


WILLOW = ROS_MAPS / "navigation_stage/willow-full-0.05.pgm"


def _read_trinary_pgm(path: pathlib.Path, resolution: float = 0.05) -> OccupancyGrid:
    """map_server trinary mode (negate 0, occupied 0.65, free 0.196); PGM row 0 is the map's top."""
    raw = path.read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # magic, width, height, maxval; skip comments
        while raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":
            pos = raw.index(b"\n", pos) + 1
            continue
        end = pos
        while not raw[end : end + 1].isspace():
            end += 1
        fields.append(raw[pos:end])
        pos = end
    w, h = int(fields[1]), int(fields[2])
    pix = np.frombuffer(raw, np.uint8, w * h, pos + 1).reshape(h, w)[::-1]
    occ = (255.0 - pix) / 255.0
    data = np.full((h, w), -1, np.int8)
    data[occ > 0.65] = 100
    data[occ < 0.196] = 0
    return OccupancyGrid(GridGeometry(resolution, w, h, Pose2D()), data)


def bench_willow_tiles() -> list[Figure]:
    if not WILLOW.exists():
        return []
    grid = _read_trinary_pgm(WILLOW)
    viewer = Viewer(SnapshotBus())
    viewer.start()
    try:
        t0 = time.perf_counter()
        n = viewer.apply_grids(_snap(0, grid=grid, version=1))
        whole = (time.perf_counter() - t0) * 1e3
    finally:
        viewer.stop()
    return [Figure(f"willow-full 1165x945 first send ({n} tiles)", whole, "ms", "< 3000 ms", whole < 3000.0)]


BENCHMARKS = [
    Benchmark(name="viewer.scene_update", run=bench_scene_update),
    Benchmark(name="viewer.map_tiles", run=bench_map_tiles),
    Benchmark(name="viewer.willow_tiles", run=bench_willow_tiles, group="slow"),
]
