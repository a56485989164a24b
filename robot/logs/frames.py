"""The laser's mount on the robot from a bag's tf tree (``/tf_static``, else ``/tf``).

A mount may be a chain (``base_link -> base_scan``, or ``base_footprint -> base_link -> lidar_link
-> laser`` on many robots) and may be rotated out of the plane: a lidar hung upside down (rotated
by pi about x) sees the world mirrored, so its 2D pose alone is not enough. The chain is composed in
3D and reduced to what a 2D pipeline needs: x, y, yaw of the laser's x axis in the base frame, and
whether its z axis points down (REP-103: z up).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from nav.types import LaserScan, Pose2D

BASE_FRAMES = ("base_link", "base_footprint")
"""Robot body frames (REP-105), in order of preference."""


def quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """3x3 rotation of a (normalized here) quaternion."""
    n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclass(frozen=True)
class Transform3:
    """A rigid transform parent -> child: ``p_parent = rotation @ p_child + translation``."""

    rotation: np.ndarray
    translation: np.ndarray

    def compose(self, other: Transform3) -> Transform3:
        return Transform3(
            self.rotation @ other.rotation, self.rotation @ other.translation + self.translation
        )

    def inverse(self) -> Transform3:
        rt = self.rotation.T
        return Transform3(rt, -rt @ self.translation)


@dataclass(frozen=True)
class LaserMount:
    """The laser in the base frame, reduced to 2D; ``chain`` names the frames it was composed from."""

    pose: Pose2D
    upside_down: bool = False
    chain: tuple[str, ...] = ()

    def describe(self) -> str:
        flip = ", upside down (scans mirrored)" if self.upside_down else ""
        via = " -> ".join(self.chain) if self.chain else "default (no tf for the laser frame)"
        return (
            f"laser mount x={self.pose.x:.3f} m y={self.pose.y:.3f} m "
            f"yaw={math.degrees(self.pose.theta):.1f} deg{flip} ({via})"
        )


def mount_from_transform(tf: Transform3, chain: tuple[str, ...]) -> LaserMount:
    r = tf.rotation
    yaw = math.atan2(r[1, 0], r[0, 0])  # where the laser's x axis points in the base plane
    return LaserMount(
        Pose2D(float(tf.translation[0]), float(tf.translation[1]), yaw), bool(r[2, 2] < 0.0), chain
    )


class TfTree:
    """Latest transform per (parent, child) edge; lookups walk the tree both ways."""

    def __init__(self) -> None:
        self.edges: dict[tuple[str, str], Transform3] = {}

    def add(self, parent: str, child: str, translation, rotation_xyzw) -> None:
        parent, child = parent.lstrip("/"), child.lstrip("/")
        self.edges[(parent, child)] = Transform3(quat_matrix(*rotation_xyzw), np.asarray(translation, float))

    def lookup(self, source: str, target: str) -> tuple[Transform3, tuple[str, ...]] | None:
        """Transform ``source -> target`` (a pose of target in source) and the frames passed."""
        source, target = source.lstrip("/"), target.lstrip("/")
        nbrs: dict[str, list[tuple[str, Transform3]]] = {}
        for (p, c), tf in self.edges.items():
            nbrs.setdefault(p, []).append((c, tf))
            nbrs.setdefault(c, []).append((p, tf.inverse()))
        seen = {source: (Transform3(np.eye(3), np.zeros(3)), (source,))}
        todo = deque([source])
        while todo:
            f = todo.popleft()
            if f == target:
                return seen[f]
            tf_f, path = seen[f]
            for n, tf in nbrs.get(f, []):
                if n not in seen:
                    seen[n] = (tf_f.compose(tf), (*path, n))
                    todo.append(n)
        return None

    def laser_mount(self, laser_frame: str) -> LaserMount | None:
        """The mount of ``laser_frame`` on the first body frame the tree connects it to."""
        for base in BASE_FRAMES:
            hit = self.lookup(base, laser_frame)
            if hit is not None:
                return mount_from_transform(*hit)
        return None


def upright(scan: LaserScan) -> LaserScan:
    """The scan an upright laser at the same place would report: angles negated, beams reversed so
    the angles still increase (a beam at angle a of a flipped laser lies at -a in the body plane)."""
    n = scan.ranges.shape[0]
    return replace(
        scan,
        angle_min=-(scan.angle_min + (n - 1) * scan.angle_increment),
        ranges=scan.ranges[::-1].copy(),
    )
