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

from nav.slam.time_offset import interpolate_poses
from nav.types import LaserScan, Pose2D
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


def _records(stamps: list[Stamp], scans: list[LaserScan], odom: np.ndarray) -> Iterator[LogRecord]:
    for s, scan, o in zip(stamps, scans, odom, strict=True):
        yield LogRecord(s, scan, Pose2D(float(o[0]), float(o[1]), float(o[2])))


class RawLog(NamedTuple):
    """A log as read: scans with their stamps, the raw odometry samples and the laser pose."""

    stamps: list[Stamp]
    scans: list[LaserScan]
    t_odom: np.ndarray  # (M,) seconds
    odom: np.ndarray  # (M, 3) odom -> base_link poses
    laser: Pose2D

    def records(self, lag: float = 0.0) -> list[LogRecord]:
        """Records in stamp order, odometry interpolated at ``t_scan - lag``."""
        t_scan = np.array([float(s) for s in self.stamps])
        order = np.argsort(t_scan, kind="stable")
        pose = interpolate_poses(t_scan[order] - lag, self.t_odom, self.odom)
        return list(_records([self.stamps[i] for i in order], [self.scans[i] for i in order], pose))


def load_raw_log(
    path: str | Path,
    fmt: LogFormat = "auto",
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    max_scans: int = 0,
) -> RawLog:
    """Read a log without pairing scans and odometry yet (see :func:`load_log`)."""
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
    return RawLog(stamps, scans, np.asarray(t_odom, float), np.asarray(odom, float).reshape(-1, 3), laser)


def load_log(
    path: str | Path,
    fmt: LogFormat = "auto",
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    max_scans: int = 0,
) -> tuple[list[LogRecord], Pose2D]:
    """Read a log: its records (in stamp order) and the laser pose in base_link. ``max_scans > 0``
    keeps only the first scans (bags stop reading early)."""
    raw = load_raw_log(path, fmt, scan_topic, odom_topic, max_scans)
    return raw.records(), raw.laser


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
