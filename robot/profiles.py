"""Robot profiles: kinematics, footprint, limits and sensors of one robot, from a TOML file.

Stock profiles live in ``robot/profiles/*.toml`` and are looked up by name; a user passes a path to
their own file. Every field is documented in ``docs/profiles.md``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Literal

import numpy as np

PROFILE_DIR = Path(__file__).parent / "profiles"

Kinematics = Literal["skid", "diff", "omni"]


class ProfileError(ValueError):
    """A profile could not be found or is invalid; the message names the field."""


@dataclass(frozen=True)
class Limits:
    """Velocity and acceleration limits (SI units). ``min_*`` are the smallest non-zero speeds the
    motors can hold (below them the base stalls)."""

    max_vel_x: float = 0.5
    min_vel_x: float = -0.25
    max_vel_y: float = 0.0
    max_vel_theta: float = 2.0
    min_speed_xy: float = 0.0
    min_speed_theta: float = 0.0
    acc_lim_x: float = 1.0
    acc_lim_y: float = 0.0
    acc_lim_theta: float = 3.0
    decel_lim_x: float = -1.0
    decel_lim_y: float = 0.0
    decel_lim_theta: float = -3.0


@dataclass(frozen=True)
class LidarSpec:
    beams: int = 360
    fov: float = 2 * math.pi  # radians
    angle_min: float = -math.pi
    range_min: float = 0.15
    range_max: float = 6.0
    rate_hz: float = 5.5
    mount_x: float = 0.0
    mount_y: float = 0.0
    mount_z: float = 0.15
    mount_yaw: float = 0.0
    range_noise_std: float = 0.01  # metres, Gaussian
    dropout_prob: float = 0.01  # probability a beam returns nothing

    @property
    def angle_increment(self) -> float:
        # A full circle has no duplicated end beam; a partial fan includes both ends.
        if abs(self.fov - 2 * math.pi) < 1e-9:
            return self.fov / self.beams
        return self.fov / max(self.beams - 1, 1)


@dataclass(frozen=True)
class IrSensor:
    x: float
    y: float
    yaw: float = 0.0
    range: float = 0.30
    fov: float = math.radians(15)


@dataclass(frozen=True)
class ImuSpec:
    gyro_noise_std: float = 0.002  # rad/s
    gyro_bias: float = 0.001  # rad/s, initial bias of the simulated gyro
    rate_hz: float = 200.0


@dataclass(frozen=True)
class RobotProfile:
    name: str
    kinematics: Kinematics = "skid"
    wheel_radius: float = 0.0325
    track_width: float = 0.17  # metres between left and right wheel centres (diff/skid)
    wheel_base: float = 0.15  # metres between front and rear axles (skid)
    omni_radius: float = 0.25  # centre to wheel contact (omni)
    ticks_per_rev: int = 1320
    footprint: tuple[tuple[float, float], ...] = ()
    robot_radius: float = 0.0  # used when no polygon footprint is given
    limits: Limits = field(default_factory=Limits)
    lidar: LidarSpec = field(default_factory=LidarSpec)
    ir: tuple[IrSensor, ...] = ()
    imu: ImuSpec = field(default_factory=ImuSpec)
    controller: str = "dwa"
    battery_full_v: float = 12.6
    battery_empty_v: float = 10.5
    mass: float = 2.0
    source: str = ""  # file the profile was read from

    @property
    def is_omni(self) -> bool:
        return self.kinematics == "omni"

    @property
    def wheel_count(self) -> int:
        return 4 if self.kinematics in ("skid", "omni") else 2

    def footprint_polygon(self, segments: int = 16) -> np.ndarray:
        """The footprint as an (N, 2) polygon in base_link (a circle is approximated)."""
        if self.footprint:
            return np.asarray(self.footprint, dtype=float)
        a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
        return np.column_stack((np.cos(a), np.sin(a))) * self.robot_radius

    @property
    def inscribed_radius(self) -> float:
        """Largest circle about base_link inside the footprint."""
        if not self.footprint:
            return self.robot_radius
        p = self.footprint_polygon()
        q = np.roll(p, -1, axis=0)
        edge = q - p
        # distance from the origin to each edge's line
        cross = np.abs(p[:, 0] * edge[:, 1] - p[:, 1] * edge[:, 0])
        return float(np.min(cross / np.hypot(edge[:, 0], edge[:, 1])))

    @property
    def circumscribed_radius(self) -> float:
        if not self.footprint:
            return self.robot_radius
        return float(np.max(np.hypot(*self.footprint_polygon().T)))


def _build(cls: type, data: dict[str, Any], where: str) -> Any:
    known = {f.name for f in fields(cls)}
    unknown = set(data) - known
    if unknown:
        raise ProfileError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
    return cls(**data)


def _positive(value: float, name: str) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ProfileError(f"profile field {name} must be a positive number, got {value!r}")


def profile_from_dict(data: dict[str, Any], source: str = "") -> RobotProfile:
    """Build and validate a profile from parsed TOML."""
    data = dict(data)
    try:
        limits = _build(Limits, data.pop("limits", {}), "limits")
        lidar_raw = dict(data.pop("lidar", {}))
        for key in ("fov", "angle_min", "mount_yaw"):
            if key + "_deg" in lidar_raw:
                lidar_raw[key] = math.radians(lidar_raw.pop(key + "_deg"))
        lidar = _build(LidarSpec, lidar_raw, "lidar")
        imu = _build(ImuSpec, data.pop("imu", {}), "imu")
        ir_list = []
        for i, raw in enumerate(data.pop("ir", [])):
            raw = dict(raw)
            if "yaw_deg" in raw:
                raw["yaw"] = math.radians(raw.pop("yaw_deg"))
            ir_list.append(_build(IrSensor, raw, f"ir[{i}]"))
        if "footprint" in data:
            data["footprint"] = tuple((float(p[0]), float(p[1])) for p in data["footprint"])
        profile = _build(
            RobotProfile,
            {**data, "limits": limits, "lidar": lidar, "imu": imu, "ir": tuple(ir_list), "source": source},
            "profile",
        )
    except TypeError as exc:  # missing required field such as name
        raise ProfileError(f"profile {source or '?'}: {exc}") from exc
    if profile.kinematics not in ("skid", "diff", "omni"):
        raise ProfileError(f"profile field kinematics must be skid, diff or omni, got {profile.kinematics!r}")
    for name in ("wheel_radius", "track_width", "ticks_per_rev"):
        _positive(getattr(profile, name), name)
    _positive(profile.limits.max_vel_x, "limits.max_vel_x")
    _positive(profile.limits.max_vel_theta, "limits.max_vel_theta")
    _positive(profile.lidar.range_max, "lidar.range_max")
    _positive(profile.lidar.rate_hz, "lidar.rate_hz")
    if profile.lidar.beams < 3:
        raise ProfileError("profile field lidar.beams must be at least 3")
    if not profile.footprint and profile.robot_radius <= 0:
        raise ProfileError("profile needs a footprint polygon or a positive robot_radius")
    if profile.footprint and len(profile.footprint) < 3:
        raise ProfileError("profile field footprint needs at least 3 points")
    return profile


def available_profiles() -> list[str]:
    return sorted(p.stem for p in PROFILE_DIR.glob("*.toml"))


def load_profile(name_or_path: str | Path) -> RobotProfile:
    """Load a stock profile by name (``skid4``) or a user's profile by path."""
    path = Path(name_or_path)
    if not path.suffix and not path.exists():
        path = PROFILE_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        raise ProfileError(
            f"unknown profile {str(name_or_path)!r}: "
            f"not a file and not one of {', '.join(available_profiles())}"
        )
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"profile {path}: not valid TOML: {exc}") from exc
    data.setdefault("name", path.stem)
    return profile_from_dict(data, source=str(path))
