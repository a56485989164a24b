"""``navdeck emulate``: prints the device paths and URL, runs for --duration, reports user errors."""

from __future__ import annotations

import os

import pytest

from app.cli import main


def test_emulate_base_prints_url(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["emulate", "base", "--world", "box", "--link-dir", str(tmp_path), "--duration", "0.3"])
    out = capsys.readouterr().out
    assert rc == 0
    assert f"robot URL: serial://{tmp_path}/base?lidar={tmp_path}/rplidar" in out
    assert "/dev/pts/" in out
    assert not os.path.exists(tmp_path / "base")  # closed (unplugged) on exit


def test_emulate_rplidar_alone(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["emulate", "rplidar", "--world", "box", "--link-dir", str(tmp_path), "--duration", "0.2"]) == 0
    )
    assert f"lidar: {tmp_path}/rplidar" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["emulate", "base", "--world", "nowhere"], "unknown world"),
        (["emulate", "base", "--profile", "nope"], "unknown profile"),
        (["emulate", "base", "--world", "box", "--drop-prob", "1.5"], "--drop-prob"),
    ],
)
def test_user_errors_are_one_line(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "--duration", "0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
