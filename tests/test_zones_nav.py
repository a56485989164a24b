"""Zones at work in the simulated robot (virtual clock): navigation goes around a keepout zone drawn
across its shortest route; a speed zone limits teleop and the navigator, says why, and entering and
leaving it are run events (issue 19)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from conftest import make_settings

from app.api.ws_schema import ZonesMsg
from app.features import localization, navigation, zones
from app.modes import Mode
from app.runtime import Runtime
from app.telemetry import snapshot_dict
from app.zone_store import SpeedUnit, ZoneKind, ZoneSpec
from nav.costmap.filter_layer import points_in_polygon
from nav.types import Pose2D, Twist2D
from robot.clock import VirtualClock

GOAL = Pose2D(0.8, 3.5, math.pi)
# across the straight line start -> goal, from the north wall down to y = 2.9: the way is below it
KEEPOUT = [[2.0, 2.9], [2.4, 2.9], [2.4, 4.95], [2.0, 4.95]]


def runtime(tmp_path: Path):
    rt = Runtime.build(make_settings(tmp_path), clock=VirtualClock())
    rt.setup_features((localization, navigation, zones))
    return rt


def add_zone(rt, spec: ZoneSpec) -> None:
    z = rt.features["zones"]
    z.store.add(z.map_id, spec)
    z.reload(z.map_id)


def test_navigation_goes_around_a_keepout_zone(tmp_path: Path) -> None:
    rt = runtime(tmp_path)
    try:
        rt.on_pose_input("initial_pose", Pose2D(3.0, 3.5, 0.0))
        add_zone(rt, ZoneSpec("wet floor", ZoneKind.KEEPOUT, KEEPOUT))
        rt.on_pose_input("goal", GOAL)
        assert rt.session.modes.mode == Mode.NAVIGATING
        nav = rt.features["navigation"]
        poses = []
        for _ in range(1200):  # 60 s of virtual time at most
            rt.session.run_for(0.05)
            poses.append((rt.session.driver.truth_pose.x, rt.session.driver.truth_pose.y))
            if not nav.active:
                break
        assert nav.last_outcome is not None and nav.last_outcome["kind"] == "reached", nav.last_outcome
        xy = np.array(poses)
        assert not points_in_polygon(xy, np.array(KEEPOUT)).any()
        assert xy[:, 1].min() < 2.9  # it went around the zone's south end
        assert not [e for e in rt.session.events if e["type"] == "zone"]  # never entered
    finally:
        rt.close()


def test_a_speed_zone_limits_teleop_and_says_why(tmp_path: Path) -> None:
    rt = runtime(tmp_path)
    try:
        square = [[2.5, 3.0], [3.1, 3.0], [3.1, 4.0], [2.5, 4.0]]  # around the start (3.0, 3.5)
        add_zone(rt, ZoneSpec("aisle", ZoneKind.SPEED, square, 30.0, SpeedUnit.PERCENT))
        rt.session.modes.request(Mode.TELEOP)
        top = rt.session.profile.limits.max_vel_x
        inside_speeds, outside_speeds, measured = [], [], []
        for _ in range(60):  # 3 s east at full speed: out of the zone after 0.1 m
            rt.session.set_teleop(Twist2D(top, 0.0, 0.0), "test")
            before = rt.session.driver.truth_pose
            rt.session.run_for(0.05)
            p = rt.session.driver.truth_pose
            speed = rt.session.last_command.vx
            if points_in_polygon(np.array([[p.x, p.y], [before.x, before.y]]), np.array(square)).all():
                measured.append(p.distance_to(before) / 0.05)  # true speed over the tick, inside
            (
                inside_speeds
                if points_in_polygon(np.array([[p.x, p.y]]), np.array(square))[0]
                else outside_speeds
            ).append(speed)
        limit = 0.3 * top
        assert inside_speeds and max(inside_speeds) <= limit + 1e-9
        assert measured and max(measured) <= limit + 0.02  # the measure, on the simulated base
        assert outside_speeds and max(outside_speeds) > limit + 0.05  # no limit once out
        kinds = [(e["action"], e["name"]) for e in rt.session.events if e["type"] == "zone"]
        assert kinds == [("enter", "aisle"), ("leave", "aisle")]
    finally:
        rt.close()


def test_telemetry_names_the_speed_limit_and_its_zone(tmp_path: Path) -> None:
    rt = runtime(tmp_path)
    try:
        square = [[2.5, 3.0], [3.5, 3.0], [3.5, 4.0], [2.5, 4.0]]
        add_zone(rt, ZoneSpec("aisle", ZoneKind.SPEED, square, 0.1, SpeedUnit.MPS))
        rt.session.modes.request(Mode.TELEOP)
        for _ in range(20):  # 1 s: the acceleration ramp is over
            rt.session.set_teleop(Twist2D(0.2, 0.0, 0.25), "test")
            rt.session.run_for(0.05)
        out = snapshot_dict(rt.session.bus.latest, "test")
        ZonesMsg.model_validate(out["zones"])  # the telemetry schema (/api/schemas/ws/telemetry.json)
        limit = out["zones"]["speed_limit"]
        assert limit["linear"] == 0.1 and "aisle" in limit["reason"]
        assert "speed_limit" in out["clamped"]
        ((kind, label, vertices),) = rt.session.bus.latest.extras["zone_layer"]  # the 3D view's layer
        assert kind == "speed" and label == "aisle (0.1 m/s)" and vertices.shape == (4, 2)
        cmd = rt.session.last_command
        assert math.hypot(cmd.vx, cmd.vy) <= 0.1 + 1e-9
        assert abs(cmd.wz / cmd.vx - 1.25) < 1e-9  # the same arc as asked
    finally:
        rt.close()
