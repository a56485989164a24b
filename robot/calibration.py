"""Odometry calibration math: wheel radius from a measured straight line, effective track width (or
omni radius) from a measured number of in-place turns, and a comment-preserving profile TOML update.

The method is the classic two-run encoder calibration (UMBmark's simplest form; Borenstein & Feng,
"Measurement and correction of systematic odometry errors in mobile robots", IEEE T-RA 1996): a
wrong wheel radius scales every distance by ``r_true / r_profile``, so one straight run against a
tape measure gives ``r_new = r * d_measured / d_encoders``. The turn run then fixes the effective
track: encoder yaw is ``(d_right - d_left) / track``, so ``track_new = (d_right - d_left)|r_new /
phi_measured`` (the distances recomputed with the *corrected* radius, otherwise the radius error
would be folded into the track). Skid-steer wheels scrub when turning, so the effective track is
usually wider than the wheel spacing; that is what odometry needs, not the tape-measured spacing.

A gyro integral over the turn is an independent measurement of the angle: it is reported next to the
operator's count and can stand in for it (``use_gyro``) when counting turns is impractical.

Pure functions: numpy in, numbers out, no I/O (``app/commands/calibrate.py`` drives the robot).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot.kinematics import omni_forward, virtual_wheels
from robot.profiles import RobotProfile


class CalibrationError(ValueError):
    """A run is too short, inconsistent or gives an implausible correction; the message says which."""


@dataclass(frozen=True)
class CalibrationOptions:
    """Sanity limits of the calibration runs."""

    min_distance: float = 0.2
    """m; the straight run must cover at least this (shorter runs are dominated by tick quantization
    and the operator's measuring error). Default 0.2."""
    min_angle: float = math.pi
    """rad; the turn run must cover at least half a turn. Default pi."""
    max_ratio: float = 1.5
    """A corrected value more than this factor away from the profile's is refused as a mistake
    (wrong units, wrong robot, turns miscounted). Default 1.5."""
    max_heading_drift: float = 0.35
    """rad; the straight run's encoder heading change above this means it was not straight. Default 0.35."""
    gyro_tolerance: float = 0.05
    """Relative disagreement between the gyro and the measured angle above which a warning is
    raised (a miscounted turn or a gyro scale error). Default 0.05."""


@dataclass(frozen=True)
class CalibrationResult:
    """Old and corrected geometry, with the quantities they came from (SI units)."""

    wheel_radius: float
    wheel_radius_new: float
    turn_field: str  # "track_width" (skid/diff) or "omni_radius" (omni)
    turn_value: float
    turn_value_new: float
    encoder_distance: float  # straight run, with the old radius
    measured_distance: float
    encoder_angle: float  # turn run, with the old geometry
    measured_angle: float
    gyro_angle: float | None
    warnings: tuple[str, ...] = ()

    def changes(self) -> dict[str, float]:
        """Profile fields to write: ``{"wheel_radius": ..., "track_width" | "omni_radius": ...}``."""
        return {"wheel_radius": self.wheel_radius_new, self.turn_field: self.turn_value_new}


def wheel_travel(profile: RobotProfile, dticks: np.ndarray) -> np.ndarray:
    """Encoder count deltas (profile wheel order) -> metres each wheel rolled with the profile's radius."""
    d = np.asarray(dticks, dtype=float)
    if d.shape[-1] != profile.wheel_count:
        raise CalibrationError(f"expected {profile.wheel_count} encoder counts, got {d.shape[-1]}")
    return d * (2.0 * math.pi * profile.wheel_radius / profile.ticks_per_rev)


def encoder_motion(
    profile: RobotProfile, dticks: np.ndarray, wheel_radius: float | None = None
) -> tuple[float, float]:
    """(distance, yaw) the encoders claim for a run (``wheel_radius`` overrides the profile's).

    Skid/diff: virtual wheels (source A), ``d = (d_l + d_r)/2``, ``phi = (d_r - d_l)/track``.
    Omni: least-squares forward kinematics, ``d = |(dx, dy)|``, ``phi = sum / (4 R)``."""
    travel = wheel_travel(profile, dticks)
    if wheel_radius is not None:
        travel = travel * (wheel_radius / profile.wheel_radius)
    if profile.is_omni:
        dx, dy, dth = omni_forward(travel, profile.omni_radius)
        return float(math.hypot(float(dx), float(dy))), float(dth)
    dl, dr = virtual_wheels(travel)
    return (float(dl) + float(dr)) / 2.0, (float(dr) - float(dl)) / profile.track_width


def corrected_wheel_radius(
    profile: RobotProfile,
    dticks: np.ndarray,
    measured_distance: float,
    options: CalibrationOptions | None = None,
) -> float:
    """``r * d_measured / d_encoders`` for a straight run of ``dticks`` counts."""
    o = options or CalibrationOptions()
    if not (math.isfinite(measured_distance) and measured_distance >= o.min_distance):
        raise CalibrationError(
            f"measured distance {measured_distance!r} m: drive at least {o.min_distance} m straight"
        )
    d_enc, phi = encoder_motion(profile, dticks)
    if d_enc < 0.5 * o.min_distance:
        raise CalibrationError(f"the encoders counted only {d_enc:.3f} m: did the wheels turn?")
    if abs(phi) > o.max_heading_drift:
        raise CalibrationError(
            f"the encoders saw the heading change by {math.degrees(phi):.0f} deg: the run was not straight"
        )
    r_new = profile.wheel_radius * measured_distance / d_enc
    _check_ratio("wheel_radius", profile.wheel_radius, r_new, o)
    return r_new


def corrected_turn_geometry(
    profile: RobotProfile,
    dticks: np.ndarray,
    measured_angle: float,
    wheel_radius: float | None = None,
    options: CalibrationOptions | None = None,
) -> tuple[str, float]:
    """Effective ``track_width`` (skid/diff) or ``omni_radius`` (omni) from an in-place turn.

    ``measured_angle`` is the true yaw change in radians (signed like the turn: CCW positive);
    ``wheel_radius`` the corrected radius from the straight run. Returns (field name, new value)."""
    o = options or CalibrationOptions()
    if not (math.isfinite(measured_angle) and abs(measured_angle) >= o.min_angle):
        raise CalibrationError(
            f"measured angle {measured_angle!r} rad: turn at least {o.min_angle / (2 * math.pi):.2g} turns"
        )
    _, phi_enc = encoder_motion(profile, dticks, wheel_radius)
    if phi_enc * measured_angle <= 0:
        raise CalibrationError(
            "the encoders turned the other way than the measured angle (wheel order or sign wrong?)"
        )
    name, old = (
        ("omni_radius", profile.omni_radius) if profile.is_omni else ("track_width", profile.track_width)
    )
    new = old * phi_enc / measured_angle
    _check_ratio(name, old, new, o)
    return name, new


def calibrate(
    profile: RobotProfile,
    straight_dticks: np.ndarray,
    measured_distance: float,
    turn_dticks: np.ndarray,
    measured_angle: float | None,
    gyro_angle: float | None = None,
    options: CalibrationOptions | None = None,
) -> CalibrationResult:
    """Both corrections at once. ``measured_angle`` None: take the gyro's angle as the truth."""
    o = options or CalibrationOptions()
    r_new = corrected_wheel_radius(profile, straight_dticks, measured_distance, o)
    warnings: list[str] = []
    if measured_angle is None:
        if gyro_angle is None:
            raise CalibrationError("no measured angle and no gyro: count the turns")
        measured_angle = gyro_angle
    elif gyro_angle is not None and abs(gyro_angle - measured_angle) > o.gyro_tolerance * abs(measured_angle):
        turns_gyro, turns_measured = gyro_angle / (2 * math.pi), measured_angle / (2 * math.pi)
        warnings.append(
            f"the gyro measured {turns_gyro:.3f} turns, you {turns_measured:.3f}:"
            " recount the turns, or check the IMU's scale"
        )
    name, new = corrected_turn_geometry(profile, turn_dticks, measured_angle, r_new, o)
    d_enc, _ = encoder_motion(profile, straight_dticks)
    _, phi_enc = encoder_motion(profile, turn_dticks)
    old = profile.omni_radius if profile.is_omni else profile.track_width
    return CalibrationResult(
        profile.wheel_radius,
        r_new,
        name,
        old,
        new,
        d_enc,
        measured_distance,
        phi_enc,
        measured_angle,
        gyro_angle,
        tuple(warnings),
    )


def _check_ratio(name: str, old: float, new: float, o: CalibrationOptions) -> None:
    ratio = new / old
    if not (1.0 / o.max_ratio <= ratio <= o.max_ratio):
        raise CalibrationError(
            f"{name} would change from {old:.4g} to {new:.4g} (x{ratio:.2f}): check the measurement"
        )


_TABLE = re.compile(r"^\s*\[")


def update_profile_toml(text: str, values: dict[str, float | str], digits: int = 5) -> str:
    """Set top-level ``key = value`` lines of a profile TOML, keeping every other line and the
    comments (a key that is missing is added before the first table). Numbers are rounded to
    ``digits`` significant digits: 0.1 mm on a 65 mm wheel is finer than any tape measure; strings
    (``name``) are written as TOML basic strings."""
    lines = text.splitlines(keepends=True)
    first_table = next((i for i, line in enumerate(lines) if _TABLE.match(line)), len(lines))
    pending = dict(values)
    for i in range(first_table):
        for key in list(pending):
            m = re.match(rf"^(\s*{re.escape(key)}\s*=\s*)([^#\n]*?)(\s*(#.*)?)(\r?\n)?$", lines[i])
            if m:
                value, rest = _fmt(pending.pop(key), digits), m.group(3)
                if m.group(4):  # keep the comment in its column when the new value fits
                    pad = max(1, len(m.group(2)) + len(rest) - len(rest.lstrip()) - len(value))
                    rest = " " * pad + rest.lstrip()
                lines[i] = f"{m.group(1)}{value}{rest}{m.group(5) or ''}"
    if pending:
        insert = [f"{k} = {_fmt(v, digits)}  # calibrated\n" for k, v in pending.items()]
        at = first_table
        while at > 0 and not lines[at - 1].strip():  # keep the blank line before the first table
            at -= 1
        if at > 0 and not lines[at - 1].endswith("\n"):
            lines[at - 1] += "\n"
        lines[at:at] = insert
    return "".join(lines)


def _fmt(value: float | str, digits: int) -> str:
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string with only \" \\ \uXXXX escapes is a TOML basic string
    return f"{float(f'{value:.{digits}g}')!r}"


def profile_name_for(path: Path) -> str:
    """The ``name`` of a profile written to ``path``: its file stem (``wheelie-cal.toml`` ->
    ``wheelie-cal``), so a calibrated copy is told apart from the stock profile it came from."""
    return path.stem or "calibrated"
