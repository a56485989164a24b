"""``navdeck slam`` on a short slice of a real log, ``navdeck slam-eval`` on a known trajectory."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from bench.datasets import SLAM_BENCHMARK
from nav.slam.metric import parse_relations, score_trajectory

INTEL = SLAM_BENCHMARK / "bags/intel.orig.bag"


@pytest.mark.skipif(not INTEL.exists(), reason="Intel benchmark log not available")
def test_slam_cli_writes_map_and_trajectory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["slam", str(INTEL), "--limit", "150", "--out", str(out)]) == 0
    assert (out / "map.pgm").stat().st_size > 1000
    assert "resolution: 0.05" in (out / "map.yaml").read_text()
    lines = (out / "trajectory.txt").read_text().splitlines()
    assert len(lines) == 150
    first = lines[0].split()
    assert first[0] == "976052857.337530017" and len(first) == 4  # stamp text exactly as in the bag
    assert "scans/s" in capsys.readouterr().err


FR079 = SLAM_BENCHMARK / "bags/fr079.orig.bag"


@pytest.mark.skipif(not FR079.exists(), reason="FR079 benchmark log not available")
def test_slam_cli_laser_frame_trajectory(tmp_path: Path) -> None:
    """``--frame laser`` writes the laser's poses: FR079's laser sits 0.04 m ahead of base_link."""
    rows = {}
    for frame in ("base_link", "laser"):
        out = tmp_path / frame
        args = ["slam", str(FR079), "--limit", "40", "--quiet", "--frame", frame, "--out", str(out)]
        assert main(args) == 0
        rows[frame] = np.loadtxt(out / "trajectory.txt", dtype=float)
    base, laser = rows["base_link"], rows["laser"]
    np.testing.assert_allclose(laser[:, 3], base[:, 3], atol=1e-9)  # same heading
    ahead = (laser[:, 1] - base[:, 1]) * np.cos(base[:, 3]) + (laser[:, 2] - base[:, 2]) * np.sin(base[:, 3])
    np.testing.assert_allclose(ahead, 0.04, atol=1e-3)


def test_slam_cli_log_without_scans_fails_cleanly(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "odom.log"
    log.write_text("ODOM 0.0 0.0 0.0 0 0 0 100.0 host 100.0\n")
    assert main(["slam", str(log), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no usable laser scans" in err[0]


def _write_known(tmp_path: Path) -> tuple[Path, Path]:
    # a square path; relations from the true poses; the estimate has 0.1 m and 2 deg errors at t=3
    t = np.arange(6, dtype=float) + 1000.0
    truth = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, math.pi / 2], [0, 1, math.pi], [0, 0, -math.pi / 2], [1, 0, 0]]
    )
    est = truth.copy()
    est[3] += [0.1, 0.0, math.radians(2.0)]
    traj = tmp_path / "traj.txt"
    traj.write_text("".join(f"{ti:.6f} {x} {y} {th}\n" for ti, (x, y, th) in zip(t, est, strict=True)))
    rel_lines = []
    for a, b in [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]:
        pa, pb = truth[a], truth[b]
        c, s = math.cos(pa[2]), math.sin(pa[2])
        dx, dy = pb[0] - pa[0], pb[1] - pa[1]
        yaw = (pb[2] - pa[2] + math.pi) % (2 * math.pi) - math.pi
        rel_lines.append(f"{t[a]:.6f} {t[b]:.6f} {c * dx + s * dy} {-s * dx + c * dy} 0 0 0 {yaw}\n")
    rel = tmp_path / "rel.relations"
    rel.write_text("# t1 t2 x y z roll pitch yaw\n" + "".join(rel_lines))
    return traj, rel


def test_slam_eval_known_trajectory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    traj, rel = _write_known(tmp_path)
    assert main(["slam-eval", "--trajectory", str(traj), "--relations", str(rel)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n"] == 5
    # relations (2,3) and (3,4) each see the 0.1 m / 2 deg error; the other three are exact
    assert math.isclose(out["rot_mean_deg"], 2 * 2.0 / 5, rel_tol=1e-6)
    assert 0.04 - 1e-9 <= out["trans_mean"] <= 0.1
    assert set(out) >= {"n", "trans_mean", "trans_std", "rot_mean_deg", "rot_std_deg"}


def test_metric_exact_trajectory_scores_zero(tmp_path: Path) -> None:
    traj, rel = _write_known(tmp_path)
    rows = np.loadtxt(traj)
    rows[3, 1:] -= [0.1, 0.0, math.radians(2.0)]
    score = score_trajectory(rows, parse_relations(rel.read_text()))
    assert score.n == 5 and score.trans_mean < 1e-9 and score.rot_mean_deg < 1e-9


def test_slam_eval_without_matching_stamps_fails(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    traj, rel = _write_known(tmp_path)
    traj.write_text("5.0 0 0 0\n6.0 1 0 0\n")
    assert main(["slam-eval", "--trajectory", str(traj), "--relations", str(rel)]) == 2
    assert "no relation" in capsys.readouterr().err
