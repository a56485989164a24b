"""Walkers between two scans: person-sized clusters of returns tracked by their centroid.

A pure algorithm shared by the safety layer (robot/safety.py, in the base frame of each scan) and the
navigation stage (in the map frame, for TEB's dynamic obstacles): consecutive returns less than
``CLUSTER_GAP`` apart form a cluster; one at most ``PERSON_MAX_EXTENT`` wide with at least three
returns is person-sized; its centroid is matched to the nearest person-sized centroid of the
previous scan, and a walking speed (``PERSON_MIN_SPEED`` .. ``PERSON_MAX_SPEED``) makes it a walker
with a constant velocity, as teb_local_planner's and collision_monitor's dynamic obstacles.
Everything is a few vectorized numpy operations per scan.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import Pose2D

PERSON_MAX_SPEED = 1.5
"""m/s; fastest walker predicted (faster apparent motion is a mismatch)."""
PERSON_MIN_SPEED = 0.2
"""m/s; slower apparent motion of a cluster is taken for noise (a static object)."""
PERSON_MAX_EXTENT = 0.7
"""m; a cluster of returns wider than this is a wall or furniture, not a person."""
CLUSTER_GAP = 0.15
"""m; consecutive returns farther apart than this belong to different objects."""
PERSON_RADIUS = 0.25
"""m; a walker's body around its tracked centroid (the scan sees only its near side)."""
MAX_SCAN_GAP = 1.0
"""s; clusters of a scan older than this are not matched (the walker may be anywhere)."""


def scan_clusters(pts: np.ndarray) -> np.ndarray:
    """Cluster label per return (N, 2, in scan order, N >= 1): consecutive returns less than
    ``CLUSTER_GAP`` apart share one, numbered from 0 in scan order."""
    return np.concatenate(([0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T) > CLUSTER_GAP)))


class WalkerTracker:
    """``update(points, stamp) -> velocity per point``; ``centres`` / ``velocities`` hold the
    walkers (moving person-sized clusters) of the latest scan, in the frame of its points."""

    def __init__(self) -> None:
        self._clusters = np.zeros((0, 2))
        self._stamp = -math.inf
        self.centres = np.zeros((0, 2))
        self.velocities = np.zeros((0, 2))
        self.stamp = -math.inf

    def reset(self) -> None:
        self.__init__()

    def update(self, pts: np.ndarray, stamp: float, prev_to_now: Pose2D | None = None) -> np.ndarray:
        """Predicted velocity (N, 2) of each of a scan's returns ``pts`` (beam order, any fixed
        frame): zero except for the walkers' returns. ``prev_to_now`` maps the previous scan's
        frame into this one's (the robot's motion between two base-frame scans; None: same frame)."""
        vel = np.zeros_like(pts, dtype=float)
        self.centres, self.velocities, self.stamp = np.zeros((0, 2)), np.zeros((0, 2)), stamp
        if pts.shape[0] == 0:
            self._clusters, self._stamp = np.zeros((0, 2)), stamp
            return vel
        label = scan_clusters(pts)
        count = np.bincount(label)
        centre = (
            np.column_stack((np.bincount(label, pts[:, 0]), np.bincount(label, pts[:, 1]))) / count[:, None]
        )
        first = np.searchsorted(label, np.arange(len(count)))
        last = np.searchsorted(label, np.arange(len(count)), side="right") - 1
        extent = np.hypot(*(pts[last] - pts[first]).T)
        person = (count >= 3) & (extent <= PERSON_MAX_EXTENT)
        dt = stamp - self._stamp
        prev = self._clusters
        if prev.size and prev_to_now is not None:
            prev = prev_to_now.transform_points(prev)
        if prev.size and 0.0 < dt <= MAX_SCAN_GAP and person.any():
            d = np.hypot(centre[:, None, 0] - prev[None, :, 0], centre[:, None, 1] - prev[None, :, 1])
            j = d.argmin(axis=1)
            v = (centre - prev[j]) / dt
            speed = np.hypot(v[:, 0], v[:, 1])
            walking = person & (speed >= PERSON_MIN_SPEED) & (speed <= PERSON_MAX_SPEED)
            vel = np.where(walking[label][:, None], v[label], 0.0)
            self.centres, self.velocities = centre[walking], v[walking]
        self._clusters, self._stamp = centre[person], stamp
        return vel


def near_points(centres: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Which of the walkers' ``centres`` (W, 2) lie within ``radius`` of any of ``points`` (M, 2):
    a walker on a stretch of path (the points a path's, the radius the robot's circumscribed
    radius plus a walker's body and a margin)."""
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if not (len(c) and len(p)):
        return np.zeros(len(c), dtype=bool)
    d = np.hypot(c[:, None, 0] - p[None, :, 0], c[:, None, 1] - p[None, :, 1])
    return (d <= radius).any(axis=1)
