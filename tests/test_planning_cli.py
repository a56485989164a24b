"""``navdeck plan``: JSON output, pure-geometry lengths, typed failures (exit 0), bad input (exit 2)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from app.cli import main


@pytest.fixture()
def map_yaml(tmp_path: Path) -> Path:
    """A 4 x 3 m map at 0.05 m: outer walls and an internal wall at x = 2 m with a gap at the top."""
    h, w = 60, 80
    img = np.full((h, w), 254, dtype=np.uint8)  # free (white)
    img[0, :] = img[-1, :] = img[:, 0] = img[:, -1] = 0  # occupied (black)
    img[15:, 40] = 0  # image row 0 is the top of the map: the wall leaves a gap near the top
    (tmp_path / "m.pgm").write_bytes(b"P5\n%d %d\n255\n" % (w, h) + img.tobytes())
    (tmp_path / "m.yaml").write_text(
        "image: m.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return tmp_path / "m.yaml"


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict]:
    code = main(["plan", *argv])
    out = capsys.readouterr().out
    return code, (json.loads(out) if out.strip().startswith("{") else {})


def test_plan_json_pure_geometry(map_yaml: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Start and goal on cell centres in the same free row: a straight 8-connected path.
    code, out = _run(
        capsys, "--map", str(map_yaml), "--start", "0.525,1.025", "--goal", "1.525,1.025",
        "--no-inflation", "--cost-weight", "0", "--json",
    )  # fmt: skip
    assert code == 0 and out["found"] is True
    assert out["length_m"] == pytest.approx(1.0, abs=1e-6)
    assert out["path"][0] == [0.525, 1.025] and out["path"][-1] == [1.525, 1.025]
    assert {"time_ms", "length_m", "path"} <= out.keys()


def test_plan_json_detour_and_planners_agree(map_yaml: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lengths = []
    for planner in ("astar", "dijkstra"):
        code, out = _run(
            capsys, "--map", str(map_yaml), "--start", "1.025,0.525", "--goal", "3.025,0.525",
            "--planner", planner, "--no-inflation", "--cost-weight", "0", "--json",
        )  # fmt: skip
        assert code == 0 and out["found"]
        pts = np.array(out["path"])
        assert pts[:, 1].max() > 2.2  # over the wall through the gap
        lengths.append(out["length_m"])
    assert lengths[0] == pytest.approx(lengths[1], abs=1e-6)
    assert lengths[0] > 2 * math.hypot(1.0, 1.7)  # longer than the two straight legs via the gap


def test_plan_typed_failure_exits_zero(map_yaml: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _run(capsys, "--map", str(map_yaml), "--start", "1,1", "--goal", "9,1", "--json")
    assert code == 0 and out["found"] is False and out["error"] == "GoalOutsideMap"
    code, out = _run(capsys, "--map", str(map_yaml), "--start", "0.01,1", "--goal", "1,1", "--json")
    assert code == 0 and out["error"] == "StartOccupied"


def test_plan_bad_input_exits_two(map_yaml: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plan", "--map", str(tmp_path / "missing.yaml"), "--start", "1,1", "--goal", "2,1"]) == 2
    assert (
        main(["plan", "--map", str(map_yaml), "--start", "1,1", "--goal", "2,1", "--robot-radius", "-1"]) == 2
    )
    with pytest.raises(SystemExit) as info:
        main(["plan", "--map", str(map_yaml), "--start", "1,x", "--goal", "2,1"])
    assert info.value.code == 2
    capsys.readouterr()
