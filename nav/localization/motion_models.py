"""Odometry motion models for particle filters, vectorized over particles.

Differential drive: ``sample_motion_model_odometry`` of Thrun, Burgard & Fox, *Probabilistic
Robotics* (2005), Table 5.6: the odometry increment between two filter updates is split into an
initial rotation ``rot1``, a translation ``trans`` and a final rotation ``rot2``, and each is
perturbed with zero-mean Gaussian noise whose variance grows with the motion through alpha1..alpha4.
Like Nav2 (``nav2_amcl/motion_model/differential_motion_model.cpp``) the rotation *noise* terms use
``min(|rot|, |pi - rot|)``, so a robot driving backwards (rot1 near +-pi) is not treated as having
turned around twice, and ``rot1`` is 0 for a near-pure rotation (trans < 1 cm) where atan2 is noise.

Omnidirectional: Nav2's ``omni_motion_model.cpp``: the increment is a translation along the
bearing of travel, a rotation, and a strafe perpendicular to the bearing whose noise is driven by
alpha5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.types import Pose2D, wrap_angle

# Below this translation (m) the direction of travel is undefined: treat the motion as a pure turn.
_MIN_TRANS_FOR_ROT1 = 0.01


@dataclass(frozen=True)
class MotionAlphas:
    """Noise parameters alpha1..alpha5 (Nav2 amcl names; alpha5 is used by the omni model only)."""

    alpha1: float = 0.2
    alpha2: float = 0.2
    alpha3: float = 0.2
    alpha4: float = 0.2
    alpha5: float = 0.2


@dataclass(frozen=True)
class OdometryDelta:
    """The decomposition of an odometry increment (Thrun Table 5.6, lines 2-4)."""

    rot1: float
    trans: float
    rot2: float


def decompose_odometry(odom_prev: Pose2D, odom_now: Pose2D) -> OdometryDelta:
    """Split the motion between two odometry poses into (rot1, trans, rot2)."""
    dx = odom_now.x - odom_prev.x
    dy = odom_now.y - odom_prev.y
    trans = float(np.hypot(dx, dy))
    if trans < _MIN_TRANS_FOR_ROT1:
        rot1 = 0.0
    else:
        rot1 = float(wrap_angle(np.arctan2(dy, dx) - odom_prev.theta))
    rot2 = float(wrap_angle(odom_now.theta - odom_prev.theta - rot1))
    return OdometryDelta(rot1, trans, rot2)


def _reverse_aware(rot: float) -> float:
    """Magnitude of a rotation for the noise model, treating forward and backward motion alike."""
    return min(abs(float(wrap_angle(rot))), abs(float(wrap_angle(rot - np.pi))))


def sample_motion_model_odometry(
    particles: np.ndarray,
    odom_prev: Pose2D,
    odom_now: Pose2D,
    alphas: MotionAlphas,
    rng: np.random.Generator,
) -> np.ndarray:
    """Propagate (N, 3) particles [x, y, theta] through one odometry increment (differential drive).

    Returns a new (N, 3) array; every particle gets its own noise sample.
    """
    d = decompose_odometry(odom_prev, odom_now)
    r1n, r2n = _reverse_aware(d.rot1), _reverse_aware(d.rot2)
    t2 = d.trans * d.trans
    sd_rot1 = np.sqrt(alphas.alpha1 * r1n * r1n + alphas.alpha2 * t2)
    sd_trans = np.sqrt(alphas.alpha3 * t2 + alphas.alpha4 * (r1n * r1n + r2n * r2n))
    sd_rot2 = np.sqrt(alphas.alpha1 * r2n * r2n + alphas.alpha2 * t2)
    n = particles.shape[0]
    noise = rng.standard_normal((n, 3))
    rot1_hat = d.rot1 - sd_rot1 * noise[:, 0]
    trans_hat = d.trans - sd_trans * noise[:, 1]
    rot2_hat = d.rot2 - sd_rot2 * noise[:, 2]
    out = np.empty_like(particles, dtype=float)
    heading = particles[:, 2] + rot1_hat
    out[:, 0] = particles[:, 0] + trans_hat * np.cos(heading)
    out[:, 1] = particles[:, 1] + trans_hat * np.sin(heading)
    out[:, 2] = wrap_angle(particles[:, 2] + rot1_hat + rot2_hat)
    return out


def sample_motion_model_omni(
    particles: np.ndarray,
    odom_prev: Pose2D,
    odom_now: Pose2D,
    alphas: MotionAlphas,
    rng: np.random.Generator,
) -> np.ndarray:
    """Propagate (N, 3) particles through one odometry increment of an omnidirectional base.

    Translation noise grows with translation (alpha3) and rotation (alpha1), rotation noise with
    rotation (alpha4) and translation (alpha2), strafe noise with rotation (alpha1) and
    translation (alpha5): Nav2 ``OmniMotionModel::odometryUpdate``.
    """
    dx = odom_now.x - odom_prev.x
    dy = odom_now.y - odom_prev.y
    trans = float(np.hypot(dx, dy))
    rot = float(wrap_angle(odom_now.theta - odom_prev.theta))
    t2, r2 = trans * trans, rot * rot
    sd_trans = np.sqrt(alphas.alpha3 * t2 + alphas.alpha1 * r2)
    sd_rot = np.sqrt(alphas.alpha4 * r2 + alphas.alpha2 * t2)
    sd_strafe = np.sqrt(alphas.alpha1 * r2 + alphas.alpha5 * t2)
    # Bearing of travel relative to the old heading, re-applied to each particle's heading.
    rel_bearing = float(wrap_angle(np.arctan2(dy, dx) - odom_prev.theta)) if trans > 0.0 else 0.0
    n = particles.shape[0]
    noise = rng.standard_normal((n, 3))
    bearing = particles[:, 2] + rel_bearing
    cb, sb = np.cos(bearing), np.sin(bearing)
    trans_hat = trans + sd_trans * noise[:, 0]
    rot_hat = rot + sd_rot * noise[:, 1]
    strafe_hat = sd_strafe * noise[:, 2]
    out = np.empty_like(particles, dtype=float)
    out[:, 0] = particles[:, 0] + trans_hat * cb + strafe_hat * sb
    out[:, 1] = particles[:, 1] + trans_hat * sb - strafe_hat * cb
    out[:, 2] = wrap_angle(particles[:, 2] + rot_hat)
    return out


def sample_motion(
    model_type: str,
    particles: np.ndarray,
    odom_prev: Pose2D,
    odom_now: Pose2D,
    alphas: MotionAlphas,
    rng: np.random.Generator,
) -> np.ndarray:
    """Dispatch on Nav2's ``robot_model_type`` (``differential`` or ``omnidirectional``)."""
    if model_type == "omnidirectional":
        return sample_motion_model_omni(particles, odom_prev, odom_now, alphas, rng)
    if model_type == "differential":
        return sample_motion_model_odometry(particles, odom_prev, odom_now, alphas, rng)
    raise ValueError(f"unknown robot_model_type {model_type!r}")
