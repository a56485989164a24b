"""Stand-alone look at the 3D view without a robot: ``python -m app.viewer.demo --port 8765`` then open
http://127.0.0.1:8765/viz/ . A robot drives a loop in a synthetic office; its scan is ray-marched
against the map. Clicked goals / initial poses are printed. For manual checks and screenshots only.
"""

from __future__ import annotations

import argparse
import math
import threading
import time

import numpy as np
import uvicorn
from fastapi import FastAPI
from scipy.ndimage import distance_transform_edt

from app.bus import Snapshot, SnapshotBus
from app.viewer.relay import make_router
from app.viewer.scene import Viewer
from nav.types import Costmap, GridGeometry, LaserScan, OccupancyGrid, Path, Pose2D, Twist2D, wrap_angle


def office_map(width: int = 600, height: int = 400, seed: int = 3) -> OccupancyGrid:
    """A 30 x 20 m office at 5 cm: outer walls, a corridor, rooms with doors, furniture, unknown outside."""
    rng = np.random.default_rng(seed)
    d = np.full((height, width), -1, np.int8)
    d[10:-10, 10:-10] = 0
    d[10, 10:-10] = d[-11, 10:-10] = d[10:-10, 10] = d[10:-10, -11] = 100
    d[180, 10:-10] = d[220, 10:-10] = 100  # corridor walls
    for x in range(110, width - 10, 100):
        d[10:180, x] = d[220:-10, x] = 100
        d[180, x - 40 : x - 24] = d[220, x - 40 : x - 24] = 0  # doors
    for _ in range(40):  # furniture blocks, kept out of the corridor
        r, c = rng.integers(20, 160), rng.integers(20, width - 30)
        if rng.random() < 0.5:
            r += 220
        d[r : r + rng.integers(4, 15), c : c + rng.integers(4, 15)] = 100
    return OccupancyGrid(GridGeometry(0.05, width, height, Pose2D(-15.0, -10.0, 0.0)), d)


def march_scan(grid: OccupancyGrid, pose: Pose2D, beams: int = 360, range_max: float = 6.0) -> LaserScan:
    """Ray-march every beam at half-cell steps (vectorized over beams x steps); first occupied cell wins."""
    res = grid.resolution
    angles = -math.pi + 2 * math.pi / beams * np.arange(beams)
    steps = np.arange(0.15, range_max, res / 2)
    a = angles[:, None] + pose.theta
    xy = np.stack((pose.x + steps[None] * np.cos(a), pose.y + steps[None] * np.sin(a)), axis=-1)
    rows, cols = grid.geometry.world_to_cell(xy.reshape(-1, 2))
    inside = grid.geometry.in_bounds(rows, cols)
    hit = np.zeros(rows.shape, bool)
    hit[inside] = grid.data[rows[inside], cols[inside]] >= 65
    hit = hit.reshape(beams, steps.size)
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    ranges = np.where(first >= 0, steps[np.maximum(first, 0)], np.inf)
    return LaserScan(time.time(), -math.pi, 2 * math.pi / beams, ranges, 0.15, range_max)


def local_costmap(grid: OccupancyGrid, pose: Pose2D, size: int = 60) -> Costmap:
    """A rolling 3 x 3 m window: lethal where the map is occupied, a linear inflation ramp around it."""
    res = grid.resolution
    ox = math.floor((pose.x - size * res / 2) / res) * res
    oy = math.floor((pose.y - size * res / 2) / res) * res
    geo = GridGeometry(res, size, size, Pose2D(ox, oy, 0.0))
    r, c = np.mgrid[0:size, 0:size]
    pts = geo.cell_to_world(r.ravel(), c.ravel())
    gr, gc = grid.geometry.world_to_cell(pts)
    ok = grid.geometry.in_bounds(gr, gc)
    occ = np.zeros(size * size, bool)
    occ[ok] = grid.data[gr[ok], gc[ok]] >= 65
    dist = distance_transform_edt(~occ.reshape(size, size)) * res
    costs = np.clip(252 * (1 - dist / 0.55), 0, 252).astype(np.uint8)
    costs[dist <= 0.13] = 253
    costs[dist == 0] = 254
    return Costmap(geo, costs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--port", type=int, default=8765)
    ap.add_argument("--host", default="127.0.0.1")
    args = ap.parse_args()

    bus = SnapshotBus()
    footprint = np.array([[0.12, 0.10], [-0.12, 0.10], [-0.12, -0.10], [0.12, -0.10]])
    viewer = Viewer(
        bus, footprint=footprint, on_pose_input=lambda k, p, tab: print(f"pose input ({tab}): {k} {p}")
    )
    viewer.start()
    grid = office_map()
    stop = threading.Event()

    def loop() -> None:
        trail: list[tuple[float, float]] = []
        rng = np.random.default_rng(0)
        seq = 0
        while not stop.is_set():
            t = seq * 0.05
            pose = Pose2D(
                6.0 * math.cos(0.05 * t),
                0.0 + 0.6 * math.sin(0.1 * t),
                float(wrap_angle(0.05 * t + math.pi / 2)),
            )
            trail = [*trail[-400:], (pose.x, pose.y)]
            goal = Pose2D(8.0, 0.0, 0.0)
            path = np.column_stack(
                (np.linspace(pose.x, goal.x, 40), np.linspace(pose.y, goal.y, 40), np.zeros(40))
            )
            samples = np.stack(
                [
                    pose.transform_points(
                        np.column_stack(
                            (
                                np.linspace(0, 1, 15) * v,
                                0.5 * w * (np.linspace(0, 1, 15) * v) ** 2,
                            )
                        )
                    )
                    for v in (0.1, 0.2, 0.26)
                    for w in np.linspace(-1, 1, 7)
                ]
            )
            particles = np.column_stack(
                (
                    pose.x + rng.normal(0, 0.15, 300),
                    pose.y + rng.normal(0, 0.15, 300),
                    pose.theta + rng.normal(0, 0.1, 300),
                )
            )
            bus.publish(
                Snapshot(
                    stamp=t,
                    seq=seq,
                    mode="navigating",
                    pose=pose,
                    odom_pose=pose,
                    velocity=Twist2D(0.3, 0.0, 0.05),
                    command=Twist2D(0.3, 0.0, 0.05),
                    scan=march_scan(grid, pose) if seq % 4 == 0 else None,
                    trail=np.array(trail),
                    grid=grid,
                    grid_version=1,
                    path=Path(path),
                    local_plan=samples,
                    goal=goal,
                    particles=particles,
                    behavior="follow_path",
                    extras={"costmap": local_costmap(grid, pose), "local_plan_best": 17},
                )
            )
            seq += 1
            time.sleep(0.05)

    threading.Thread(target=loop, daemon=True).start()
    app = FastAPI()
    app.include_router(make_router(lambda: viewer))
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level="warning")
    finally:
        stop.set()
        viewer.stop()


if __name__ == "__main__":
    main()
