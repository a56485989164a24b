"""ROS1 bag / ROS2 bag / MCAP reading through the pure-Python ``rosbags`` package."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nav.types import LaserScan, Pose2D
from robot.logs.stamp import Stamp


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def scan_from_msg(msg, stamp: Stamp) -> LaserScan:
    """sensor_msgs/LaserScan -> LaserScan; readings at or beyond range_max become +inf (REP-117)."""
    r = np.asarray(msg.ranges, dtype=float).copy()
    r[~(r < msg.range_max)] = np.inf
    return LaserScan(
        stamp=float(stamp),
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        ranges=r,
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        frame_id=str(msg.header.frame_id) or "laser",
    )


def read_rosbag(
    path: Path, scan_topic: str, odom_topic: str, max_scans: int = 0
) -> tuple[list[Stamp], list[LaserScan], list[float], list[tuple[float, float, float]], Pose2D]:
    """Scans, odometry samples (from ``odom_topic`` or tf odom->base_link) and the static laser pose.
    With ``max_scans > 0`` reading stops once that many scans and one later odometry sample are in."""
    from rosbags.highlevel import AnyReader

    from robot.logs.reader import LogError

    stamps: list[Stamp] = []
    scans: list[LaserScan] = []
    t_odom: list[float] = []
    odom: list[tuple[float, float, float]] = []
    t_tf: list[float] = []
    tf_odom: list[tuple[float, float, float]] = []
    laser = Pose2D()
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types
        raise LogError(f"{path.name}: not a readable bag ({exc})") from exc
    try:
        topics = {c.topic for c in reader.connections}
        # tf is only needed for odometry when there is no odometry topic
        wanted = {scan_topic, odom_topic, "/tf_static"} | ({"/tf"} if odom_topic not in topics else set())
        conns = [c for c in reader.connections if c.topic in wanted]
        for con, _t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, con.msgtype)
            if max_scans and len(scans) >= max_scans and t_odom and t_odom[-1] > float(stamps[-1]):
                break
            if con.topic == scan_topic and con.msgtype.endswith("LaserScan"):
                if max_scans and len(scans) >= max_scans:
                    continue
                st = Stamp.from_ros(msg.header.stamp.sec, msg.header.stamp.nanosec)
                stamps.append(st)
                scans.append(scan_from_msg(msg, st))
            elif con.topic == odom_topic and con.msgtype.endswith("Odometry"):
                p = msg.pose.pose
                t_odom.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
                odom.append((p.position.x, p.position.y, _yaw(p.orientation)))
            elif con.topic in ("/tf", "/tf_static") and con.msgtype.endswith("TFMessage"):
                for tr in msg.transforms:
                    parent = tr.header.frame_id.lstrip("/")
                    child = tr.child_frame_id.lstrip("/")
                    q, v = tr.transform.rotation, tr.transform.translation
                    if parent == "odom" and child in ("base_link", "base_footprint"):
                        t_tf.append(tr.header.stamp.sec + tr.header.stamp.nanosec * 1e-9)
                        tf_odom.append((v.x, v.y, _yaw(q)))
                    elif parent in ("base_link", "base_footprint") and child in (
                        "laser",
                        "base_laser_link",
                        "base_scan",
                        "laser_link",
                    ):
                        laser = Pose2D(v.x, v.y, _yaw(q))
    finally:
        reader.close()
    if not t_odom:
        t_odom, odom = t_tf, tf_odom
    return stamps, scans, t_odom, odom, laser
