"""Turning viser pointer events into planar poses, like Rviz2's "2D Goal Pose" / "2D Pose Estimate" tools.

viser reports a click as a camera ray (``SceneClickEvent.ray_origin/ray_direction``) and a node drag as
a grab point on the node plus the pointer projected onto a *camera-facing* plane through it
(``SceneNodeDragEvent.end_position``). The robot lives on the ground plane z = 0 (REP-103, z up), so
both become ground points by intersecting the camera ray with z = 0; Rviz's tools do the same
(``rviz_common::interaction::ViewportProjectionFinder``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from nav.types import Pose2D

Vec3 = Sequence[float] | np.ndarray


class PoseInputError(ValueError):
    """A pointer event that does not define a ground pose (ray parallel to or away from the ground)."""


def ray_ground(origin: Vec3, direction: Vec3, z: float = 0.0) -> np.ndarray:
    """(x, y) where the ray ``origin + t * direction`` (t > 0) meets the plane at height ``z``."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or abs(d[2]) < 1e-9:
        raise PoseInputError("ray does not meet the ground")
    t = (z - o[2]) / d[2]
    if t <= 0.0:
        raise PoseInputError("ground is behind the camera")
    return (o + t * d)[:2]


def ground_through(camera_position: Vec3, point: Vec3, z: float = 0.0) -> np.ndarray:
    """Ground point seen behind ``point`` from the camera: the pointer ray through a drag-plane point."""
    c = np.asarray(camera_position, dtype=float)
    return ray_ground(c, np.asarray(point, dtype=float) - c, z)


def pose_from_press_drag(press_xy: Vec3, release_xy: Vec3, fallback_theta: float = 0.0) -> Pose2D:
    """Rviz's pose tools: the press sets the position, the drag direction sets the heading.

    A drag shorter than 1 mm keeps ``fallback_theta`` (a click without a drag)."""
    p = np.asarray(press_xy, dtype=float)[:2]
    q = np.asarray(release_xy, dtype=float)[:2]
    d = q - p
    theta = math.atan2(d[1], d[0]) if float(np.hypot(*d)) > 1e-3 else fallback_theta
    return Pose2D(float(p[0]), float(p[1]), float(theta))


def heading_towards(frm: Pose2D, xy: Vec3) -> float:
    """Heading from ``frm`` to ``xy`` (used when a plain click gives a goal without a heading: arrive
    facing the direction of travel); ``frm.theta`` if the point is on top of it."""
    dx, dy = float(xy[0]) - frm.x, float(xy[1]) - frm.y
    return math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-3 else frm.theta
