"""``POST /api/runs/import``: a recorded bag becomes a run (issue 21), on the real Intel slice."""

from __future__ import annotations

import dataclasses
import io
import math
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_bags import NOETIC, ROS1, rewrite_ros1

from robot.logs.bag_convert import strip_definitions, to_ros2


def upload(client, path: Path, name: str | None = None):
    with path.open("rb") as f:
        return client.post(
            "/api/runs/import", files={"file": (name or path.name, f, "application/octet-stream")}
        )


def wait_job(client, job_id: int, timeout: float = 300.0) -> dict:
    deadline = time.monotonic() + timeout  # a generous bound for a loaded machine, not a speed check
    while time.monotonic() < deadline:
        job = client.get(f"/api/runs/import/{job_id}").json()
        if job["state"] in ("done", "failed"):
            return job
        time.sleep(0.1)
    raise AssertionError(f"import {job_id} did not finish: {job}")


def with_commands_and_log(topic: str, typ: str, msg, t: int):
    """The Intel slice plus a /cmd_vel at every odometry message (vx = 0.3, wz = -0.2 after 20 s)
    and one WARN and one INFO /rosout line."""
    yield topic, typ, msg, t
    if topic == "/odom":
        twist = NOETIC.types["geometry_msgs/msg/Twist"]
        vec = NOETIC.types["geometry_msgs/msg/Vector3"]
        late = t - 976052857_337283969 > 20_000_000_000
        yield (
            "/cmd_vel",
            "geometry_msgs/msg/Twist",
            twist(vec(0.3, 0.0, 0.0), vec(0.0, 0.0, -0.2 if late else 0.1)),
            t,
        )
    if topic == "/tf_static":
        log = NOETIC.types["rosgraph_msgs/msg/Log"]
        for level, text in ((4, "laser timeout, reconnecting"), (2, "all good")):
            yield (
                "/rosout",
                "rosgraph_msgs/msg/Log",
                log(msg.transforms[0].header, level, "/driver", text, "", "", 0, []),
                t,
            )


def test_a_ros1_bag_becomes_a_run_with_map_scans_and_replay(client) -> None:
    r = upload(client, ROS1)
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"])
    assert job["state"] == "done", job
    assert job["scans_done"] == job["scans_total"] == 205
    assert "scan topic: /base_scan (the only LaserScan topic)" in job["notes"]
    rid = job["run_id"]
    runs = client.get("/api/runs").json()
    assert [x["id"] for x in runs["items"]] == [rid]
    run = client.get(f"/api/runs/{rid}").json()
    assert run["outcome"] == "completed" and run["kind"] == "mapping"
    assert run["started_at"].startswith("2000-12-05T21:47:37.3375")  # the first scan's stamp
    assert math.isclose(run["duration_s"], 39.8, abs_tol=0.1)
    assert run["maps"] == 1 and run["scans"] >= 70  # 2 Hz over 40 s
    assert run["summary"]["imported"]["file"] == ROS1.name and run["summary"]["imported"]["scans"] == 205
    assert run["summary"]["laser_pose"] == [0.0, 0.0, 0.0] and run["summary"]["samples"] == 399
    assert run["summary"]["distance_m"] > 0.5  # the robot moved (odometry integrated)
    traj = client.get(f"/api/runs/{rid}/trajectory").json()
    assert traj["count"] == 399 and traj["map"]["image_url"].endswith("map.png")
    assert client.get(f"/api/runs/{rid}/map.png").headers["content-type"] == "image/png"
    state = client.get(f"/api/runs/{rid}/state?t=20").json()
    assert len(state["scan"]["points"]) > 50 and state["mode"] == "mapping"
    replay = client.post("/api/replay", json={"action": "load", "run_id": rid}).json()
    assert replay["run_id"] == rid and math.isclose(replay["duration"], 39.8, abs_tol=0.1)


def test_commands_and_warnings_of_the_bag_are_kept(client, tmp_path) -> None:
    bag = rewrite_ros1(ROS1, tmp_path / "cmd.bag", with_commands_and_log)
    job = wait_job(client, upload(client, bag).json()["id"])
    assert job["state"] == "done", job
    rid = job["run_id"]
    run = client.get(f"/api/runs/{rid}").json()
    logs = [e for e in run["events"] if e["type"] == "log"]
    assert [e["msg"] for e in logs] == ["laser timeout, reconnecting"] and logs[0]["level"] == 4
    assert run["summary"]["imported"]["commands"] is True
    early = client.get(f"/api/runs/{rid}/state?t=10").json()["command"]
    late = client.get(f"/api/runs/{rid}/state?t=30").json()["command"]
    assert np.allclose(early, [0.3, 0.0, 0.1], atol=1e-6) and np.allclose(late, [0.3, 0.0, -0.2], atol=1e-6)


def test_a_zipped_humble_folder_without_definitions_imports(client, tmp_path) -> None:
    bag = tmp_path / "tb4_run"
    to_ros2(ROS1, bag)
    strip_definitions(bag)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for p in bag.iterdir():
            z.write(p, f"tb4_run/{p.name}")
    r = client.post("/api/runs/import", files={"file": ("tb4_run.zip", buf.getvalue(), "application/zip")})
    job = wait_job(client, r.json()["id"])
    assert job["state"] == "done", job
    assert any("decoded with the ROS 2 Humble (the bag's ros_distro) typestore" in n for n in job["notes"])


@pytest.mark.parametrize(
    ("name", "body", "says"),
    [
        ("notes.txt", b"hello", "not a bag"),
        ("empty.bag", b"", "the upload is empty"),
        ("fake.mcap", b"#ROSBAG V2.0\n", "not a .mcap file"),
        ("broken.zip", b"PK\x03\x04garbage", "not a readable archive"),
    ],
)
def test_what_is_not_a_bag_is_a_422_problem_and_no_run(client, name, body, says) -> None:
    r = client.post("/api/runs/import", files={"file": (name, body, "application/octet-stream")})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    assert says in r.json()["detail"] and r.json()["type"].endswith("/not-a-bag")
    assert client.get("/api/runs").json()["total"] == 0


def test_a_bag_without_scans_fails_with_one_line_and_leaves_no_run(client, tmp_path) -> None:
    def no_scan(topic: str, typ: str, msg, t: int):
        if topic != "/base_scan":
            yield topic, typ, msg, t

    job = wait_job(client, upload(client, rewrite_ros1(ROS1, tmp_path / "noscan.bag", no_scan)).json()["id"])
    assert job["state"] == "failed" and job["run_id"] is None
    assert job["error"].startswith("noscan.bag: no sensor_msgs/LaserScan topic in the bag")
    assert client.get("/api/runs").json()["total"] == 0
    r = client.get("/api/runs/import/999")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_a_finished_run_keeps_the_summary_it_was_created_with(client) -> None:
    """``RunsStore.finish`` replaced the whole summary: the laser pose a replay places scans with was lost."""
    store = client.app.state.runtime.features["recording"].store
    rid = store.create_run("teleop", summary={"laser_pose": [0.1, 0.0, 1.5]})
    store.finish(rid, "completed")
    assert store.run(rid)["summary"]["laser_pose"] == [0.1, 0.0, 1.5]


def with_map_and_localization(topic: str, typ: str, msg, t: int):
    """The Intel slice as a robot that localized itself in its own map: /tf map -> odom at
    (1, 2, 0.5 rad) beside every odom -> base_link, and one 40 x 30 /map."""
    if topic == "/tf":
        tr = msg.transforms[0]
        v, q = tr.transform.translation, tr.transform.rotation
        loc = dataclasses.replace(
            tr,
            header=dataclasses.replace(tr.header, frame_id="map"),
            child_frame_id="odom",
            transform=dataclasses.replace(
                tr.transform,
                translation=dataclasses.replace(v, x=1.0, y=2.0, z=0.0),
                rotation=dataclasses.replace(q, x=0.0, y=0.0, z=math.sin(0.25), w=math.cos(0.25)),
            ),
        )
        msg = dataclasses.replace(msg, transforms=[tr, loc])
    yield topic, typ, msg, t
    if topic == "/tf_static":
        T = NOETIC.types
        header = T["std_msgs/msg/Header"](0, msg.transforms[0].header.stamp, "map")
        origin = T["geometry_msgs/msg/Pose"](
            T["geometry_msgs/msg/Point"](-5.0, -3.0, 0.0),
            T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
        )
        info = T["nav_msgs/msg/MapMetaData"](header.stamp, 0.25, 40, 30, origin)
        data = np.full(40 * 30, -1, dtype=np.int8)
        data[:40] = 100  # the bottom row is a wall
        yield "/map", "nav_msgs/msg/OccupancyGrid", T["nav_msgs/msg/OccupancyGrid"](header, info, data), t


def test_a_bag_with_its_own_map_and_localization_keeps_them(client, tmp_path) -> None:
    bag = rewrite_ros1(ROS1, tmp_path / "localized.bag", with_map_and_localization)
    job = wait_job(client, upload(client, bag).json()["id"])
    assert job["state"] == "done", job
    assert "map: the bag's own (/map and /tf map -> odom); no SLAM run" in job["notes"]
    rid = job["run_id"]
    traj = client.get(f"/api/runs/{rid}/trajectory").json()
    assert (
        traj["map"]["width"] == 40
        and traj["map"]["height"] == 30
        and traj["map"]["origin"][:2] == [-5.0, -3.0]
    )
    s = traj["samples"]
    odom = np.column_stack((s["ox"], s["oy"], s["otheta"]))
    c, sn = math.cos(0.5), math.sin(0.5)
    want_x = 1.0 + c * odom[:, 0] - sn * odom[:, 1]
    want_y = 2.0 + sn * odom[:, 0] + c * odom[:, 1]
    assert np.allclose(s["x"], want_x, atol=5e-4) and np.allclose(s["y"], want_y, atol=5e-4)
    run = client.get(f"/api/runs/{rid}").json()
    assert run["summary"]["imported"]["map"] == "recorded /map" and "nodes" not in run["summary"]["imported"]
