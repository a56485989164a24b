"""Issue 18 diagnosis: why live SLAM's maps come out 0.2-0.5 % smaller than the world.

Offline corridor replay: a robot driven exactly straight along an office corridor at a fixed speed,
the simulator's lidar cast at each scan's true pose (the profile's rate, noise off unless asked),
odometry exact (the true pose), everything fed straight into :class:`nav.slam.GraphSlam` as the
mapping stage does (``add_scan`` + ``optimize_if_due``, a final back-end run). No session, no
controller: what is left is the SLAM front end against the simulator's scans.

Figure: the slope of (SLAM distance from the start - true distance) over the true distance, of
SLAM's final trajectory (a least-squares line through the origin), in percent; and the sum of the
front end's along-track corrections (match - prediction) over the nodes.

``python -m bench.slamscale [world] [y] [x_from] [x_to] [speed] [phase]`` prints one run as JSON.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from app.commands.explore import load_world
from nav.grid import LogOddsGrid
from nav.slam.system import GraphSlam, SlamOptions
from nav.types import Pose2D
from robot.profiles import load_profile
from robot.sim.lidar import SimLidar
from robot.sim.world import World


@dataclass(frozen=True)
class Drive:
    world: str = "office:4"
    y: float = 7.39
    x_from: float = 5.0
    x_to: float = 30.0
    speed: float = 0.26
    noise: bool = False
    shift: tuple[float, float] = (0.0, 0.0)
    """Added to every true pose before the cast: moves the robot's line against the world's cell
    lattice (a fraction of a cell tests the quantisation hypothesis)."""


@dataclass
class Result:
    slope_pct: float
    end_error_m: float
    front_end_sum_m: float
    nodes: int
    distance_m: float
    cpu_s: float
    node_x: np.ndarray | None = None
    """Per node: its true distance from the start."""
    node_step_error: np.ndarray | None = None
    """Per node (from the second): front-end step length - true step length (m)."""


def corridor_poses(d: Drive, rate_hz: float) -> np.ndarray:
    """(N, 3) true poses at the lidar's scan times, heading along the drive."""
    dist = abs(d.x_to - d.x_from)
    n = int(dist / d.speed * rate_hz) + 1
    s = np.arange(n) * d.speed / rate_hz
    sign = 1.0 if d.x_to >= d.x_from else -1.0
    x = d.x_from + sign * s + d.shift[0]
    y = np.full(n, d.y + d.shift[1])
    th = np.full(n, 0.0 if sign > 0 else math.pi)
    return np.column_stack((x, y, th))


@contextlib.contextmanager
def lattice_phase(phase: float) -> Iterator[None]:
    """Experiment only: every new submap grid's cell lattice moved ``phase`` cells down-left of where
    ``LogOddsGrid.ensure_contains`` puts it (the first scan's lowest point - grow_margin, i.e. on a
    wall face the scan saw when the submap is axis-aligned with the world)."""
    original = LogOddsGrid.ensure_contains

    def shifted(self: LogOddsGrid, xy: np.ndarray) -> None:
        if xy.size and 0 in self.shape:
            xy = np.vstack((xy, xy.min(axis=0) - phase * self.resolution))
        original(self, xy)

    LogOddsGrid.ensure_contains = shifted  # type: ignore[method-assign]
    try:
        yield
    finally:
        LogOddsGrid.ensure_contains = original  # type: ignore[method-assign]


def replay(d: Drive, options: SlamOptions | None = None, world: World | None = None) -> Result:
    """Run one corridor drive through GraphSlam; CPU is this process's time for the replay."""
    world = world or load_world(d.world)
    spec = load_profile("skid4").lidar
    lidar = SimLidar(spec, np.random.default_rng(0), noise=d.noise)
    laser = Pose2D(spec.mount_x, spec.mount_y, spec.mount_yaw)
    truth = corridor_poses(d, spec.rate_hz)
    slam = GraphSlam(options or SlamOptions())
    t0 = time.process_time()
    for k, (x, y, th) in enumerate(truth):
        pose = Pose2D(float(x), float(y), float(th))
        scan = lidar.scan(world, pose, k / spec.rate_hz)
        slam.add_scan(scan, pose, laser)
        slam.optimize_if_due()
    slam.run_backend()
    cpu = time.process_time() - t0
    traj = slam.trajectory()[:, 1:3]
    true_dist = np.hypot(*(truth[:, :2] - truth[0, :2]).T)
    slam_dist = np.hypot(*(traj - traj[0]).T)
    err = slam_dist - true_dist
    slope = float(np.dot(err, true_dist) / max(np.dot(true_dist, true_dist), 1e-12))
    # front end's along-track corrections: node match vs odometry prediction from the previous node
    stamps, local = slam.front_end_nodes()
    idx = np.rint(stamps * spec.rate_hz).astype(int)
    tr = truth[idx]
    step_true = np.hypot(*np.diff(tr[:, :2], axis=0).T)
    step_fe = np.hypot(*np.diff(local[:, :2], axis=0).T)
    return Result(
        slope_pct=100.0 * slope,
        end_error_m=float(err[-1]),
        front_end_sum_m=float(np.sum(step_fe - step_true)),
        nodes=len(stamps),
        distance_m=float(true_dist[-1]),
        cpu_s=cpu,
        node_x=np.hypot(*(tr[:, :2] - truth[0, :2]).T),
        node_step_error=step_fe - step_true,
    )


def main(argv: list[str]) -> None:
    d = Drive()
    keys = ("world", "y", "x_from", "x_to", "speed")
    for k, v in zip(keys, argv[:5], strict=False):
        d = replace(d, **{k: v if k == "world" else float(v)})
    r = replay(d)
    print(json.dumps({k: v for k, v in r.__dict__.items() if not isinstance(v, np.ndarray)}))


if __name__ == "__main__":
    main(sys.argv[1:])
