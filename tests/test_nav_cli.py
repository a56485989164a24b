"""``navdeck sim-nav``: the whole stack on a virtual clock, JSON out; bad input exits 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
APARTMENT = ROOT / "maps" / "stock" / "apartment.yaml"


def navdeck(*args: str) -> subprocess.CompletedProcess:
    """The real entry point in a child process (argument parsing, exit codes, stdout)."""
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def navdeck_inproc(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str, str]:
    from app.cli import main

    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse errors
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_sim_nav_json_reaches_goal() -> None:
    r = navdeck(
        "sim-nav",
        "--map",
        str(APARTMENT),
        "--start",
        "3,3.5,0",
        "--goal",
        "3,1.2,-1.57",
        "--seed",
        "3",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    keys = {"reached", "time_s", "path_length_m", "recoveries", "collisions", "min_clearance_m"}
    assert keys | {"localization_error_m"} <= set(out)
    assert out["reached"] is True and out["collisions"] == 0
    assert 2.0 < out["path_length_m"] < 6.0 and 0.0 < out["time_s"] < 60.0
    assert out["min_clearance_m"] > 0.05 and out["localization_error_m"] < 0.1


def test_sim_nav_is_deterministic_for_a_seed() -> None:
    from app.commands.sim_nav import SimNavConfig, run_sim_nav

    cfg = SimNavConfig(APARTMENT, (3.0, 3.5, 0.0), ((3.0, 2.5, 0.0),), localization="truth", seed=5)
    a, b = run_sim_nav(cfg), run_sim_nav(cfg)
    assert a.reached and a.time_s == b.time_s and a.path_length_m == b.path_length_m


def test_sim_nav_with_unmapped_obstacle_goes_around() -> None:
    from app.commands.sim_nav import SimNavConfig, run_sim_nav

    box = ((2.8, 2.2), (3.2, 2.2), (3.2, 2.5), (2.8, 2.5))  # on the straight line, not on the map
    cfg = SimNavConfig(APARTMENT, (3.0, 3.5, -1.5708), ((3.0, 1.2, -1.5708),), obstacles=(box,), seed=2)
    res = run_sim_nav(cfg)
    assert res.reached and res.collisions == 0, res


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--goal", "50,1,0"], "off the map"),
        (["--goal", "0.02,0.02,0"], "inside an obstacle"),
        (["--goal", "nan,1,0"], "finite"),
        (["--goal", "3,1.2", "--timeout", "-1"], "--timeout"),
    ],
)
def test_sim_nav_bad_input_exits_2(capsys: pytest.CaptureFixture, args: list[str], message: str) -> None:
    code, out, err = navdeck_inproc(capsys, "sim-nav", "--map", str(APARTMENT), "--start", "3,3.5,0", *args)
    assert code == 2 and out == ""
    assert message in err


def test_sim_nav_missing_map_exits_2(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    code, _, err = navdeck_inproc(
        capsys, "sim-nav", "--map", str(tmp_path / "nope.yaml"), "--start", "0,0,0", "--goal", "1,1,0"
    )
    assert code == 2 and "not found" in err


def test_sim_nav_accepts_negative_coordinates_as_typed(tmp_path: Path) -> None:
    """``--start -2,-0.5,0`` (issue 16): argparse alone reads ``-2,...`` as an option and exits
    with "expected one argument". The apartment with its origin moved to (-5, -4) puts the usual
    start and goal at negative coordinates; the real entry point must run it."""
    (tmp_path / "apartment.pgm").write_bytes((APARTMENT.parent / "apartment.pgm").read_bytes())
    text = APARTMENT.read_text().replace("origin: [0, 0, 0]", "origin: [-5, -4, 0]")
    (tmp_path / "shifted.yaml").write_text(text)
    r = navdeck(
        "sim-nav", "--map", str(tmp_path / "shifted.yaml"), "--start", "-2,-0.5,0",
        "--goal", "-2,-1.5,-1.57", "--localization", "truth", "--json",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["reached"] is True and out["collisions"] == 0


def test_negative_values_reach_every_pose_option() -> None:
    from app.cli import parse_args

    args = parse_args(["sim-nav", "--map", "m.yaml", "--start", "-1.5,2,0", "--goal", "-3,-0.5",
                       "--goal=-1,2,-1.57", "--seed", "-1"])  # fmt: skip
    assert args.start == (-1.5, 2.0, 0.0)
    assert args.goal == [(-3.0, -0.5, 0.0), (-1.0, 2.0, -1.57)]
    assert args.seed == -1
    plan = parse_args(["plan", "--map", "m.yaml", "--start", "-1,-1", "--goal", "-2.5,1,3.1"])
    assert plan.start == (-1.0, -1.0, 0.0) and plan.goal == (-2.5, 1.0, 3.1)
