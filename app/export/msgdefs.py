"""ROS 2 message definitions (Humble ``.msg`` text) for the MCAP export's schemas.

MCAP's ``ros2msg`` schema encoding is the main definition followed by every type it uses, each after
a line of 80 ``=`` and ``MSG: pkg/Type`` (what ``ros2 bag record`` writes). Types are spelled with
their package everywhere so no reader has to apply the same-package shorthand rule.
"""

from __future__ import annotations

import re

DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\ngeometry_msgs/Pose pose",
    "geometry_msgs/PoseWithCovariance": "geometry_msgs/Pose pose\nfloat64[36] covariance",
    "geometry_msgs/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular",
    "geometry_msgs/TwistWithCovariance": "geometry_msgs/Twist twist\nfloat64[36] covariance",
    "geometry_msgs/Transform": "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist"
    ),
    "nav_msgs/Path": "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses",
    "nav_msgs/MapMetaData": (
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\n"
        "geometry_msgs/Pose origin"
    ),
    "nav_msgs/OccupancyGrid": "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data",
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities"
    ),
    "rcl_interfaces/Log": (
        "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n"
        "builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n"
        "string function\nuint32 line"
    ),
}

SEPARATOR = "=" * 80
_TYPE = re.compile(r"^([a-z0-9_]+/[A-Za-z0-9_]+)(\[\d*\])?\s", re.MULTILINE)


def dependencies(name: str) -> list[str]:
    """Types ``name`` uses, depth-first in first-use order, without duplicates."""
    seen: list[str] = []

    def visit(t: str) -> None:
        for m in _TYPE.finditer(DEFS[t]):
            dep = m.group(1)
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(name)
    return seen


def msgdef(name: str) -> str:
    """The full ``ros2msg`` schema text for ``name``."""
    parts = [DEFS[name]]
    for dep in dependencies(name):
        parts.append(f"{SEPARATOR}\nMSG: {dep}\n{DEFS[dep]}")
    return "\n".join(parts) + "\n"
