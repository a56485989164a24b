"""``read_log``: one entry point for every supported log format.

Each record pairs a laser scan with the odometry pose (odom -> base_link) interpolated at the scan's
stamp, the way a SLAM front end would see it live. Formats:

- ``rosbag``: ROS1 bags, ROS 2 bags (folders, single ``.db3`` or ``.mcap`` files, with or without
  embedded message definitions) through the ``rosbags`` package: the only sensor_msgs/LaserScan
  topic, nav_msgs/Odometry or else tf odom -> base_link, the laser mount from the tf tree
  (:mod:`robot.logs.rosbag`, :mod:`robot.logs.frames`).
- ``carmen``: CARMEN text logs (``FLASER``, ``ROBOTLASER1``, ``ODOM`` lines; Montemerlo et al. 2003).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from nav.slam.time_offset import interpolate_poses
from nav.types import LaserScan, Pose2D
from robot.logs.carmen import read_carmen
from robot.logs.errors import LogError
from robot.logs.rosbag import BagExtras, read_rosbag
from robot.logs.stamp import Stamp

LogFormat = Literal["auto", "rosbag", "carmen"]


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
    notes: tuple[str, ...] = ()  # what the reader chose (topics, typestore, laser mount), to print
    extras: BagExtras | None = None  # twists, commands, log events (``extras=True``, bags only)

    def records(self, lag: float = 0.0) -> list[LogRecord]:
        """Records in stamp order, odometry interpolated at ``t_scan - lag``."""
        t_scan = np.array([float(s) for s in self.stamps])
        order = np.argsort(t_scan, kind="stable")
        pose = interpolate_poses(t_scan[order] - lag, self.t_odom, self.odom)
        return list(_records([self.stamps[i] for i in order], [self.scans[i] for i in order], pose))


def load_raw_log(
    path: str | Path,
    fmt: LogFormat = "auto",
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int = 0,
    *,
    extras: bool = False,
) -> RawLog:
    """Read a log without pairing scans and odometry yet (see :func:`load_log`). Topics left None
    are found in the bag (see :func:`robot.logs.rosbag.choose_topics`)."""
    p = Path(path)
    if not p.exists():
        raise LogError(f"no such log: {p}")
    kind = detect_format(p) if fmt == "auto" else fmt
    notes: list[str] = []
    more = None
    if kind == "rosbag":
        bag = read_rosbag(p, scan_topic, odom_topic, max_scans, extras=extras)
        stamps, scans, t_odom, odom, laser, notes, more = (
            bag.stamps,
            bag.scans,
            bag.t_odom,
            bag.odom,
            bag.laser,
            bag.notes,
            bag.extras,
        )
    elif kind == "carmen":
        stamps, scans, t_odom, odom, laser = read_carmen(p)
        if max_scans:
            stamps, scans = stamps[:max_scans], scans[:max_scans]
    else:
        raise LogError(f"unknown log format {fmt!r}")
    if not scans:
        raise LogError(f"{p.name}: no usable laser scans ({'; '.join(notes) or 'no scan lines'})")
    if len(t_odom) == 0:
        raise LogError(
            f"{p.name}: no odometry samples ({'; '.join(n for n in notes if n.startswith('odometry'))}); "
            "pass --odom-topic"
        )
    odom_arr = np.asarray(odom, float).reshape(-1, 3)
    return RawLog(stamps, scans, np.asarray(t_odom, float), odom_arr, laser, tuple(notes), more)


def load_log(
    path: str | Path,
    fmt: LogFormat = "auto",
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int = 0,
) -> tuple[list[LogRecord], Pose2D]:
    """Read a log: its records (in stamp order) and the laser pose in base_link. ``max_scans > 0``
    keeps only the first scans (bags stop reading early)."""
    raw = load_raw_log(path, fmt, scan_topic, odom_topic, max_scans)
    return raw.records(), raw.laser


def read_log(
    path: str | Path, fmt: LogFormat = "auto", scan_topic: str | None = None, odom_topic: str | None = None
) -> Iterator[LogRecord]:
    """Iterate ``(stamp, LaserScan, odom Pose2D)`` over a log. Raises :class:`LogError` when the log
    has no usable scans or no odometry."""
    recs, _ = load_log(path, fmt, scan_topic, odom_topic)
    return iter(recs)


def count_scans(path: str | Path, fmt: LogFormat = "auto", scan_topic: str | None = None) -> int:
    """Number of usable scans (reads the log)."""
    recs, _ = load_log(path, fmt, scan_topic)
    return len(recs)
