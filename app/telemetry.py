"""Snapshot -> JSON for the telemetry websocket and ``GET /api/robot``."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any

import numpy as np

from app.api.schemas import public_navigation
from app.bus import Snapshot
from nav.types import Pose2D, Twist2D


def pose_dict(p: Pose2D) -> dict[str, float]:
    return {"x": round(p.x, 4), "y": round(p.y, 4), "theta": round(p.theta, 4)}


def twist_dict(t: Twist2D) -> dict[str, Any]:
    """geometry_msgs/Twist shape."""
    return {
        "linear": {"x": round(t.vx, 4), "y": round(t.vy, 4), "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": round(t.wz, 4)},
    }


def downsample_scan(snap: Snapshot, max_beams: int = 180) -> dict[str, Any] | None:
    """Every k-th beam, ranges in cm precision; ``null`` where there is no return."""
    scan = snap.scan
    if scan is None:
        return None
    step = max(1, math.ceil(scan.ranges.shape[0] / max_beams))
    r = np.asarray(scan.ranges[::step], dtype=float)
    valid = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
    rounded = np.round(r, 2)
    return {
        "stamp_monotonic_s": round(scan.stamp, 3),
        "angle_min": round(scan.angle_min, 5),
        "angle_increment": round(scan.angle_increment * step, 6),
        "range_max": scan.range_max,
        "ranges": [float(v) if ok else None for v, ok in zip(rounded.tolist(), valid.tolist(), strict=True)],
    }


def snapshot_dict(
    snap: Snapshot, profile_name: str, *, include_scan: bool = True, allowed_modes: list[str] | None = None
) -> dict[str, Any]:
    out: dict[str, Any] = {
        "time": datetime.now(UTC).isoformat().replace("+00:00", "Z"),
        "stamp_monotonic_s": round(snap.stamp, 3),
        "seq": snap.seq,
        "mode": snap.mode,
        "allowed_modes": allowed_modes or [],
        "pose": pose_dict(snap.pose),
        "odom_pose": pose_dict(snap.odom_pose),
        "velocity": twist_dict(snap.velocity),
        "command": twist_dict(snap.command),
        "clamped": list(snap.clamped),
        "estop": snap.estop,
        "fault": snap.fault,
        "behavior": snap.behavior,
        "profile_name": profile_name,
        "health": snap.health,
        "goal": pose_dict(snap.goal) if snap.goal is not None else None,
    }
    for key in ("navigation", "localization", "mapping", "exploration", "contact", "zones"):
        if key in snap.extras:
            out[key] = snap.extras[key]
    if "navigation" in out:
        out["navigation"] = public_navigation(out["navigation"])
    if include_scan:
        out["scan"] = downsample_scan(snap)
    return out
