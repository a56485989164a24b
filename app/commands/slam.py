"""``navdeck slam LOG --out DIR``: offline graph SLAM over a recorded log.

Writes ``DIR/map.pgm`` + ``DIR/map.yaml`` (map_server format) and ``DIR/trajectory.txt`` (one line
per scan, ``timestamp x y theta``, the timestamp exactly as written in the log; base_link poses, or
the laser's with ``--frame laser``), ready for ``navdeck slam-eval``. Progress (scans done / total,
rate, ETA) goes to stderr.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("slam", help="build a map and trajectory from a recorded log (ROS bag, MCAP, CARMEN)")
    p.add_argument("log", type=Path, help="ROS1 .bag, ROS2 bag folder, .mcap or CARMEN .log")
    p.add_argument("--format", choices=["auto", "rosbag", "carmen"], default="auto")
    p.add_argument(
        "--scan-topic",
        default=None,
        help="sensor_msgs/LaserScan topic (default: the bag's only LaserScan topic)",
    )
    p.add_argument(
        "--odom-topic",
        default=None,
        help="nav_msgs/Odometry topic (default: /odom or the only one, else /tf odom -> base_link)",
    )
    p.add_argument("--profile", help="robot profile: laser mount pose and max range (default: from the log)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument(
        "--frame",
        choices=["base_link", "laser"],
        default="base_link",
        help="frame of the poses in trajectory.txt: the robot (REP-105 base_link) or the laser, which "
        "is what the SLAM benchmark's relations describe",
    )
    p.add_argument("--limit", type=int, default=0, help="process only the first N scans (0 = all)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


class ProgressBar:
    """Plain-text progress on stderr: bar, done/total, rate and ETA; redrawn at most 5x a second."""

    def __init__(self, stream=None, width: int = 30) -> None:
        self.stream = stream if stream is not None else sys.stderr  # resolved now, not at import
        self.width = width
        self.start = time.monotonic()
        self.last = 0.0

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if done < total and now - self.last < 0.2:
            return
        self.last = now
        el = max(now - self.start, 1e-9)
        rate = done / el
        eta = (total - done) / rate if rate > 0 else 0.0
        fill = int(self.width * done / max(total, 1))
        bar = "#" * fill + "." * (self.width - fill)
        self.stream.write(
            f"\r[{bar}] {done}/{total} scans {rate:6.1f} scans/s ETA {int(eta // 60)}m{int(eta % 60):02d}s"
        )
        if done >= total:
            self.stream.write("\n")
        self.stream.flush()


def run(args: argparse.Namespace) -> int:
    from nav.slam.offline import run_offline
    from nav.slam.system import SlamError, SlamOptions
    from nav.types import Pose2D
    from robot.logs import LogError
    from robot.logs.reader import load_raw_log

    try:
        raw = load_raw_log(args.log, args.format, args.scan_topic, args.odom_topic, max(args.limit, 0))
    except LogError as exc:
        raise CliError(str(exc)) from None
    for note in raw.notes:  # what was found in the bag: topics, typestore, laser mount
        print(note, file=sys.stderr)
    records, laser = raw.records(), raw.laser
    options = SlamOptions()
    if args.profile:
        from robot.profiles import ProfileError, load_profile

        try:
            prof = load_profile(args.profile)
        except (ProfileError, FileNotFoundError, ValueError) as exc:
            raise CliError(f"profile {args.profile!r}: {exc}") from None
        lid = prof.lidar
        laser = Pose2D(lid.mount_x, lid.mount_y, lid.mount_yaw)
        options = SlamOptions(max_laser_range=min(options.max_laser_range, lid.range_max))
    t0 = time.process_time()
    try:
        slam = run_offline(
            records, laser, options, None if args.quiet else ProgressBar(), odometry=(raw.t_odom, raw.odom)
        )
    except SlamError as exc:
        raise CliError(str(exc)) from None
    cpu = time.process_time() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    from maps.mapio import save_map

    save_map(slam.map(), args.out, "map")
    traj = slam.trajectory(sensor=args.frame == "laser")
    lines = [
        f"{rec.stamp} {x:.6f} {y:.6f} {th:.6f}" for rec, (_t, x, y, th) in zip(records, traj, strict=True)
    ]
    (args.out / "trajectory.txt").write_text("\n".join(lines) + "\n")
    duration = float(records[-1].stamp) - float(records[0].stamp)
    print(
        f"{len(records)} scans, {slam.num_nodes} nodes, {slam.num_loop_closures} loop closures, "
        f"odometry lag {slam.odometry_lag * 1e3:.0f} ms, "
        f"{cpu:.1f} s CPU ({duration / max(cpu, 1e-9):.1f}x real time) -> {args.out}",
        file=sys.stderr,
    )
    return 0
