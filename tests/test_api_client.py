"""The Python client (app/client.py) drives a whole mission against a real embedded server, using
nothing but the client (issue 22 "done when"): map import and activation, initial pose, waypoints,
cancel, e-stop, reset, run export, teleop over the websocket; and a mission outlives its client.

The server runs on a ``VirtualClock`` (the simulator's clock option): the control loop advances time
one period per tick, so "60 s with no client" is 60 s of robot time, whatever the machine's load.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import make_settings

from app.client import ApiError, NavdeckClient
from app.embedded import EmbeddedServer, serve_in_thread
from app.features.missions import MissionState
from app.runtime import Runtime
from robot.clock import VirtualClock

START = (3.0, 3.5, 0.0)  # the apartment world's start pose
FAR = [(7.0, 4.0, 0.0), (3.0, 1.2, 0.0)]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    settings = make_settings(tmp_path_factory.mktemp("client"))
    with serve_in_thread(settings, Runtime.build(settings, clock=VirtualClock())) as srv:
        yield srv


@pytest.fixture(scope="module")
def nd(server: EmbeddedServer) -> NavdeckClient:
    return NavdeckClient(server.url, timeout_s=60.0)


def _world_copy(nd: NavdeckClient, tmp: Path) -> Path:
    """The active (world) map as map_saver files, as a fleet tool would keep them."""
    active = next(m for m in nd.maps(limit=500).items if m.active)
    yaml, pgm = nd.export_map(active.id)
    (tmp / "flat.yaml").write_bytes(yaml)
    (tmp / "map.pgm").write_bytes(pgm)
    return tmp / "flat.yaml"


def test_a_full_mission_using_only_the_client(nd: NavdeckClient, tmp_path: Path) -> None:
    # map import (the same files twice: two maps told apart by name) and activation
    path = _world_copy(nd, tmp_path)
    first = nd.import_map(path)
    second = nd.import_map(path)
    assert first.name == "flat" and second.name == "flat (2)" and first.id != second.id
    activated = nd.activate_map(first.id)
    assert activated.active_map_id == first.id and activated.match_score is not None
    assert activated.match_score >= 0.3
    page = nd.maps(limit=500)
    assert page.active_map_id == first.id and [m.id for m in page.items if m.active] == [first.id]
    with pytest.raises(ApiError) as refused:
        nd.delete_map(first.id)  # the active map cannot go
    assert refused.value.status == 409 and refused.value.kind == "active-map"
    nd.delete_map(second.id)

    # initial pose: the answer is the filter's state after it weighed a scan there
    loc = nd.set_initial_pose(*START)
    assert loc.map_id == first.id and loc.particles > 0 and loc.updates > 0
    assert loc.localized and loc.converged and not loc.map_mismatch
    assert math.hypot(loc.pose.x - START[0], loc.pose.y - START[1]) < 0.3

    # waypoints, then cancel
    m = nd.start_mission(FAR)
    assert m.state == MissionState.ACCEPTED and len(m.goals) == 2
    m = nd.wait_mission(m.id, until=frozenset({MissionState.ACTIVE}), timeout_s=120)
    m = nd.cancel_mission(m.id)
    assert m.state in (MissionState.CANCELING, MissionState.CANCELED)
    m = nd.wait_mission(m.id, timeout_s=120)
    assert m.state == MissionState.CANCELED and m.cancel is not None
    assert m.cancel.reason == "operator_cancel"

    # e-stop ends the next mission with its own reason; reset gives the robot back
    m = nd.start_mission(FAR)
    nd.wait_mission(m.id, until=frozenset({MissionState.ACTIVE}), timeout_s=120)
    robot = nd.estop()
    assert robot.mode == "estop" and robot.estop
    m = nd.wait_mission(m.id, timeout_s=120)
    assert m.state == MissionState.CANCELED and m.cancel is not None and m.cancel.reason == "estop"
    with pytest.raises(ApiError) as not_now:
        nd.start_mission(FAR)
    assert not_now.value.status == 409 and not_now.value.kind == "navigation-refused"
    robot = nd.reset()
    assert robot.mode == "idle" and not robot.estop

    # the runs of both missions, exported
    runs = nd.runs(kind="navigation")
    assert runs.total >= 1 and runs.items[0].kind == "navigation"
    exported = json.loads(nd.export_run(runs.items[0].id, "json"))
    assert exported["run"]["id"] == runs.items[0].id

    # teleop over the websocket: this socket drives, closing it stops the robot (the deadman)
    with nd.teleop("client-test") as drive:
        assert drive.hello["type"] == "hello"
        control = drive.take_control()
        assert control["driving"] is True
        deadline = time.monotonic() + 30
        while nd.robot().mode != "teleop" and time.monotonic() < deadline:
            drive.send(0.0)  # a zero first arms teleop (re-arm after the reset)
            drive.send(0.15)
            time.sleep(0.1)
        assert nd.robot().mode == "teleop"
    deadline = time.monotonic() + 30
    while nd.robot().command.linear.x != 0.0 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert nd.robot().command.linear.x == 0.0


def test_a_mission_survives_60_s_with_no_client(server: EmbeddedServer, nd: NavdeckClient) -> None:
    robot = nd.robot()
    if robot.estop:
        nd.reset()
    if robot.mode != "idle":
        nd.set_mode("idle")
    pose = nd.robot().pose
    nd.set_initial_pose(pose.x, pose.y, pose.theta)
    patrol = FAR * 4  # ~8 legs of 3-5 m: longer than a minute of driving
    m = nd.start_mission(patrol)
    clock = server.runtime.session.clock
    started = clock.now()
    # the client goes away: no request, no socket; its REST lease lapses (the guard's idle sweep)
    server.app.state.guard.sweep(now=1e12)
    assert server.runtime.lease.holder is None
    while clock.now() - started < 60.0:  # robot time (virtual clock), whatever the load
        time.sleep(0.5)
    later = nd.mission(m.id)
    assert later.state in (MissionState.ACTIVE, MissionState.SUCCEEDED), later
    assert later.cancel is None and later.progress.goals_reached >= 2, later.progress
