"""Every ROS bag a user has, read with no flags (issue 21), on real data: the first 40 s of the
Intel Research Lab log as a ROS1 bag whose scan topic is ``/base_scan`` (tests/data/bags), and the
ROS 2 bags written from it with rosbags: ``.db3`` without message definitions in Humble's and Foxy's
layouts, single ``.db3`` / ``.mcap`` files, zstd file and message compression, other laser mounts."""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from app.cli import main
from robot.logs import LogError
from robot.logs.bag_convert import slice_ros1, strip_definitions, to_ros2
from robot.logs.frames import TfTree
from robot.logs.reader import RawLog, load_raw_log

DATA = Path(__file__).parent / "data" / "bags"
ROS1 = DATA / "intel-40s-base_scan.bag"
NOETIC = get_typestore(Stores.ROS1_NOETIC)

Edit = Callable[[str, str, object, int], Iterable[tuple[str, str, object, int]]]


def rewrite_ros1(src: Path, dst: Path, edit: Edit) -> Path:
    """Copy a ROS1 bag message by message through ``edit(topic, type, msg, t_ns)``, which returns
    the messages to write instead (none drops it; new types come from the Noetic typestore)."""
    with AnyReader([src]) as reader, Writer1(dst) as writer:
        conns: dict[tuple[str, str], object] = {}
        for con, t, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            for topic, typ, out, t_out in edit(con.topic, con.msgtype, msg, t):
                store = reader.typestore if typ in reader.typestore.fielddefs else NOETIC
                if (topic, typ) not in conns:
                    conns[(topic, typ)] = writer.add_connection(topic, typ, typestore=store)
                writer.write(conns[(topic, typ)], t_out, store.serialize_ros1(out, typ))
    return dst


def mounted(yaw: float, upside_down: bool) -> Edit:
    """The same robot with its laser turned by ``yaw`` (and hung upside down): tf_static says so and
    every scan is what that laser would have measured (same beams, its own angles)."""
    c, s = math.cos(yaw / 2), math.sin(yaw / 2)
    # Rz(yaw) (x) Rx(pi) = (x=c, y=s, z=0, w=0); Rz(yaw) alone = (0, 0, s, c)
    quat = (c, s, 0.0, 0.0) if upside_down else (0.0, 0.0, s, c)

    def edit(topic: str, typ: str, msg, t: int):
        if topic == "/tf_static":
            tr = msg.transforms[0]
            q = dataclasses.replace(tr.transform.rotation, x=quat[0], y=quat[1], z=quat[2], w=quat[3])
            tr = dataclasses.replace(
                tr, child_frame_id="rplidar_link", transform=dataclasses.replace(tr.transform, rotation=q)
            )
            msg = dataclasses.replace(msg, transforms=[tr])
        elif topic == "/base_scan":
            n = len(msg.ranges)
            header = dataclasses.replace(msg.header, frame_id="rplidar_link")
            if upside_down:  # a beam at body angle b is at laser angle yaw - b: reversed order
                amin = yaw - (msg.angle_min + (n - 1) * msg.angle_increment)
                msg = dataclasses.replace(msg, header=header, angle_min=amin, ranges=msg.ranges[::-1].copy())
            else:
                msg = dataclasses.replace(msg, header=header, angle_min=msg.angle_min - yaw)
            msg = dataclasses.replace(msg, angle_max=msg.angle_min + (n - 1) * msg.angle_increment)
        yield topic, typ, msg, t

    return edit


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    """The stored ROS1 bag and every ROS 2 form written from it."""
    d = tmp_path_factory.mktemp("bags")
    out = {"ros1": ROS1}
    to_ros2(ROS1, d / "humble")
    strip_definitions(d / "humble")  # Humble: the distro only in the .db3's schema table
    out["db3 humble, no definitions"] = d / "humble"
    out["single .db3, no definitions"] = d / "humble" / "humble.db3"
    to_ros2(ROS1, d / "foxy")
    strip_definitions(d / "foxy", distro=None)  # Foxy: no distro anywhere
    out["db3 foxy, no definitions"] = d / "foxy"
    to_ros2(ROS1, d / "mcap", "mcap")
    out["mcap dir"] = d / "mcap"
    shutil.copy(d / "mcap" / "mcap.mcap", d / "single.mcap")
    out["single .mcap"] = d / "single.mcap"
    to_ros2(ROS1, d / "zfile", compress_mode="file")
    out["db3 zstd file"] = d / "zfile"
    to_ros2(ROS1, d / "zmsg", "mcap", compress_mode="message")
    out["mcap zstd message"] = d / "zmsg"
    slice_ros1(ROS1, d / "lz4.bag", seconds=60, compression="lz4")
    out["ros1 lz4"] = d / "lz4.bag"
    return out


@pytest.fixture(scope="module")
def reference() -> RawLog:
    return load_raw_log(ROS1)


FORMATS = [
    "db3 humble, no definitions",
    "single .db3, no definitions",
    "db3 foxy, no definitions",
    "mcap dir",
    "single .mcap",
    "db3 zstd file",
    "mcap zstd message",
    "ros1 lz4",
]


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_reads_the_same_scans_and_odometry_with_no_flags(bags, reference, fmt) -> None:
    raw = load_raw_log(bags[fmt])
    assert [str(s) for s in raw.stamps] == [str(s) for s in reference.stamps]
    assert len(raw.scans) == 205
    for a, b in zip(raw.scans, reference.scans, strict=True):
        assert np.array_equal(a.ranges, b.ranges) and a.angle_min == b.angle_min
    assert np.array_equal(raw.t_odom, reference.t_odom) and np.array_equal(raw.odom, reference.odom)
    assert raw.laser == reference.laser
    assert "scan topic: /base_scan (the only LaserScan topic)" in raw.notes


def test_typestore_fallback_is_named(bags) -> None:
    embedded = load_raw_log(bags["mcap dir"]).notes[0]
    humble = load_raw_log(bags["db3 humble, no definitions"]).notes[0]
    foxy_layout = load_raw_log(bags["db3 foxy, no definitions"]).notes[0]
    assert embedded == "message definitions: embedded in the bag"
    assert "none in the bag" in humble and "ROS 2 Humble (the bag's ros_distro)" in humble
    # no ros_distro anywhere: Humble is tried first
    assert "none in the bag" in foxy_layout and "ROS 2 Humble typestore" in foxy_layout


def test_the_bags_own_distro_is_used(tmp_path) -> None:
    bag = tmp_path / "galactic"
    to_ros2(ROS1, bag)
    strip_definitions(bag, distro="galactic")
    raw = load_raw_log(bag)
    assert "ROS 2 Galactic (the bag's ros_distro)" in raw.notes[0] and len(raw.scans) == 205


def test_cli_maps_a_humble_db3_without_definitions_and_a_ros1_base_scan_bag_with_no_flags(
    bags, tmp_path, capsys
) -> None:
    assert main(["slam", str(ROS1), "--out", str(tmp_path / "ros1"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "scan topic: /base_scan (the only LaserScan topic)" in err and "205 scans" in err
    db3 = bags["db3 humble, no definitions"]
    assert main(["slam", str(db3), "--out", str(tmp_path / "db3"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "decoded with the ROS 2 Humble (the bag's ros_distro) typestore" in err
    a = (tmp_path / "ros1" / "trajectory.txt").read_text()
    assert a == (tmp_path / "db3" / "trajectory.txt").read_text() and len(a.splitlines()) == 205
    assert (tmp_path / "db3" / "map.pgm").stat().st_size > 0


@pytest.mark.parametrize(("yaw_deg", "upside_down"), [(90.0, False), (90.0, True), (-30.0, True)])
def test_laser_mount_from_tf_static_turned_and_upside_down(tmp_path, reference, yaw_deg, upside_down) -> None:
    """A TurtleBot 4's lidar is turned 90 degrees; some robots hang theirs upside down. Read with the
    mount found in /tf_static, the scans land on the same points of the robot's plane."""
    bag = rewrite_ros1(ROS1, tmp_path / "mount.bag", mounted(math.radians(yaw_deg), upside_down))
    raw = load_raw_log(bag)
    assert math.isclose(raw.laser.theta, math.radians(yaw_deg), abs_tol=1e-9)
    note = next(n for n in raw.notes if n.startswith("laser mount"))
    assert "base_link -> rplidar_link" in note and ("upside down" in note) == upside_down
    for a, b in zip(raw.scans[::20], reference.scans[::20], strict=True):
        pa = raw.laser.transform_points(a.points())
        pb = reference.laser.transform_points(b.points())
        assert np.allclose(pa, pb, atol=1e-4)


def test_tf_chain_composes_offsets_and_rotations() -> None:
    tree = TfTree()
    tree.add("base_footprint", "base_link", (0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0))
    s = math.sin(math.pi / 4)
    tree.add("base_link", "lidar_mount", (0.2, 0.1, 0.3), (0.0, 0.0, s, s))  # turned +90 deg
    tree.add("lidar_mount", "laser", (0.05, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))  # hung upside down
    mount = tree.laser_mount("laser")
    assert mount is not None and mount.chain == ("base_link", "lidar_mount", "laser")
    assert math.isclose(mount.pose.x, 0.2, abs_tol=1e-12) and math.isclose(mount.pose.y, 0.15, abs_tol=1e-12)
    assert math.isclose(mount.pose.theta, math.pi / 2, abs_tol=1e-12) and mount.upside_down
    assert tree.laser_mount("elsewhere") is None


def _duplicate_scan(topic: str, typ: str, msg, t: int):
    yield topic, typ, msg, t
    if topic == "/base_scan":
        yield "/front_scan", typ, msg, t


def test_several_scan_topics_are_listed_and_the_flag_picks_one(tmp_path) -> None:
    bag = rewrite_ros1(ROS1, tmp_path / "two.bag", _duplicate_scan)
    with pytest.raises(
        LogError, match=r"several LaserScan topics: /base_scan \(205 msgs\), /front_scan.*--scan-topic"
    ):
        load_raw_log(bag)
    raw = load_raw_log(bag, scan_topic="/front_scan")
    assert len(raw.scans) == 205 and "scan topic: /front_scan (given)" in raw.notes
    with pytest.raises(LogError, match=r"no LaserScan topic '/scan'.*its LaserScan topics: /base_scan"):
        load_raw_log(bag, scan_topic="/scan")


def test_odometry_from_tf_when_there_is_no_odometry_topic(tmp_path, reference) -> None:
    def no_odom(topic: str, typ: str, msg, t: int):
        if topic != "/odom":
            yield topic, typ, msg, t

    raw = load_raw_log(rewrite_ros1(ROS1, tmp_path / "tf.bag", no_odom))
    assert "odometry: /tf odom -> base_link (no nav_msgs/Odometry topic)" in raw.notes
    assert len(raw.t_odom) == 401 and np.allclose(raw.odom, reference.odom, atol=1e-9)


def test_no_scan_topic_is_one_line_naming_what_is_there(tmp_path) -> None:
    def no_scan(topic: str, typ: str, msg, t: int):
        if topic != "/base_scan":
            yield topic, typ, msg, t

    with pytest.raises(
        LogError, match=r"no sensor_msgs/LaserScan topic in the bag \(topics: /odom \(401 msgs\)"
    ):
        load_raw_log(rewrite_ros1(ROS1, tmp_path / "noscan.bag", no_scan))


def test_damaged_bag_is_a_typed_error(tmp_path) -> None:
    bad = tmp_path / "cut.bag"
    bad.write_bytes(ROS1.read_bytes()[:3000])
    with pytest.raises(LogError, match=r"cut\.bag"):
        load_raw_log(bad)


def test_given_topics_are_used_and_a_wrong_odometry_topic_names_the_right_one() -> None:
    raw = load_raw_log(ROS1, scan_topic="/base_scan", odom_topic="/odom")
    assert raw.notes[1:3] == ("scan topic: /base_scan (given)", "odometry: /odom (given)")
    with pytest.raises(
        LogError, match=r"no Odometry topic '/wheel_odom'.*its Odometry topics: /odom \(401 msgs\)"
    ):
        load_raw_log(ROS1, odom_topic="/wheel_odom")
