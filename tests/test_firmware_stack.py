"""Full stack on the C firmware: ``navdeck serve --robot serial://...`` with the host build of the
firmware core as the base (its own process, on a pseudo-terminal) and the emulated RPLidar A1.

Teleop drives the C base through the real websocket, server, session and SerialDriver; pulling the
cable faults the robot, replugging and a reset recover it. The lidar emulator stands still in its own
simulated room (the C base has its own plant), which is all these tests need from it: scans arrive.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from conftest import teleop_until, twist
from websockets.sync.client import connect

from app.embedded import EmbeddedServer, serve_in_thread
from app.settings import Settings
from robot.firmware.build import CompilerMissingError, build
from robot.firmware.host_base import HostFirmwareBase
from robot.profiles import load_profile
from robot.serial.driver import wait_for
from robot.serial.emulate import EmulatorPair

PROFILE = load_profile("skid4")

# The server imports most modules as it starts; an import holds the GIL long enough to starve the
# in-process lidar emulator on a loaded machine (see tests/test_hardware_stack.py). Import first.
for _package in ("app", "nav", "robot"):
    for _module in pkgutil.walk_packages(importlib.import_module(_package).__path__, f"{_package}."):
        importlib.import_module(_module.name)


@pytest.fixture(scope="module", autouse=True)
def _built() -> None:
    try:
        build("navdeck_fw_host")
    except CompilerMissingError as exc:
        pytest.skip(f"the host firmware needs a C compiler: {exc}")


@pytest.fixture
def fw(tmp_path: Path) -> Iterator[HostFirmwareBase]:
    with HostFirmwareBase(PROFILE, link_dir=tmp_path / "dev") as base:
        yield base


@pytest.fixture
def server(tmp_path: Path, fw: HostFirmwareBase) -> Iterator[EmbeddedServer]:
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path / "lidar", seed=3) as lidar_only:
        # a 1 s link timeout: the cable pull must fault at once (a vanished port), not a starved thread
        url = f"{fw.url()}?lidar={lidar_only.lidar_path}&link_timeout=1.0&lidar_timeout=3.0"
        settings = Settings(
            data_dir=tmp_path, db_url=f"sqlite:///{tmp_path / 'navdeck.db'}", viewer=False, robot=url
        )
        with serve_in_thread(settings) as srv:
            assert wait_for(lambda: srv.runtime.session.last_scan is not None, timeout=10.0)
            yield srv


def test_teleop_drives_the_c_base_unplug_faults_replug_recovers(
    fw: HostFirmwareBase, server: EmbeddedServer
) -> None:
    session = server.runtime.session
    with connect(f"{server.ws_url}/ws/teleop") as ws:
        assert json.loads(ws.recv(timeout=10))["type"] == "hello"
        # odometry from the C firmware's encoder counts: straight ahead
        assert teleop_until(ws, lambda: session.odom_pose.x > 0.2, vx=0.2), session.fault
        assert session.fault is None, session.fault
        assert abs(session.odom_pose.y) < 0.02 and abs(session.odom_pose.theta) < 0.05, session.odom_pose
        assert session.health()["link"] == "ok"
        ws.send(twist(vx=0.2))
        assert wait_for(lambda: session.modes.mode.value == "teleop", timeout=2.0), session.fault

        fw.unplug()
        assert wait_for(lambda: session.modes.mode.value == "fault", timeout=3.0, period=0.005)
        assert session.fault is not None and fw.path in session.fault
        assert session.link_state.value == "lost"
        r = httpx.post(f"{server.url}/api/robot/reset", timeout=10)
        assert r.status_code == 409  # refused while the port is gone

        fw.replug()
        assert wait_for(lambda: session.link_state.value == "ok", timeout=5.0)
        assert session.modes.mode.value == "fault"  # latched until the operator resets
        r = httpx.post(f"{server.url}/api/robot/reset", timeout=10)
        assert r.status_code == 200, r.text
        assert r.json()["mode"] == "idle" and r.json()["fault"] is None
        # drives again on a fresh command (the key released first: a reset re-arms, never moves)
        ws.send(twist())
        before = session.odom_pose.x
        assert teleop_until(ws, lambda: session.odom_pose.x - before > 0.08, vx=0.2), session.fault
        assert session.fault is None, session.fault
