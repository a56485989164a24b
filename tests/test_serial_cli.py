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


def test_fault_switches_typed_on_stdin(tmp_path) -> None:
    from robot.profiles import load_profile
    from robot.serial.emulate import EmulatorPair
    from robot.serial.rplidar import Health
    from robot.serial.switches import apply_switch

    with EmulatorPair(load_profile("skid4"), world="box", link_dir=tmp_path) as pair:
        assert pair.lidar is not None
        devices = {"base": pair.base, "lidar": pair.lidar}
        assert apply_switch("unplug lidar", devices) == "unplug: lidar"
        assert not os.path.exists(tmp_path / "rplidar") and os.path.exists(tmp_path / "base")
        assert apply_switch("replug", devices) == "replug: base, lidar"
        assert os.path.exists(tmp_path / "rplidar")
        assert "0x8021" in apply_switch("health 0x8021", devices)
        assert pair.lidar.health == Health(2, 0x8021)
        apply_switch("health ok", devices)
        assert pair.lidar.health == Health(0, 0)
        apply_switch("stall base", devices)
        assert pair.base.faults.stall and not pair.lidar.faults.stall
        apply_switch("resume", devices)
        assert not pair.base.faults.stall
        assert apply_switch("drop 0.01 lidar", devices) == "drop 0.01: lidar"
        assert pair.lidar.faults.drop_prob == 0.01 and pair.base.faults.drop_prob == 0.0
        for bad, answer in (
            ("drop 2", "must be in [0, 1)"),
            ("unplug wheel", "no emulated device 'wheel'"),
            ("health x", "not a number"),
            ("fly", "unknown command"),
        ):
            assert answer in apply_switch(bad, devices)
        assert apply_switch("   ", devices) == ""
