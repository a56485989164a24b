"""The CLI fails with one line, not a traceback, on bad input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

NAVDECK = [sys.executable, "-m", "app.cli"]


def run_cli(*args: str, tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*NAVDECK, *args, "--db", f"sqlite:///{tmp_path}/x.db"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parent.parent,
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["serve", "--profile", "no-such-profile"], "unknown profile"),
        (["serve", "--world", "moon"], "unknown world"),
        (["serve", "--world", "/nope/missing.yaml"], "does not exist"),
        (["serve", "--robot", "teleport://x"], "unknown robot"),
    ],
)
def test_bad_serve_arguments_exit_with_one_line(args: list[str], needle: str, tmp_path: Path) -> None:
    proc = run_cli(*args, tmp_path=tmp_path)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert needle in lines[0] and "Traceback" not in proc.stderr


def test_bad_profile_file_names_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "mine.toml"
    bad.write_text('name = "mine"\nkinematics = "tank"\nrobot_radius = 0.2\n')
    proc = run_cli("serve", "--profile", str(bad), tmp_path=tmp_path)
    assert proc.returncode == 2 and "kinematics" in proc.stderr


def test_help_lists_commands() -> None:
    proc = subprocess.run([*NAVDECK, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0
    for cmd in ("serve", "bench"):
        assert cmd in proc.stdout
