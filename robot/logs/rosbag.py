"""ROS1 bags, ROS 2 bags (directories or single ``.db3`` / ``.mcap`` files) through ``rosbags``.

Bags written before rosbag2 stored message definitions (Foxy, Galactic, Humble with sqlite3) carry
none: they are read with the stock typestore of the bag's ``ros_distro`` (``metadata.yaml``, or the
``.db3``'s schema table), else Humble, then Foxy, and the notes say which. Topics and frames are
found by themselves (:func:`choose_topics`, :mod:`robot.logs.frames`); what was chosen goes into
``BagRead.notes`` for the caller to print. Compression (ROS1 bz2/lz4 chunks, rosbag2 zstd file or
message mode, MCAP chunks) is handled by ``rosbags``.
"""

from __future__ import annotations

import math
import sqlite3
from collections.abc import Iterator
from contextlib import closing, contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader as Reader2
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from nav.types import GridGeometry, LaserScan, OccupancyGrid, Pose2D
from robot.logs.errors import LogError
from robot.logs.frames import BASE_FRAMES, LaserMount, TfTree, upright
from robot.logs.stamp import Stamp

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
MAP_TYPE = "nav_msgs/msg/OccupancyGrid"
TWIST_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
LOG_TYPES = ("rcl_interfaces/msg/Log", "rosgraph_msgs/msg/Log")
FALLBACK_DISTROS = ("humble", "foxy")
"""Typestores tried, in order, for a bag without definitions and without a ``ros_distro``."""


@dataclass
class BagExtras:
    """What a run import keeps beside scans and odometry (seconds on the bag's clock)."""

    t_twist: list[float] = field(default_factory=list)  # odometry twist (body frame)
    twist: list[tuple[float, float, float]] = field(default_factory=list)  # vx, vy, wz
    t_cmd: list[float] = field(default_factory=list)
    cmd: list[tuple[float, float, float]] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)  # {"t", "type": "log", "level", "name", "msg"}
    map_topic: str = ""  # the recorded map's topic (``/map``, or the only OccupancyGrid topic)
    grid: OccupancyGrid | None = None  # the last map recorded on it
    t_grid: float = 0.0
    t_map_odom: list[float] = field(default_factory=list)  # /tf map -> odom (the localization)
    map_odom: list[tuple[float, float, float]] = field(default_factory=list)


@dataclass
class BagRead:
    stamps: list[Stamp]
    scans: list[LaserScan]
    t_odom: list[float]
    odom: list[tuple[float, float, float]]
    laser: Pose2D
    notes: list[str]
    extras: BagExtras | None = None


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _sec(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


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
        frame_id=str(msg.header.frame_id).lstrip("/") or "laser",
    )


def grid_from_msg(msg) -> OccupancyGrid:
    """nav_msgs/OccupancyGrid -> OccupancyGrid (same row-major layout, row 0 at the origin)."""
    info = msg.info
    o = info.origin
    geom = GridGeometry(
        float(info.resolution),
        int(info.width),
        int(info.height),
        Pose2D(o.position.x, o.position.y, _yaw(o.orientation)),
    )
    data = np.asarray(msg.data, dtype=np.int8).reshape(int(info.height), int(info.width)).copy()
    return OccupancyGrid(geom, data)


# ------------------------------------------------------------------------------------------ opening
def ros_distro(path: Path) -> str | None:
    """The ROS distribution a rosbag2 recording names: ``metadata.yaml``'s ``ros_distro`` (rosbag2
    version >= 8), else the ``.db3`` schema table's (Humble's sqlite3 plugin writes it there)."""
    if path.is_dir():
        with suppress(Exception), Reader2(path) as meta:  # a damaged bag fails later, with its reason
            if meta.ros_distro and meta.ros_distro != "rosbags":
                return str(meta.ros_distro).lower()
    dbs = sorted(path.glob("*.db3")) if path.is_dir() else [path] if path.suffix == ".db3" else []
    for db in dbs[:1]:
        with suppress(sqlite3.Error), closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as con:
            row = con.execute("SELECT ros_distro FROM schema").fetchone()
            if row and row[0] and row[0] != "rosbags":
                return str(row[0]).lower()
    return None


def _store(distro: str) -> Typestore | None:
    try:
        return get_typestore(Stores(f"ros2_{distro}"))
    except ValueError:
        return None


def typestore_candidates(path: Path) -> list[tuple[str, Typestore]]:
    """(label, typestore) to try, in order, for a bag without definitions."""
    distro = ros_distro(path)
    out = []
    if distro and (store := _store(distro)) is not None:
        out.append((f"ROS 2 {distro.capitalize()} (the bag's ros_distro)", store))
    for d in FALLBACK_DISTROS:
        if d != distro and (store := _store(d)) is not None:
            out.append((f"ROS 2 {d.capitalize()}", store))
    return out


def _open(path: Path, default: Typestore | None) -> AnyReader:
    reader = AnyReader([path], default_typestore=default)
    reader.open()
    return reader


def _probe(reader: AnyReader, conns: list[Connection]) -> None:
    """Deserialize one message of each connection (raises when the typestore does not fit)."""
    for con in conns:
        for c, _t, raw in reader.messages(connections=[con]):
            reader.deserialize(raw, c.msgtype)
            break


@contextmanager
def open_bag(path: Path, notes: list[str]) -> Iterator[AnyReader]:
    """An open reader; for a bag without definitions the first typestore that decodes it."""
    try:
        reader = _open(path, None)
        notes.append("message definitions: embedded in the bag")
    except AnyReaderError as exc:
        if "no type definitions" not in str(exc):
            raise LogError(f"{path.name}: not a readable bag ({exc})") from exc
        reader = _open_without_definitions(path, notes)
    except Exception as exc:  # rosbags raises several unrelated types for damaged files
        raise LogError(f"{path.name}: not a readable bag ({exc})") from exc
    try:
        yield reader
    finally:
        reader.close()


def _open_without_definitions(path: Path, notes: list[str]) -> AnyReader:
    tried = []
    for label, store in typestore_candidates(path):
        try:
            reader = _open(path, store)
        except Exception as exc:  # raised inside open_bag's handler: its own except would not see it
            raise LogError(f"{path.name}: not a readable bag ({exc})") from exc
        wanted = [c for c in reader.connections if c.msgtype in (SCAN_TYPE, ODOM_TYPE, TF_TYPE)]
        try:
            _probe(reader, wanted)
        except (AnyReaderError, KeyError, ValueError, IndexError, AssertionError) as exc:
            reader.close()
            tried.append(f"{label}: {exc}")
            continue
        notes.append(f"message definitions: none in the bag; decoded with the {label} typestore")
        return reader
    raise LogError(
        f"{path.name}: the bag has no message definitions and no stock typestore decodes it "
        f"({'; '.join(tried) or 'none tried'}); record with a newer rosbag2 or convert it with rosbags"
    )


# ------------------------------------------------------------------------------------------- topics
def _listing(conns: list[Connection]) -> str:
    counts: dict[str, int] = {}
    for c in conns:
        counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
    return ", ".join(f"{t} ({n} msgs)" for t, n in sorted(counts.items()))


def choose_topics(
    path: Path, conns: list[Connection], scan_topic: str | None, odom_topic: str | None, notes: list[str]
) -> tuple[str, str | None]:
    """The scan topic (given, or the only LaserScan topic) and the odometry topic (given, ``/odom``
    or the only nav_msgs/Odometry topic; None: odometry from ``/tf`` odom -> base_link)."""
    scans = [c for c in conns if c.msgtype == SCAN_TYPE]
    odoms = [c for c in conns if c.msgtype == ODOM_TYPE]
    scan_names = sorted({c.topic for c in scans})
    if scan_topic:
        if scan_topic not in scan_names:
            have = f"its LaserScan topics: {_listing(scans)}" if scans else "it has no LaserScan topic"
            raise LogError(
                f"{path.name}: no LaserScan topic {scan_topic!r} in the bag ({have}); pass --scan-topic"
            )
        notes.append(f"scan topic: {scan_topic} (given)")
    elif not scans:
        raise LogError(
            f"{path.name}: no sensor_msgs/LaserScan topic in the bag (topics: {_listing(conns) or 'none'})"
        )
    elif len(scan_names) > 1:
        raise LogError(
            f"{path.name}: several LaserScan topics: {_listing(scans)}; pass --scan-topic to pick one"
        )
    else:
        scan_topic = scan_names[0]
        notes.append(f"scan topic: {scan_topic} (the only LaserScan topic)")
    odom_names = sorted({c.topic for c in odoms})
    if odom_topic:
        if odom_topic not in odom_names:
            have = f"its Odometry topics: {_listing(odoms)}" if odoms else "it has no Odometry topic"
            raise LogError(
                f"{path.name}: no Odometry topic {odom_topic!r} in the bag ({have}); pass --odom-topic"
            )
        notes.append(f"odometry: {odom_topic} (given)")
        return scan_topic, odom_topic
    if "/odom" in odom_names or len(odom_names) == 1:
        chosen = "/odom" if "/odom" in odom_names else odom_names[0]
        others = f"; others: {', '.join(n for n in odom_names if n != chosen)}" if len(odom_names) > 1 else ""
        notes.append(f"odometry: {chosen} (nav_msgs/Odometry{others})")
        return scan_topic, chosen
    if len(odom_names) > 1:
        raise LogError(
            f"{path.name}: several Odometry topics and none is /odom: {_listing(odoms)}; pass --odom-topic"
        )
    if any(c.topic == "/tf" and c.msgtype == TF_TYPE for c in conns):
        notes.append("odometry: /tf odom -> base_link (no nav_msgs/Odometry topic)")
        return scan_topic, None
    raise LogError(
        f"{path.name}: no odometry: no nav_msgs/Odometry topic and no /tf (topics: {_listing(conns)}); "
        "pass --odom-topic"
    )


# ------------------------------------------------------------------------------------------ reading
def read_rosbag(
    path: Path,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int = 0,
    *,
    extras: bool = False,
) -> BagRead:
    """Scans, odometry samples (from the odometry topic or /tf odom -> base_link) and the laser
    mount, with notes on what was chosen. With ``max_scans > 0`` reading stops once that many scans
    and one later odometry sample are in. ``extras``: also odometry twists, velocity commands
    (Twist topics named ``*cmd_vel*``) and WARN+ log messages (``/rosout``)."""
    notes: list[str] = []
    stamps: list[Stamp] = []
    scans: list[LaserScan] = []
    t_odom: list[float] = []
    odom: list[tuple[float, float, float]] = []
    t_tf: list[float] = []
    tf_odom: list[tuple[float, float, float]] = []
    tree = TfTree()
    more = BagExtras() if extras else None
    with open_bag(path, notes) as reader:
        scan_topic, odom_topic = choose_topics(path, reader.connections, scan_topic, odom_topic, notes)
        wanted = {scan_topic, odom_topic, "/tf_static", "/tf"}
        if more is not None:
            wanted |= {
                c.topic for c in reader.connections if c.msgtype in TWIST_TYPES and "cmd_vel" in c.topic
            }
            wanted |= {c.topic for c in reader.connections if c.msgtype in LOG_TYPES}
            maps = sorted({c.topic for c in reader.connections if c.msgtype == MAP_TYPE})
            more.map_topic = "/map" if "/map" in maps else maps[0] if len(maps) == 1 else ""
            wanted |= {more.map_topic} - {""}
        conns = [c for c in reader.connections if c.topic in wanted]
        try:
            for con, t_bag, raw in reader.messages(connections=conns):
                if (
                    max_scans
                    and len(scans) >= max_scans
                    and t_odom
                    and stamps
                    and t_odom[-1] > float(stamps[-1])
                ):
                    break
                msg = reader.deserialize(raw, con.msgtype)
                typ = con.msgtype
                if con.topic == scan_topic and typ == SCAN_TYPE:
                    if max_scans and len(scans) >= max_scans:
                        continue
                    st = Stamp.from_ros(msg.header.stamp.sec, msg.header.stamp.nanosec)
                    stamps.append(st)
                    scans.append(scan_from_msg(msg, st))
                elif con.topic == odom_topic and typ == ODOM_TYPE:
                    p = msg.pose.pose
                    t = _sec(msg.header.stamp)
                    t_odom.append(t)
                    odom.append((p.position.x, p.position.y, _yaw(p.orientation)))
                    if more is not None:
                        tw = msg.twist.twist
                        more.t_twist.append(t)
                        more.twist.append((tw.linear.x, tw.linear.y, tw.angular.z))
                elif typ == TF_TYPE:
                    for tr in msg.transforms:
                        parent, child = tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/")
                        q, v = tr.transform.rotation, tr.transform.translation
                        if parent == "odom" and child in BASE_FRAMES:
                            if odom_topic is None:
                                t_tf.append(_sec(tr.header.stamp))
                                tf_odom.append((v.x, v.y, _yaw(q)))
                        elif parent == "map" and child == "odom" and more is not None:
                            more.t_map_odom.append(_sec(tr.header.stamp))
                            more.map_odom.append((v.x, v.y, _yaw(q)))
                        else:
                            tree.add(parent, child, (v.x, v.y, v.z), (q.x, q.y, q.z, q.w))
                elif more is not None and typ in TWIST_TYPES:
                    tw = msg.twist if typ.endswith("TwistStamped") else msg
                    more.t_cmd.append(t_bag * 1e-9)
                    more.cmd.append((tw.linear.x, tw.linear.y, tw.angular.z))
                elif more is not None and typ in LOG_TYPES:
                    _log_event(more, msg, typ, t_bag)
                elif more is not None and typ == MAP_TYPE:
                    more.grid, more.t_grid = grid_from_msg(msg), _sec(msg.header.stamp)
        except AnyReaderError as exc:
            raise LogError(f"{path.name}: cannot decode {con.topic} ({exc})") from exc
    if odom_topic is None:
        t_odom, odom = t_tf, tf_odom
    mount = _mount(tree, scans, notes)
    if mount.upside_down:
        scans = [upright(s) for s in scans]
    return BagRead(stamps, scans, t_odom, odom, mount.pose, notes, more)


def _mount(tree: TfTree, scans: list[LaserScan], notes: list[str]) -> LaserMount:
    frame = scans[0].frame_id if scans else "laser"
    mount = tree.laser_mount(frame)
    if mount is None:
        notes.append(f"laser mount: no tf from base_link to {frame!r}; assumed at base_link's origin")
        return LaserMount(Pose2D())
    notes.append(mount.describe())
    return mount


# ROS 1 levels are bit flags (WARN = 4), ROS 2 levels decades (WARN = 30).
_WARN = {"rosgraph_msgs/msg/Log": 4, "rcl_interfaces/msg/Log": 30}


def _log_event(more: BagExtras, msg, typ: str, t_bag: int) -> None:
    level = int(msg.level)
    if level >= _WARN[typ]:
        more.events.append(
            {
                "t": t_bag * 1e-9,
                "type": "log",
                "level": level,
                "name": str(msg.name),
                "msg": str(msg.msg)[:500],
            }
        )
