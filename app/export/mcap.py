"""A run as an MCAP file with ROS 2 (CDR) messages that Foxglove and ``ros2 bag`` open.

Topics and frames follow REP-103/105: ``/tf`` carries map -> odom -> base_link at every sample,
``/tf_static`` base_link -> laser once; ``/odom`` (nav_msgs/Odometry, odom -> base_link, body-frame
twist), ``/cmd_vel`` (geometry_msgs/Twist), ``/scan`` (sensor_msgs/LaserScan, laser frame, +inf = no
return per REP-117), ``/plan`` (nav_msgs/Path, map), ``/goal_pose`` (geometry_msgs/PoseStamped),
``/map`` (nav_msgs/OccupancyGrid, map) and events on ``/rosout`` (rcl_interfaces/Log). Stamps are the
recording's wall time. The schemas are the ROS 2 message definitions (``app.export.msgdefs``).
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
from mcap_ros2.writer import Writer

from app.export.data import RunData
from app.export.msgdefs import msgdef
from nav.types import Pose2D

TOPICS: dict[str, str] = {
    "/tf": "tf2_msgs/TFMessage",
    "/tf_static": "tf2_msgs/TFMessage",
    "/odom": "nav_msgs/Odometry",
    "/cmd_vel": "geometry_msgs/Twist",
    "/scan": "sensor_msgs/LaserScan",
    "/plan": "nav_msgs/Path",
    "/goal_pose": "geometry_msgs/PoseStamped",
    "/map": "nav_msgs/OccupancyGrid",
    "/rosout": "rcl_interfaces/Log",
}

LOG_INFO, LOG_WARN, LOG_ERROR = 20, 30, 40
EVENT_LEVEL = {"fault": LOG_ERROR, "collision": LOG_ERROR, "estop": LOG_WARN, "plan_failed": LOG_WARN}


def _time(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(ns: int, frame: str) -> dict:
    return {"stamp": _time(ns), "frame_id": frame}


def _quat(theta: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(theta / 2.0), "w": math.cos(theta / 2.0)}


def _pose(x: float, y: float, theta: float) -> dict:
    return {"position": {"x": x, "y": y, "z": 0.0}, "orientation": _quat(theta)}


def _tf(ns: int, parent: str, child: str, p: Pose2D) -> dict:
    return {
        "header": _header(ns, parent),
        "child_frame_id": child,
        "transform": {"translation": {"x": p.x, "y": p.y, "z": 0.0}, "rotation": _quat(p.theta)},
    }


def _vec(x: float, y: float, z: float) -> dict:
    return {"x": x, "y": y, "z": z}


def write_mcap(data: RunData, out: io.BufferedIOBase | io.BytesIO) -> dict[str, int]:
    """Write the run to ``out``; returns the message count per topic."""
    counts = dict.fromkeys(TOPICS, 0)
    writer = Writer(out)
    schemas = {name: writer.register_msgdef(name, msgdef(name)) for name in set(TOPICS.values())}

    def put(topic: str, ns: int, msg: dict) -> None:
        writer.write_message(topic, schemas[TOPICS[topic]], msg, log_time=ns, publish_time=ns)
        counts[topic] += 1

    run = data.run
    meta = {k: str(run.get(k)) for k in ("id", "kind", "robot", "profile", "map_id", "outcome", "started_at")}
    # a run exported while it records: readers see it is partial and up to which run time
    meta["partial"] = str(data.partial).lower()
    meta["recorded_s"] = f"{float(data.samples['t'][-1]) if data.samples.size else 0.0:.3f}"
    writer.add_metadata("navdeck_run", meta)
    t0 = data.stamp_ns(0.0)
    lx, ly, lyaw = data.laser_pose
    put("/tf_static", t0, {"transforms": [_tf(t0, "base_link", "laser", Pose2D(lx, ly, lyaw))]})
    for t, _version, grid in data.grids:
        ns = data.stamp_ns(t)
        g = grid.geometry
        info = {
            "map_load_time": _time(ns),
            "resolution": g.resolution,
            "width": g.width,
            "height": g.height,
            "origin": _pose(g.origin.x, g.origin.y, g.origin.theta),
        }
        put("/map", ns, {"header": _header(ns, "map"), "info": info, "data": grid.data.ravel().tolist()})
    zero_cov = [0.0] * 36
    s = data.samples
    for row in s:
        ns = data.stamp_ns(float(row["t"]))
        odom = Pose2D(float(row["ox"]), float(row["oy"]), float(row["otheta"]))
        base = Pose2D(float(row["x"]), float(row["y"]), float(row["theta"]))
        map_to_odom = base.compose(odom.inverse())
        put(
            "/tf",
            ns,
            {"transforms": [_tf(ns, "map", "odom", map_to_odom), _tf(ns, "odom", "base_link", odom)]},
        )
        twist = {
            "linear": _vec(float(row["vx"]), float(row["vy"]), 0.0),
            "angular": _vec(0.0, 0.0, float(row["wz"])),
        }
        put(
            "/odom",
            ns,
            {
                "header": _header(ns, "odom"),
                "child_frame_id": "base_link",
                "pose": {"pose": _pose(odom.x, odom.y, odom.theta), "covariance": zero_cov},
                "twist": {"twist": twist, "covariance": zero_cov},
            },
        )
        cmd = {
            "linear": _vec(float(row["cmd_vx"]), float(row["cmd_vy"]), 0.0),
            "angular": _vec(0.0, 0.0, float(row["cmd_wz"])),
        }
        put("/cmd_vel", ns, cmd)
    for t, scan in data.scans:
        ns = data.stamp_ns(t)
        n = scan.ranges.shape[0]
        put(
            "/scan",
            ns,
            {
                "header": _header(ns, "laser"),
                "angle_min": scan.angle_min,
                "angle_max": scan.angle_min + scan.angle_increment * max(n - 1, 0),
                "angle_increment": scan.angle_increment,
                "time_increment": 0.0,
                "scan_time": 0.0,
                "range_min": scan.range_min,
                "range_max": scan.range_max,
                "ranges": np.asarray(scan.ranges, dtype=np.float32).tolist(),
                "intensities": [],
            },
        )
    for t, poses in data.plans:
        ns = data.stamp_ns(t)
        stamped = [{"header": _header(ns, "map"), "pose": _pose(*map(float, p))} for p in poses]
        put("/plan", ns, {"header": _header(ns, "map"), "poses": stamped})
    for g in data.goals:
        ns = data.stamp_ns(float(g["t"]))
        put("/goal_pose", ns, {"header": _header(ns, "map"), "pose": _pose(g["x"], g["y"], g["theta"])})
    for ev in data.events:
        ns = data.stamp_ns(float(ev["t"]))
        payload = {k: v for k, v in ev.items() if k not in ("t", "type")}
        put(
            "/rosout",
            ns,
            {
                "stamp": _time(ns),
                "level": EVENT_LEVEL.get(ev["type"], LOG_INFO),
                "name": "navdeck",
                "msg": f"{ev['type']}: {json.dumps(payload, default=str)}",
                "file": "",
                "function": ev["type"],
                "line": 0,
            },
        )
    writer.finish()
    return counts


def mcap_bytes(data: RunData) -> bytes:
    buf = io.BytesIO()
    write_mcap(data, buf)
    return buf.getvalue()
