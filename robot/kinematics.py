"""Wheel kinematics and pose integration for skid-steer, differential and 4-wheel omni bases.

- Skid steer (source A): the four wheels are folded into a differential drive with two virtual
  wheels, ``W_L = (W_FL + W_RL) / 2`` and ``W_R = (W_FR + W_RR) / 2``.
- Differential drive (source B): ``v = (v_r + v_l) / 2``, ``w = (v_r - v_l) / L``; over a short
  interval the base moves on an arc about the instantaneous centre of rotation.
- Omni, four wheels 90 degrees apart (source C): wheel ``i`` sits at angle ``a_i`` (front 0, left
  pi/2, rear pi, right -pi/2) at radius ``R`` and rolls tangentially, so its rim speed is
  ``-sin(a_i) vx + cos(a_i) vy + R w``; the pose follows ``xdot = vx cos(theta) - vy sin(theta)``,
  ``ydot = vx sin(theta) + vy cos(theta)``, ``thetadot = w``.

Wheel order everywhere is the profile's: skid/diff-4 ``FL, RL, FR, RR``; diff-2 ``L, R``; omni
``front, left, rear, right``. Functions accept numpy arrays so many samples go through at once.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import Pose2D, Twist2D, wrap_angle

# Omni wheel angles about base_link, in profile order (front, left, rear, right).
OMNI_WHEEL_ANGLES = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
# |phi| below this uses the series form of the arc update (avoids 0/0 in r = d / phi).
_SMALL_ANGLE = 1e-9


def virtual_wheels(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Four skid wheels (last axis FL, RL, FR, RR) -> virtual (left, right); two wheels pass through."""
    w = np.asarray(w, dtype=float)
    if w.shape[-1] == 2:
        return w[..., 0], w[..., 1]
    if w.shape[-1] != 4:
        raise ValueError(f"expected 2 or 4 wheels on the last axis, got {w.shape[-1]}")
    return (w[..., 0] + w[..., 1]) / 2.0, (w[..., 2] + w[..., 3]) / 2.0


def diff_forward(v_left: np.ndarray, v_right: np.ndarray, track: float) -> tuple[np.ndarray, np.ndarray]:
    """Wheel rim speeds (m/s) -> body (v, w): ``v = (v_r + v_l)/2``, ``w = (v_r - v_l)/track``."""
    return (np.asarray(v_right) + v_left) / 2.0, (np.asarray(v_right) - v_left) / track


def diff_inverse(v: np.ndarray, w: np.ndarray, track: float) -> tuple[np.ndarray, np.ndarray]:
    """Body (v, w) -> wheel rim speeds (v_left, v_right)."""
    half = np.asarray(w) * (track / 2.0)
    return np.asarray(v) - half, np.asarray(v) + half


def skid_inverse(v: np.ndarray, w: np.ndarray, track: float) -> np.ndarray:
    """Body (v, w) -> four rim speeds (..., 4) in FL, RL, FR, RR order (both wheels of a side equal)."""
    vl, vr = diff_inverse(v, w, track)
    return np.stack((vl, vl, vr, vr), axis=-1)


def skid_forward(wheels: np.ndarray, track: float) -> tuple[np.ndarray, np.ndarray]:
    """Four rim speeds (FL, RL, FR, RR) -> body (v, w) through the virtual wheels."""
    vl, vr = virtual_wheels(wheels)
    return diff_forward(vl, vr, track)


def omni_inverse(vx: np.ndarray, vy: np.ndarray, w: np.ndarray, radius: float) -> np.ndarray:
    """Body twist -> four rim speeds (..., 4) in front, left, rear, right order."""
    vx, vy, w = (np.asarray(a, dtype=float)[..., None] for a in (vx, vy, w))
    return -np.sin(OMNI_WHEEL_ANGLES) * vx + np.cos(OMNI_WHEEL_ANGLES) * vy + radius * w


def omni_forward(wheels: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Four rim speeds -> body (vx, vy, w): the least-squares inverse of ``omni_inverse`` (exact
    when the wheels agree, averaging out disagreement otherwise)."""
    s = np.asarray(wheels, dtype=float)
    f, l, b, r = s[..., 0], s[..., 1], s[..., 2], s[..., 3]
    return (r - l) / 2.0, (f - b) / 2.0, (f + l + b + r) / (4.0 * radius)


def wheel_speeds(
    kinematics: str, twist: Twist2D, track: float, omni_radius: float, wheels: int
) -> np.ndarray:
    """Rim speeds (m/s) for a body twist, in profile wheel order."""
    if kinematics == "omni":
        return omni_inverse(twist.vx, twist.vy, twist.wz, omni_radius)
    if wheels == 2:
        return np.array(diff_inverse(twist.vx, twist.wz, track))
    return skid_inverse(twist.vx, twist.wz, track)


def body_twist(kinematics: str, rim_speeds: np.ndarray, track: float, omni_radius: float) -> Twist2D:
    """Rim speeds in profile wheel order -> body twist."""
    if kinematics == "omni":
        vx, vy, w = omni_forward(rim_speeds, omni_radius)
        return Twist2D(float(vx), float(vy), float(w))
    v, w = skid_forward(rim_speeds, track)
    return Twist2D(float(v), 0.0, float(w))


def integrate_exact(pose: Pose2D, d_left: float, d_right: float, track: float) -> Pose2D:
    """Arc update for a differential drive (source B): travel ``d = (d_l + d_r)/2`` on a circle
    turning ``phi = (d_r - d_l)/track``; the straight-line limit is taken when ``phi`` ~ 0."""
    d = (d_left + d_right) / 2.0
    phi = (d_right - d_left) / track
    return integrate_arc(pose, d, phi)


def integrate_arc(pose: Pose2D, d: float, phi: float) -> Pose2D:
    """Move ``d`` metres along a circular arc while turning ``phi`` radians (exact)."""
    th = pose.theta
    if abs(phi) < _SMALL_ANGLE:
        mid = th + phi / 2.0
        dx, dy = d * math.cos(mid), d * math.sin(mid)
    else:
        r = d / phi
        dx = r * (math.sin(th + phi) - math.sin(th))
        dy = -r * (math.cos(th + phi) - math.cos(th))
    return Pose2D(pose.x + dx, pose.y + dy, float(wrap_angle(th + phi)))


def integrate_small_angle(pose: Pose2D, d_left: float, d_right: float, track: float) -> Pose2D:
    """Source A's first-order form: ``x' = x + d cos(theta)``, ``y' = y + d sin(theta)``,
    ``theta' = theta + phi`` (heading taken at the start of the interval)."""
    d = (d_left + d_right) / 2.0
    phi = (d_right - d_left) / track
    return Pose2D(
        pose.x + d * math.cos(pose.theta),
        pose.y + d * math.sin(pose.theta),
        float(wrap_angle(pose.theta + phi)),
    )


def se2_exp(dx: np.ndarray, dy: np.ndarray, dth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body-frame displacement of a constant twist integrated for unit time: the SE(2) exponential
    of (dx, dy, dth) = (vx, vy, w) * dt. Vectorized; exact straight-line limit for dth -> 0."""
    dx, dy, dth = (np.asarray(a, dtype=float) for a in (dx, dy, dth))
    small = np.abs(dth) < 1e-6
    safe = np.where(small, 1.0, dth)
    # sin(t)/t and (1 - cos t)/t with their series near 0
    a = np.where(small, 1.0 - dth**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, dth / 2.0 - dth**3 / 24.0, (1.0 - np.cos(safe)) / safe)
    return a * dx - b * dy, b * dx + a * dy, dth


def integrate_twist(pose: Pose2D, twist: Twist2D, dt: float) -> Pose2D:
    """Exact pose after holding a body twist (vx, vy, w) for ``dt`` seconds (diff and omni).
    Scalar math (no numpy): this runs every physics substep."""
    dx, dy, dth = twist.vx * dt, twist.vy * dt, twist.wz * dt
    if abs(dth) < 1e-6:
        a, b = 1.0 - dth * dth / 6.0, dth / 2.0 - dth**3 / 24.0
    else:
        a, b = math.sin(dth) / dth, (1.0 - math.cos(dth)) / dth
    ex, ey = a * dx - b * dy, b * dx + a * dy
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    return Pose2D(pose.x + c * ex - s * ey, pose.y + s * ex + c * ey, float(wrap_angle(pose.theta + dth)))


def integrate_poses(poses: np.ndarray, twists: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """Vectorized ``integrate_twist``: (N, 3) poses and (N, 3) body twists -> (N, 3) poses."""
    poses = np.asarray(poses, dtype=float)
    tw = np.asarray(twists, dtype=float) * np.asarray(dt, dtype=float)[..., None]
    ex, ey, eth = se2_exp(tw[..., 0], tw[..., 1], tw[..., 2])
    c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
    out = np.empty_like(poses)
    out[..., 0] = poses[..., 0] + c * ex - s * ey
    out[..., 1] = poses[..., 1] + s * ex + c * ey
    out[..., 2] = wrap_angle(poses[..., 2] + eth)
    return out
