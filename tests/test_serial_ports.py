"""``navdeck ports``: the emulated base and RPLidar on pseudo-terminals are told apart by a read-only
probe that starts no scan and commands no motion; a pty with nothing behind it is "unknown", a port
held by another program is "unavailable" (busy)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from app.cli import main
from robot.profiles import load_profile
from robot.serial.emulate import EmulatorPair
from robot.serial.port import open_port
from robot.serial.probe import LIDAR_MOTION_REQUESTS, _param_get_frame, list_devices, probe
from robot.serial.protocol import MessageDecoder, ParamGet, VelocityCommand
from robot.serial.rplidar import Cmd, request

PROFILE = load_profile("skid4")


@pytest.fixture
def pair(tmp_path: Path):
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path / "dev", seed=1) as p:
        yield p


def test_ports_tells_the_base_from_the_lidar_without_motion(pair: EmulatorPair, capsys) -> None:
    assert main(["ports", pair.lidar_path, pair.base_path, "--json"]) == 0
    rows = {r["device"]: r for r in json.loads(capsys.readouterr().out)["ports"]}
    assert rows[pair.base_path]["probe"]["kind"] == "base"
    assert rows[pair.lidar_path]["probe"]["kind"] == "rplidar"
    assert "model 0x18" in rows[pair.lidar_path]["probe"]["detail"]
    assert rows[pair.base_path]["vid_pid"] is None  # a pty is no USB device
    # read-only: the lidar was asked for its health and info, never to scan or reset
    assert Cmd.GET_HEALTH in pair.lidar.requests and Cmd.GET_INFO in pair.lidar.requests
    assert not set(pair.lidar.requests) & {int(c) for c in LIDAR_MOTION_REQUESTS}
    assert not pair.lidar.scanning
    # the base streams telemetry by itself: it was sent nothing, in particular no velocity
    assert not [m for _, m in pair.base.message_log if isinstance(m, VelocityCommand)]


def test_a_base_that_is_not_listened_to_answers_param_get(pair: EmulatorPair) -> None:
    found = probe(pair.base_path, listen=0.0)  # skip the listening step: the PARAM_GET fallback
    assert found.kind == "base" and "PARAM_GET" in found.detail
    sent = [m for _, m in pair.base.message_log]
    assert sent and all(isinstance(m, ParamGet) for m in sent)


def test_param_get_frame_is_a_valid_frame_and_no_lidar_motion_request() -> None:
    frame = _param_get_frame()
    assert [type(m) for m in MessageDecoder().feed(frame)] == [ParamGet]
    for cmd in LIDAR_MOTION_REQUESTS:
        assert request(cmd) not in frame


def test_silent_and_busy_ports(pair: EmulatorPair, capsys) -> None:
    master, slave = os.openpty()  # a terminal nobody answers on
    try:
        silent = os.ttyname(slave)
        held = open_port(pair.base_path, 115200)  # a running server holds the base port
        try:
            assert main(["ports", silent, pair.base_path, "--listen", "0.2"]) == 0
        finally:
            held.close()
        out = capsys.readouterr().out
        assert f"{silent}: not USB" in out and "-> unknown:" in out
        assert "-> unavailable:" in out and "busy" in out and "navdeck serve" in out
    finally:
        os.close(master)
        os.close(slave)


def test_listing_without_probing_opens_nothing(pair: EmulatorPair, capsys) -> None:
    assert main(["ports", pair.lidar_path, "--no-probe", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["ports"]
    assert row["probe"] is None and row["device"] == pair.lidar_path
    assert pair.lidar.requests == []


def test_by_id_links_are_reported(tmp_path: Path, pair: EmulatorPair, monkeypatch) -> None:
    by_id = tmp_path / "by-id"
    by_id.mkdir()
    (by_id / "usb-Silicon_Labs_CP2102-if00-port0").symlink_to(pair.lidar_path)
    monkeypatch.setattr("robot.serial.probe.BY_ID_DIR", by_id)
    (dev,) = list_devices([pair.lidar_path])
    assert dev.by_id == [str(by_id / "usb-Silicon_Labs_CP2102-if00-port0")]
