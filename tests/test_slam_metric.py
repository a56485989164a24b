"""The benchmark metric's frame: relations obtained from laser scans relate laser poses, so a
base_link trajectory of a robot with an off-centre laser is scored in the laser's frame."""

from __future__ import annotations

import math

import numpy as np

from nav.slam.metric import in_sensor_frame, score_trajectory
from nav.slam.synthetic import box_world, cast_scan
from nav.slam.system import GraphSlam, SlamOptions
from nav.types import Pose2D

MOUNT = np.array([0.3, 0.05, 0.0])


def _relations(poses: np.ndarray, t: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    rows = []
    for a, b in pairs:
        d = Pose2D.from_array(poses[b]).relative_to(Pose2D.from_array(poses[a]))
        rows.append((t[a], t[b], d.x, d.y, d.theta))
    return np.array(rows)


def test_laser_relations_score_zero_in_the_laser_frame_only() -> None:
    # a robot turning on the spot and driving: base_link poses, laser 0.3 m ahead
    t = np.arange(6, dtype=float)
    base = np.array(
        [[0, 0, 0], [0, 0, math.pi / 2], [0, 0, math.pi], [1, 0, math.pi], [1, 1, -math.pi / 2], [2, 1, 0.3]]
    )
    traj = np.column_stack((t, base))
    laser = in_sensor_frame(traj, MOUNT)
    assert np.allclose(laser[1, 1:3], [-0.05, 0.3])  # rotated mount offset
    rel = _relations(laser[:, 1:], t, [(0, 1), (0, 2), (1, 3), (2, 5), (0, 5)])
    assert score_trajectory(laser, rel).trans_mean < 1e-9
    # the same relations against base_link poses: off by up to twice the mount on a half turn
    wrong = score_trajectory(traj, rel)
    assert wrong.trans_mean > 0.2 and wrong.rot_mean_deg < 1e-9


def test_trajectory_in_the_sensor_frame() -> None:
    grid, res = box_world()
    slam = GraphSlam(SlamOptions())
    mount = Pose2D(*MOUNT)
    for k in range(8):
        truth = Pose2D(3.0 + 0.15 * k, 3.0, 0.1 * k)
        scan = cast_scan(grid, res, truth.compose(mount), 180, stamp=0.2 * k)
        slam.add_scan(scan, truth.relative_to(Pose2D(3.0, 3.0, 0.0)), mount)
    base = slam.trajectory()
    sensor = slam.trajectory(sensor=True)
    assert np.allclose(sensor, in_sensor_frame(base, MOUNT))
    assert np.allclose(np.hypot(*(sensor[:, 1:3] - base[:, 1:3]).T), math.hypot(0.3, 0.05))
