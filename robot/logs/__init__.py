"""Readers for recorded robot logs (ROS1/ROS2 bags, MCAP, CARMEN) as (stamp, LaserScan, odom Pose2D)."""

from robot.logs.reader import LogError, LogRecord, Stamp, count_scans, read_log

__all__ = ["LogError", "LogRecord", "Stamp", "count_scans", "read_log"]
