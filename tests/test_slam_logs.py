"""Log readers: ROS1 bag slice (real Intel log), CARMEN text logs, exact stamps, typed errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.datasets import SLAM_BENCHMARK
from robot.logs import LogError, Stamp, read_log
from robot.logs.reader import interpolate_poses, load_log

INTEL = SLAM_BENCHMARK / "bags/intel.orig.bag"
RELATIONS = SLAM_BENCHMARK / "relations/intel.relations"


def _flaser(n: int, t: str, odom: tuple[float, float, float], r: float = 2.0) -> str:
    ranges = " ".join([f"{r:.2f}"] * (n - 1) + ["81.91"])  # last beam: no return
    x, y, th = odom
    return f"FLASER {n} {ranges} {x} {y} {th} {x} {y} {th} {t} host {t}"


def test_carmen_flaser_and_odom(tmp_path: Path) -> None:
    log = tmp_path / "run.log"
    log.write_text(
        "# comment\n"
        "ODOM 0.0 0.0 0.0 0 0 0 100.000000 host 100.0\n"
        + _flaser(180, "100.500000", (0.5, 0.0, 0.1))
        + "\nODOM 1.0 0.0 0.2 0 0 0 101.000000 host 101.0\n"
        + _flaser(180, "101.250000", (1.25, 0.0, 0.15))
        + "\n"
    )
    recs = list(read_log(log))
    assert len(recs) == 2
    stamp, scan, odom = recs[0]
    assert str(stamp) == "100.500000" and math.isclose(float(stamp), 100.5)
    assert scan.ranges.shape == (180,)
    assert np.isinf(scan.ranges[-1]) and scan.ranges[0] == 2.0
    assert math.isclose(scan.angle_min, -math.pi / 2)
    assert math.isclose(scan.angle_increment * 180, math.pi)
    # odometry interpolated at the scan stamp from all odometry samples (ODOM and FLASER lines)
    assert math.isclose(odom.x, 0.5) and math.isclose(odom.theta, 0.1)


def test_carmen_without_scans_is_a_typed_error(tmp_path: Path) -> None:
    log = tmp_path / "odom_only.log"
    log.write_text("ODOM 0.0 0.0 0.0 0 0 0 100.0 host 100.0\n")
    with pytest.raises(LogError, match="no usable laser scans"):
        list(read_log(log, fmt="carmen"))


def test_missing_file_is_a_typed_error(tmp_path: Path) -> None:
    with pytest.raises(LogError):
        read_log(tmp_path / "nope.bag")


def test_stamp_keeps_text() -> None:
    s = Stamp.from_ros(976052905, 167303085)
    assert str(s) == "976052905.167303085"
    assert abs(float(s) - 976052905.167303085) < 1e-6


def test_interpolate_poses_unwraps_angles() -> None:
    t = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, math.pi - 0.1], [1.0, 2.0, -math.pi + 0.1]])
    out = interpolate_poses(np.array([0.5]), t, poses)
    assert np.allclose(out[0, :2], [0.5, 1.0])
    assert math.isclose(abs(out[0, 2]), math.pi, abs_tol=1e-9)


@pytest.mark.skipif(not INTEL.exists(), reason="Intel benchmark log not available")
def test_rosbag_slice_matches_relation_stamps() -> None:
    recs, laser = load_log(INTEL, max_scans=400)
    assert len(recs) == 400
    assert laser.x == 0.0 and laser.theta == 0.0
    stamps = np.array([float(r.stamp) for r in recs])
    assert np.all(np.diff(stamps) > 0)
    scan = recs[0].scan
    assert scan.ranges.shape == (180,) and math.isclose(scan.angle_increment, math.pi / 179, rel_tol=1e-3)
    # the relations name scans by their stamps: some of the first ones appear verbatim (to 1 us)
    rel_t = np.loadtxt(RELATIONS, usecols=(0, 1)).ravel()
    hits = np.min(np.abs(stamps[:, None] - rel_t[None, :]), axis=1) < 1e-5
    assert hits.sum() >= 3
