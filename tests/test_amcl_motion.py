"""Odometry motion models: sample statistics against the alpha parameters (Thrun Table 5.6, Nav2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.localization.motion_models import (
    MotionAlphas,
    decompose_odometry,
    sample_motion,
    sample_motion_model_odometry,
    sample_motion_model_omni,
)
from nav.types import Pose2D, wrap_angle

N = 200_000


def _rng() -> np.random.Generator:
    return np.random.default_rng(7)


def _recover(particles_before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample (rot1, trans, rot2) actually applied, from a particle starting at the origin."""
    dx, dy = after[:, 0] - particles_before[:, 0], after[:, 1] - particles_before[:, 1]
    trans = np.hypot(dx, dy)
    rot1 = wrap_angle(np.arctan2(dy, dx) - particles_before[:, 2])
    rot2 = wrap_angle(after[:, 2] - particles_before[:, 2] - rot1)
    return rot1, trans, rot2


def test_decompose_forward_and_turn() -> None:
    d = decompose_odometry(Pose2D(1.0, 2.0, 0.5), Pose2D(1.0 + math.cos(0.7), 2.0 + math.sin(0.7), 1.0))
    assert d.trans == pytest.approx(1.0)
    assert d.rot1 == pytest.approx(0.2)
    assert d.rot2 == pytest.approx(0.3)


def test_decompose_pure_rotation_has_no_rot1() -> None:
    d = decompose_odometry(Pose2D(0.0, 0.0, 0.1), Pose2D(0.001, 0.0, 0.6))
    assert d.rot1 == 0.0
    assert d.rot2 == pytest.approx(0.5)


def test_differential_sample_statistics_match_alphas() -> None:
    """Mean motion is the odometry; the variances are alpha1 rot^2 + alpha2 trans^2 etc."""
    a = MotionAlphas(alpha1=0.1, alpha2=0.05, alpha3=0.02, alpha4=0.03)  # trans_hat stays > 0
    start = np.zeros((N, 3))
    prev, now = Pose2D(0.0, 0.0, 0.0), Pose2D(0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.5)
    out = sample_motion_model_odometry(start, prev, now, a, _rng())
    rot1, trans, rot2 = _recover(start, out)
    r1, t, r2 = 0.3, 0.5, 0.2
    assert rot1.mean() == pytest.approx(r1, abs=2e-3)
    assert trans.mean() == pytest.approx(t, abs=2e-3)
    assert rot2.mean() == pytest.approx(r2, abs=2e-3)
    assert rot1.var() == pytest.approx(a.alpha1 * r1**2 + a.alpha2 * t**2, rel=0.03)
    assert trans.var() == pytest.approx(a.alpha3 * t**2 + a.alpha4 * (r1**2 + r2**2), rel=0.03)
    assert rot2.var() == pytest.approx(a.alpha1 * r2**2 + a.alpha2 * t**2, rel=0.03)


def test_differential_applies_motion_in_each_particle_frame() -> None:
    """A particle facing +y moves along +y for a forward odometry step along odom +x."""
    p = np.array([[2.0, 3.0, math.pi / 2]])
    out = sample_motion_model_odometry(
        p, Pose2D(0, 0, 0), Pose2D(1.0, 0, 0), MotionAlphas(0, 0, 0, 0), _rng()
    )
    np.testing.assert_allclose(out[0], [2.0, 4.0, math.pi / 2], atol=1e-12)


def test_backward_motion_noise_like_forward() -> None:
    """Nav2: reversing (rot1 = pi) must not count as two half turns in the noise model."""
    a = MotionAlphas(0.2, 0.2, 0.2, 0.2)
    start = np.zeros((N, 3))
    fwd = sample_motion_model_odometry(start, Pose2D(), Pose2D(0.3, 0.0, 0.0), a, _rng())
    back = sample_motion_model_odometry(start, Pose2D(), Pose2D(-0.3, 0.0, 0.0), a, _rng())
    assert back[:, 0].mean() == pytest.approx(-0.3, abs=3e-3)
    assert np.std(back[:, 2]) == pytest.approx(np.std(fwd[:, 2]), rel=0.03)
    assert np.std(back[:, 0]) == pytest.approx(np.std(fwd[:, 0]), rel=0.03)
    # Without the reverse-aware rule the heading spread would be sqrt(2 * 0.2) * pi ~ 2 rad.
    assert np.std(back[:, 2]) < 0.3


def test_zero_motion_is_identity() -> None:
    p = _rng().normal(size=(100, 3))
    p[:, 2] = wrap_angle(p[:, 2])
    out = sample_motion_model_odometry(p, Pose2D(1, 1, 1), Pose2D(1, 1, 1), MotionAlphas(), _rng())
    np.testing.assert_allclose(out, p, atol=1e-12)


def test_omni_strafe_statistics_use_alpha5() -> None:
    """A pure sideways odometry step: mean motion is the strafe, lateral spread sqrt(alpha3) t and
    along-track (perpendicular to the bearing) spread sqrt(alpha5) t."""
    a = MotionAlphas(alpha1=0.1, alpha2=0.05, alpha3=0.04, alpha4=0.1, alpha5=0.01)
    start = np.zeros((N, 3))
    out = sample_motion_model_omni(start, Pose2D(), Pose2D(0.0, 0.4, 0.0), a, _rng())
    assert out[:, 0].mean() == pytest.approx(0.0, abs=2e-3)
    assert out[:, 1].mean() == pytest.approx(0.4, abs=2e-3)
    # Bearing is +y: translation noise along y, strafe noise along x.
    assert out[:, 1].std() == pytest.approx(math.sqrt(a.alpha3) * 0.4, rel=0.03)
    assert out[:, 0].std() == pytest.approx(math.sqrt(a.alpha5) * 0.4, rel=0.03)
    assert out[:, 2].std() == pytest.approx(math.sqrt(a.alpha2) * 0.4, rel=0.03)


def test_omni_rotation_noise_uses_alpha4() -> None:
    a = MotionAlphas(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.09, alpha5=0.0)
    out = sample_motion_model_omni(np.zeros((N, 3)), Pose2D(), Pose2D(0.0, 0.0, 0.5), a, _rng())
    assert out[:, 2].mean() == pytest.approx(0.5, abs=2e-3)
    assert out[:, 2].std() == pytest.approx(0.3 * 0.5, rel=0.03)
    np.testing.assert_allclose(out[:, :2], 0.0, atol=1e-12)


def test_dispatch_and_unknown_model() -> None:
    p = np.zeros((3, 3))
    out = sample_motion(
        "omnidirectional", p, Pose2D(), Pose2D(0.1, 0, 0), MotionAlphas(0, 0, 0, 0, 0), _rng()
    )
    np.testing.assert_allclose(out[:, 0], 0.1)
    with pytest.raises(ValueError):
        sample_motion("ackermann", p, Pose2D(), Pose2D(), MotionAlphas(), _rng())
