"""``read_log``: one entry point for every supported log format.

Each record pairs a laser scan with the odometry pose (odom -> base_link) interpolated at the scan's
stamp, the way a SLAM front end would see it live. Formats:

- ``rosbag``: ROS1 bags, ROS2 bag folders and MCAP files, through the ``rosbags`` package
  (sensor_msgs/LaserScan + nav_msgs/Odometry, or tf odom -> base_link when there is no odometry
  topic); the static laser pose comes from ``/tf_static`` (see :func:`laser_pose`).
- ``carmen``: CARMEN text logs (``FLASER``, ``ROBOTLASER1``, ``ODOM`` lines; Montemerlo et al. 2003).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from nav.types import LaserScan, Pose2D, wrap_angle
from robot.logs.stamp import Stamp

LogFormat = Literal["auto", "rosbag", "carmen"]


class LogError(ValueError):
    """A log that cannot be read or holds no usable scans."""


class LogRecord(NamedTuple):
    """One scan of a log: ``stamp`` is a :class:`Stamp` (``str(stamp)`` is the exact log text)."""

    stamp: Stamp
    scan: LaserScan
    odom: Pose2D


def detect_format(path: Path) -> Literal["rosbag", "carmen"]:
    """Guess the format from the file name / contents."""
    if path.is_dir() or path.suffix in (".bag", ".mcap", ".db3"):
        return "rosbag"
    with path.open("rb") as f:
        head = f.read(64)
    if head.startswith(b"#ROSBAG") or head.startswith(b"\x89MCAP"):
        return "rosbag"
    return "carmen"


def interpolate_poses(t_query: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Linearly interpolate (N, 3) poses (angles unwrapped first) at ``t_query``; held at the ends."""
    order = np.argsort(t, kind="stable")
    t, poses = t[order], poses[order]
    th = np.unwrap(poses[:, 2])
    out = np.column_stack(
        (np.interp(t_query, t, poses[:, 0]), np.interp(t_query, t, poses[:, 1]), np.interp(t_query, t, th))
    )
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _records(stamps: list[Stamp], scans: list[LaserScan], odom: np.ndarray) -> Iterator[LogRecord]:
    for s, scan, o in zip(stamps, scans, odom, strict=True):
        yield LogRecord(s, scan, Pose2D(float(o[0]), float(o[1]), float(o[2])))


def load_log(
    path: str | Path,
    fmt: LogFormat = "auto",
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    max_scans: int = 0,
) -> tuple[list[LogRecord], Pose2D]:
    """Read a log: its records (in stamp order) and the laser pose in base_link. ``max_scans > 0``
    keeps only the first scans (bags stop reading early)."""
    p = Path(path)
    if not p.exists():
        raise LogError(f"no such log: {p}")
    kind = detect_format(p) if fmt == "auto" else fmt
    if kind == "rosbag":
        from robot.logs.rosbag import read_rosbag

        stamps, scans, t_odom, odom, laser = read_rosbag(p, scan_topic, odom_topic, max_scans)
    elif kind == "carmen":
        from robot.logs.carmen import read_carmen

        stamps, scans, t_odom, odom, laser = read_carmen(p)
        if max_scans:
            stamps, scans = stamps[:max_scans], scans[:max_scans]
    else:
        raise LogError(f"unknown log format {fmt!r}")
    if not scans:
        raise LogError(f"{p.name}: no usable laser scans (scan topic {scan_topic!r})")
    if len(t_odom) == 0:
        raise LogError(f"{p.name}: no odometry (odom topic {odom_topic!r} nor tf odom->base_link)")
    t_scan = np.array([float(s) for s in stamps])
    order = np.argsort(t_scan, kind="stable")
    pose = interpolate_poses(t_scan[order], np.asarray(t_odom, float), np.asarray(odom, float))
    recs = list(_records([stamps[i] for i in order], [scans[i] for i in order], pose))
    return recs, laser


def read_log(
    path: str | Path, fmt: LogFormat = "auto", scan_topic: str = "/scan", odom_topic: str = "/odom"
) -> Iterator[LogRecord]:
    """Iterate ``(stamp, LaserScan, odom Pose2D)`` over a log. Raises :class:`LogError` when the log
    has no usable scans or no odometry."""
    recs, _ = load_log(path, fmt, scan_topic, odom_topic)
    return iter(recs)


def count_scans(path: str | Path, fmt: LogFormat = "auto", scan_topic: str = "/scan") -> int:
    """Number of usable scans (reads the log)."""
    recs, _ = load_log(path, fmt, scan_topic)
    return len(recs)
