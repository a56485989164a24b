"""Runs API against a real app (simulated robot, temporary SQLite): listing with filters and
pagination, detail, trajectory, bad input, exports (MCAP read back with mcap + mcap_ros2), delete."""

from __future__ import annotations

import csv
import io
import math
import time
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from bench.runs import synth_run

T0 = datetime(2026, 3, 1, 12, 0, tzinfo=UTC)


@pytest.fixture
def store(client):
    return client.app.state.runtime.features["recording"].store


@pytest.fixture
def runs(client, store) -> dict[str, int]:
    """Five finished runs on three days and one still recording."""
    grid = client.app.state.runtime.session.grid
    ids = {
        "nav_ok": synth_run(store, duration_s=12.0, started_at=T0, map_id=1, grid=grid, outcome="succeeded",
                            events=[{"t": 2.0, "type": "goal", "pose": [1.0, 0.0, 0.0]},
                                    {"t": 5.0, "type": "estop", "reason": "operator"}],
                            goals=[{"t": 2.0, "x": 1.0, "y": 0.0, "theta": 0.0, "outcome": "succeeded"}]),
        "nav_fail": synth_run(store, duration_s=3.0, started_at=T0 + timedelta(hours=1), map_id=2,
                              outcome="failed"),
        "map": synth_run(store, kind="mapping", duration_s=3.0, started_at=T0 + timedelta(days=1), map_id=1),
        "tele1": synth_run(store, kind="teleop", duration_s=2.0, started_at=T0 + timedelta(days=2)),
        "tele2": synth_run(store, kind="teleop", duration_s=2.0, started_at=T0 + timedelta(days=2, hours=1)),
        "live": synth_run(store, kind="teleop", duration_s=2.0, started_at=T0 + timedelta(days=3),
                          outcome=None),
    }  # fmt: skip
    return ids


def ids_of(resp) -> list[int]:
    assert resp.status_code == 200, resp.text
    return [r["id"] for r in resp.json()["items"]]


def test_list_is_newest_first_and_paginates(client, runs) -> None:
    body = client.get("/api/runs?limit=4").json()
    order = ["live", "tele2", "tele1", "map", "nav_fail", "nav_ok"]
    assert body["total"] == 6 and [r["id"] for r in body["items"]] == [runs[k] for k in order[:4]]
    assert ids_of(client.get("/api/runs?limit=4&offset=4")) == [runs[k] for k in order[4:]]
    assert ids_of(client.get("/api/runs?offset=10")) == []


def test_list_filters(client, runs) -> None:
    assert ids_of(client.get("/api/runs?kind=navigation")) == [runs["nav_fail"], runs["nav_ok"]]
    assert ids_of(client.get("/api/runs?outcome=failed")) == [runs["nav_fail"]]
    assert ids_of(client.get("/api/runs?map_id=1")) == [runs["map"], runs["nav_ok"]]
    assert ids_of(client.get("/api/runs?kind=teleop&outcome=recording")) == [runs["live"]]
    assert ids_of(client.get("/api/runs?since=2026-03-03")) == [runs["live"], runs["tele2"], runs["tele1"]]
    assert ids_of(client.get("/api/runs?until=2026-03-01")) == [
        runs["nav_fail"],
        runs["nav_ok"],
    ]  # inclusive day
    assert ids_of(client.get("/api/runs?since=2026-03-01T12:30:00Z&until=2026-03-02T23:00:00Z")) == [
        runs["map"],
        runs["nav_fail"],
    ]
    assert ids_of(client.get("/api/runs?robot=nobody")) == []


@pytest.mark.parametrize(
    ("query", "field"),
    [
        ("since=yesterday", "since"),
        ("until=2026-13-01", "until"),
        ("kind=flying", "kind"),
        ("outcome=great", "outcome"),
        ("map_id=abc", "map_id"),
        ("limit=0", "limit"),
        ("offset=-1", "offset"),
        ("since=2026-03-02&until=2026-03-01T00:00:00", "until"),
    ],
)
def test_bad_filters_are_422_naming_the_field(client, query, field) -> None:
    r = client.get(f"/api/runs?{query}")
    assert r.status_code == 422
    assert [e["field"] for e in r.json()["errors"]] == [field]
    assert field in r.json()["detail"]


def test_unknown_run_is_404_everywhere(client) -> None:
    for path in ("", "/trajectory", "/map.png", "/state?t=1", "/export.mcap", "/export.json", "/export.csv"):
        r = client.get(f"/api/runs/9999{path}")
        assert r.status_code == 404, path
        assert "9999" in r.json()["detail"]
    assert client.delete("/api/runs/9999").status_code == 404


def test_recording_run_exports_as_partial_but_cannot_be_deleted(client, runs) -> None:
    """Issue 17 item 11: a run still recording is exported as recorded so far, flagged partial."""
    rid = runs["live"]
    for fmt in ("mcap", "json", "csv"):
        r = client.get(f"/api/runs/{rid}/export.{fmt}")
        assert r.status_code == 200, (fmt, r.text[:200])
        assert r.headers["x-run-partial"] == "true" and "-partial." in r.headers["content-disposition"]
        done = client.get(f"/api/runs/{runs['tele1']}/export.{fmt}")
        assert done.status_code == 200 and done.headers["x-run-partial"] == "false"
    doc = client.get(f"/api/runs/{rid}/export.json").json()
    assert doc["partial"] is True and doc["run"]["outcome"] == "recording" and len(doc["samples"]["t"]) == 20
    assert client.get(f"/api/runs/{runs['tele1']}/export.json").json()["partial"] is False
    reader = make_reader(io.BytesIO(client.get(f"/api/runs/{rid}/export.mcap").content))
    (meta,) = [m for m in reader.iter_metadata() if m.name == "navdeck_run"]
    assert meta.metadata["partial"] == "true" and meta.metadata["outcome"] == "recording"
    assert float(meta.metadata["recorded_s"]) == pytest.approx(1.9)
    assert client.delete(f"/api/runs/{rid}").status_code == 409


def test_detail_trajectory_state_and_map(client, runs) -> None:
    rid = runs["nav_ok"]
    run = client.get(f"/api/runs/{rid}").json()
    assert run["outcome"] == "succeeded" and run["scans"] == 24 and run["plans"] == 1 and run["maps"] == 1
    assert [e["type"] for e in run["events"]] == ["mode", "goal", "estop"]
    assert run["summary"]["estops"] == 1 and run["summary"]["goals_reached"] == 1
    assert run["summary"]["distance_m"] == pytest.approx(0.225 * 11.9, rel=0.01)  # 0.225 m/s for 11.9 s
    traj = client.get(f"/api/runs/{rid}/trajectory?max_points=50").json()
    assert traj["count"] == 120 and traj["step"] == 3 and len(traj["samples"]["x"]) == 40
    assert traj["map"]["image_url"] == f"/api/runs/{rid}/map.png"
    png = client.get(traj["map"]["image_url"])
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    st = client.get(f"/api/runs/{rid}/state?t=5.04").json()
    assert st["t"] == pytest.approx(5.0) and st["mode"] == "navigating"
    assert st["pose"][0] == pytest.approx(1.5 * math.cos(0.75), abs=1e-4)
    assert len(st["scan"]["points"]) > 300 and st["scan"]["t"] == 5.0
    assert len(st["plan"]["poses"]) == 40
    live = client.get(f"/api/runs/{runs['live']}").json()
    assert live["summary"]["samples"] == 20  # live summary while recording


def test_mcap_export_reads_back_with_ros2_schemas(client, runs) -> None:
    rid = runs["nav_ok"]
    r = client.get(f"/api/runs/{rid}/export.mcap")
    assert r.status_code == 200 and "attachment" in r.headers["content-disposition"]
    reader = make_reader(io.BytesIO(r.content), decoder_factories=[DecoderFactory()])
    summary = reader.get_summary()
    assert summary is not None
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert {t: s.name for t, s in schemas.items()} == {
        "/tf": "tf2_msgs/TFMessage",
        "/tf_static": "tf2_msgs/TFMessage",
        "/odom": "nav_msgs/Odometry",
        "/cmd_vel": "geometry_msgs/Twist",
        "/scan": "sensor_msgs/LaserScan",
        "/plan": "nav_msgs/Path",
        "/goal_pose": "geometry_msgs/PoseStamped",
        "/map": "nav_msgs/OccupancyGrid",
        "/rosout": "rcl_interfaces/Log",
    }
    assert all(s.encoding == "ros2msg" for s in schemas.values())
    assert b"MSG: geometry_msgs/Quaternion" in schemas["/odom"].data
    counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts == {"/tf": 120, "/tf_static": 1, "/odom": 120, "/cmd_vel": 120, "/scan": 24, "/plan": 1,
                      "/goal_pose": 1, "/map": 1, "/rosout": 3}  # fmt: skip
    decoded: dict[str, list] = {}
    for _schema, channel, message, msg in reader.iter_decoded_messages():
        decoded.setdefault(channel.topic, []).append((message.log_time, msg))
    t_odom, odom = decoded["/odom"][50]
    assert odom.header.frame_id == "odom" and odom.child_frame_id == "base_link"
    assert odom.twist.twist.linear.x == pytest.approx(0.225)
    assert odom.pose.pose.position.x == pytest.approx(1.5 * math.cos(0.15 * 5.0), abs=1e-5)
    start_ns = int(T0.timestamp() * 1e9)
    assert t_odom == start_ns + 5_000_000_000
    tf = decoded["/tf"][0][1]
    assert [(x.header.frame_id, x.child_frame_id) for x in tf.transforms] == [
        ("map", "odom"),
        ("odom", "base_link"),
    ]
    scan = decoded["/scan"][3][1]
    assert scan.header.frame_id == "laser" and len(scan.ranges) == 360
    assert math.isinf(max(scan.ranges)) and scan.angle_max == pytest.approx(
        math.pi - 2 * math.pi / 360, abs=1e-6
    )
    grid = client.app.state.runtime.session.grid
    m = decoded["/map"][0][1]
    assert (m.info.width, m.info.height) == (grid.geometry.width, grid.geometry.height)
    assert np.array_equal(np.frombuffer(bytes(np.array(m.data, dtype=np.int8)), np.int8), grid.data.ravel())
    logs = [x[1] for x in decoded["/rosout"]]
    assert [lg.function for lg in logs] == ["mode", "goal", "estop"] and logs[2].level == 30


def test_json_and_csv_exports(client, runs) -> None:
    rid = runs["nav_fail"]
    doc = client.get(f"/api/runs/{rid}/export.json").json()
    assert doc["run"]["outcome"] == "failed" and len(doc["samples"]["t"]) == 30 and "scans" not in doc
    with_scans = client.get(f"/api/runs/{rid}/export.json?scans=true").json()
    assert len(with_scans["scans"]) == 6 and None in with_scans["scans"][0]["ranges"]  # +inf -> null
    text = client.get(f"/api/runs/{rid}/export.csv").text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == 30 and rows[10]["t"] == "1.0" and rows[10]["mode"] == "navigating"
    assert float(rows[10]["vx"]) == pytest.approx(0.225)


def test_delete_removes_run_and_its_data(client, store, runs) -> None:
    rid = runs["tele1"]
    assert client.delete(f"/api/runs/{rid}").status_code == 204
    assert client.get(f"/api/runs/{rid}").status_code == 404
    assert store.samples(rid)[0].shape[0] == 0 and store.scans(rid) == []
    assert client.get("/api/runs").json()["total"] == 5


def test_replay_control_seek_and_bad_input(client, runs) -> None:
    rid = runs["nav_ok"]
    assert client.post("/api/replay", json={"action": "play"}).status_code == 409  # nothing loaded
    assert client.post("/api/replay", json={"action": "load", "run_id": 9999}).status_code == 404
    r = client.post("/api/replay", json={"action": "load"})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "run_id"
    st = client.post("/api/replay", json={"action": "load", "run_id": rid, "t": 4.0}).json()
    assert st["run_id"] == rid and st["t"] == 4.0 and st["duration"] == pytest.approx(11.9)
    player = client.app.state.runtime.features["recording"].replay
    snap = player.bus.latest
    assert snap.stamp == 4.0 and snap.path is not None and snap.scan is not None and snap.grid is not None
    assert snap.pose.x == pytest.approx(1.5 * math.cos(0.6), abs=1e-5)
    r = client.post("/api/replay", json={"action": "speed", "speed": 100})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "speed"
    client.post("/api/replay", json={"action": "speed", "speed": 10})
    client.post("/api/replay", json={"action": "play"})
    deadline = time.monotonic() + 5.0
    while client.get("/api/replay").json()["t"] < 6.0 and time.monotonic() < deadline:
        time.sleep(0.05)
    st = client.post("/api/replay", json={"action": "pause"}).json()
    assert st["t"] >= 6.0 and not st["playing"]
    assert player.bus.latest.stamp > 4.0


def test_export_right_after_mapping_stops_is_partial_then_whole(tmp_path) -> None:
    """The seen case: export.mcap right after stopping mapping answered 409 for the idle grace (10 s).
    Now it is the run so far, flagged partial; once the run has ended the same export is whole."""
    import httpx
    from conftest import make_settings

    from app.embedded import serve_in_thread

    with (
        serve_in_thread(make_settings(tmp_path)) as server,
        httpx.Client(base_url=server.url, timeout=30) as api,
    ):
        assert api.post("/api/mapping/start").status_code == 200
        time.sleep(1.0)
        assert api.post("/api/mapping/stop").status_code == 200
        (run,) = api.get("/api/runs?kind=mapping").json()["items"]
        assert run["outcome"] == "recording"  # the idle grace keeps it open
        r = api.get(f"/api/runs/{run['id']}/export.mcap")
        assert r.status_code == 200 and r.headers["x-run-partial"] == "true"
        reader = make_reader(io.BytesIO(r.content))
        (meta,) = [m for m in reader.iter_metadata() if m.name == "navdeck_run"]
        assert meta.metadata["partial"] == "true" and float(meta.metadata["recorded_s"]) > 0.3
        summary = reader.get_summary()
        assert summary is not None
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert counts["/odom"] >= 3 and counts["/map"] >= 1, counts
        # a new run kind ends this one: the export is whole now
        assert api.post("/api/robot/mode", json={"mode": "teleop"}).status_code == 200
        server.runtime.features["recording"].recorder.sync()
        r = api.get(f"/api/runs/{run['id']}/export.mcap")
        assert r.status_code == 200 and r.headers["x-run-partial"] == "false"
