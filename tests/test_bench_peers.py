"""``navdeck bench peers`` helpers: MovingAI parsing, optional peers, the ratio table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench import pythonrobotics_dwa as prd
from bench.peers import (
    KartoScanMatcher,
    NavdeckScanMatcher,
    Row,
    _scan_points,
    load_movingai_map,
    load_scenarios,
    markdown_table,
    navdeck_astar,
    optional_import,
    random_grid,
)
from nav.slam.synthetic import box_world, cast_scan
from nav.types import Pose2D


def test_movingai_map_and_scenarios(tmp_path: Path) -> None:
    m = tmp_path / "tiny.map"
    m.write_text("type octile\nheight 3\nwidth 4\nmap\n..@.\n.T..\nG..S\n")
    grid = load_movingai_map(m)
    assert grid.shape == (3, 4)
    assert not grid[0, 2] and not grid[1, 1] and grid[2, 0] and grid[2, 3]
    scen = tmp_path / "tiny.scen"
    scen.write_text("version 1\n0\ttiny.map\t4\t3\t0\t0\t3\t2\t5.0\n")
    ((start, goal, optimal),) = load_scenarios(scen, 20)
    assert start == (0, 0) and goal == (2, 3)
    # Every diagonal shortcut passes a blocked corner ('@' at (0,2), 'T' at (1,1)), so the only
    # legal path runs down column 0 and along row 2: 5 straight steps.
    assert navdeck_astar(grid, start, goal) == optimal == 5.0


def test_missing_peer_is_none_and_row_has_no_ratio() -> None:
    assert optional_import("no_such_peer_package_xyz") is None
    row = Row("A*, x", 5.0, "pyastar2d (not installed)", None)
    assert row.ratio is None
    table = markdown_table([row, Row("A*, y", 3.0, "pyastar2d", 2.0)])
    assert "| A*, y | 3 ms | pyastar2d 2 ms | 1.50 |" in table
    assert "not installed" in table


def test_random_grid_is_seeded_and_solvable() -> None:
    a, b = random_grid(200, 0.2, 0), random_grid(200, 0.2, 0)
    assert np.array_equal(a, b)
    assert abs((~a).mean() - 0.2) < 0.01
    assert np.isfinite(navdeck_astar(a, (0, 0), (199, 199)))


def test_product_never_imports_a_peer() -> None:
    root = Path(__file__).resolve().parents[1]
    peers = ("pyastar2d", "karto_scanmatcher", "import amcl", "from amcl", "irsim")
    for pkg in ("app", "robot", "nav", "maps"):
        for f in (root / pkg).rglob("*.py"):
            text = f.read_text()
            assert not any(p in text for p in peers), f


def test_pythonrobotics_dwa_reference_follows_its_published_rules() -> None:
    """The DWA peer written from PythonRobotics' algorithm: its dynamic window from rest (4 speeds
    x 80 turn rates), 3 s rollouts at 0.1 s (the start and 30 steps), a collision inside the robot
    radius costs inf, and the chosen command leads towards the goal without touching an obstacle."""

    cfg = prd.Config()
    dw = prd.dynamic_window(prd.START, cfg)
    assert dw == pytest.approx((-0.02, 0.02, -cfg.max_delta_yaw_rate * 0.1, cfg.max_delta_yaw_rate * 0.1))
    traj = prd.predict_trajectory(prd.START, 0.5, 0.1, cfg)
    assert traj.shape == (31, 5) and traj[-1, 3] == 0.5  # 30 steps: 0.1 summed 30 times exceeds 3.0
    assert prd.obstacle_cost(traj, np.array([[traj[5, 0], traj[5, 1] + 0.5]]), cfg) == float("inf")
    far = np.array([[traj[5, 0], traj[5, 1] + 2.0]])
    nearest = np.hypot(traj[:, 0] - far[0, 0], traj[:, 1] - far[0, 1]).min()
    assert nearest > cfg.robot_radius and prd.obstacle_cost(traj, far, cfg) == pytest.approx(1.0 / nearest)
    x = prd.START.copy()
    for _ in range(40):  # 4 s of its demo loop
        (v, w), best = prd.dwa_control(x, cfg, prd.GOAL, prd.OBSTACLES)
        assert np.isfinite(prd.obstacle_cost(best, prd.OBSTACLES, cfg))
        x = prd.motion(x, v, w, cfg.dt)
    assert np.hypot(*(x[:2] - prd.GOAL)) < np.hypot(*(prd.START[:2] - prd.GOAL))


@pytest.mark.parametrize("side", ["navdeck", "karto"])
def test_both_scan_matchers_recover_a_known_motion(side: str) -> None:
    # two scans of the box world 0.12 m / 3 deg apart, 180-beam 180 deg laser like Intel's; the
    # odometry prior is off by (0.04, -0.03, 1.5 deg) = 5 cm: both sides must land within a grid
    # cell (karto's search is on the 0.05 m lattice, without sub-cell refinement)
    grid, res = box_world()
    rng = np.random.default_rng(0)
    a, b = Pose2D(3.0, 2.0, 0.3), Pose2D(3.115, 2.035, 0.3 + math.radians(3.0))
    ref = cast_scan(grid, res, a, 180, fov=math.pi, noise=0.005, rng=rng)
    cur = cast_scan(grid, res, b, 180, fov=math.pi, noise=0.005, rng=rng)
    truth = b.relative_to(a)
    prior = Pose2D(truth.x + 0.04, truth.y - 0.03, truth.theta + math.radians(1.5))
    if side == "navdeck":
        got = NavdeckScanMatcher().match(ref, _scan_points(ref), _scan_points(cur), prior)
    else:
        karto = pytest.importorskip("karto_scanmatcher")
        m = KartoScanMatcher(karto, ref)
        got = m.match(m.scan(ref, Pose2D(), 0), m.scan(cur, prior, 1))
    assert got.distance_to(truth) < 0.035, (got, truth)
    assert abs(got.theta - truth.theta) < math.radians(1.0)
