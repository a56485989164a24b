"""The mapping stage in a simulated session on a virtual clock: teleop loop, map, loop closure."""

from __future__ import annotations

import numpy as np
import pytest

from app.modes import Mode, TransitionRefused
from bench.mapping import (
    APARTMENT_LOOP,
    APARTMENT_START,
    OFFICE_LOOP,
    OFFICE_START,
    MappingDrive,
    build,
    run_mapping,
    seen_wall_cells,
    teleop_loop,
    wall_coverage,
)
from nav.types import Pose2D


@pytest.fixture(scope="module")
def mapped() -> MappingDrive:
    """One closed teleop loop around the apartment's table, mapping all the way (shared, ~10 s)."""
    drive = build("apartment", APARTMENT_START)
    drive.mapping.start()
    teleop_loop(drive, APARTMENT_LOOP)
    snap = drive.session.bus.latest
    drive.mapping.stop()
    drive.last_snapshot = snap  # type: ignore[attr-defined]
    yield drive
    drive.session.close()


def test_walls_of_the_apartment_are_in_the_map(mapped: MappingDrive) -> None:
    grid = mapped.mapping.current_map()
    walls = seen_wall_cells(mapped)
    assert len(walls) > 300
    assert wall_coverage(grid, walls, mapped.start_truth) >= 0.95
    # and the map is not just walls everywhere: free space dominates the known cells
    known = grid.data >= 0
    assert (grid.data[known] <= 25).mean() > 0.6  # map_saver: free below free_thresh 0.25


def test_pose_follows_slam_and_closes_the_loop(mapped: MappingDrive) -> None:
    s = mapped.session
    truth = mapped.driver.truth_pose.relative_to(mapped.start_truth)  # SLAM frame = start pose
    assert s.pose.distance_to(truth) < 0.1
    assert abs(float(np.remainder(s.pose.theta - truth.theta + np.pi, 2 * np.pi) - np.pi)) < 0.05
    assert mapped.mapping.slam.num_loop_closures > 0
    assert s.modes.mode == Mode.IDLE


def test_snapshot_carries_map_trajectory_and_graph(mapped: MappingDrive) -> None:
    snap = mapped.last_snapshot  # type: ignore[attr-defined]
    assert snap.mode == "mapping"
    info = snap.extras["mapping"]
    assert info["running"] and info["nodes"] > 50 and info["map_size_m"][0] > 3.0
    traj = snap.extras["trajectory"]
    assert traj.ndim == 2 and traj.shape[1] == 2 and len(traj) > 10
    assert snap.grid is not None and snap.grid_version > 1
    edges = snap.extras.get("graph_edges")
    assert edges is None or edges.shape[1:] == (2, 2)
    assert mapped.mapping.state()["last_optimization_ms"] is not None
    types = [e.get("status") for e in mapped.session.events if e["type"] == "mapping"]
    assert types == ["started", "stopped"]


def test_map_published_about_once_a_second() -> None:
    drive = build("apartment", APARTMENT_START)
    try:
        s = drive.session
        drive.mapping.start()
        versions = []
        for _ in range(40):  # 4 s
            s.run_for(0.1)
            versions.append(s.grid_version)
        changes = np.count_nonzero(np.diff(versions))
        assert 3 <= changes <= 5
    finally:
        drive.session.close()


def test_mode_rules_and_an_estop_pauses_mapping() -> None:
    drive = build("apartment", APARTMENT_START)
    try:
        s, m = drive.session, drive.mapping
        with pytest.raises(Exception, match="no map"):
            m.current_map()
        m.start()
        s.run_for(1.0)
        assert m.running and m.slam.num_nodes >= 1
        s.estop("test")
        s.run_for(0.1)
        assert not m.running  # the tick noticed the mode change and finished the session
        nodes = m.slam.num_nodes
        m.current_map()  # the map is kept
        with pytest.raises(TransitionRefused):
            m.start()  # ESTOP only leaves through reset
        s.reset()
        m.start()  # after E-STOP + reset, mapping resumes the interrupted session's map
        assert m.running and m.generation == 1 and m.slam.num_nodes >= nodes
        assert [e["status"] for e in s.events if e["type"] == "mapping"][-1] == "resumed"
        m.stop()
        s.request_mode("mapping")  # MAPPING through the plain mode API maps from scratch after a stop
        s.run_for(0.1)
        assert m.running and m.generation == 2
    finally:
        drive.session.close()


def test_loop_closure_corrects_injected_odometry_drift() -> None:
    """The front end is made to trust odometry (no search window, a stiff prior: as in a featureless
    corridor) and odometry drifts by 1 deg of heading per metre. Only loop closure against the first
    submaps can pull the end pose back towards the truth."""
    from dataclasses import replace

    from nav.slam.system import SlamOptions

    drive = build("apartment", APARTMENT_START)
    drive.mapping.slam_options = SlamOptions(
        linear_search_window=1e-3,
        angular_search_window=1e-3,
        angular_search_step=1e-3,
        translation_weight=1e5,
        rotation_weight=1e5,
        # loop closure alone is under test: the degenerate-direction fusion (issue 16) would also
        # pull the wide re-search's matches back onto this drifting odometry (0.237 m at the end
        # with it, 0.228 m allowed)
        degeneracy_threshold=0.0,
        constraint_translation_sigma=0.1,  # ... and says so: its constraints are loose
        constraint_rotation_sigma=0.05,
    )
    s = drive.session
    update = s.odometry.update

    def drifting(ticks, imu=None):
        before = s.odometry.pose
        st = update(ticks, imu)
        p = st.pose
        s.odometry.pose = Pose2D(p.x, p.y, p.theta + np.radians(1.0) * p.distance_to(before))
        return replace(st, pose=s.odometry.pose)

    s.odometry.update = drifting  # type: ignore[method-assign]
    try:
        drive.mapping.start()
        teleop_loop(drive, APARTMENT_LOOP)
        drive.mapping.stop()
        s.run_for(0.1)
        truth = drive.driver.truth_pose.relative_to(drive.start_truth)
        odom_only = drive.start_truth.inverse().compose(APARTMENT_START).compose(s.odom_pose)
        drift = odom_only.distance_to(truth)
        assert drift > 0.3  # the drift is really there (0.46 m)
        assert drive.mapping.slam.num_loop_closures > 0
        # raw odometry ends ~0.46 m off; loop closure must at least halve that (it reaches ~0.1-0.2 m)
        assert s.pose.distance_to(truth) < drift / 2
    finally:
        drive.session.close()


@pytest.mark.timeout(900)  # ~30 s of CPU; a CI run beside two busy loops and other jobs took > 300 s
def test_office_corridor_loop_meets_issue_3() -> None:
    # Issue 3: >= 95 % of the true wall cells within one cell of the built map after the out-and-back
    # loop along the office's 25 m corridor (~10 s). Was 93.8 %: matches lagged behind the robot
    # (points on newly seen walls pulled onto the mapped part; loop searches against the submap
    # just left), so the corridor's far end came out 0.1 m short.
    r = run_mapping("office", OFFICE_START, OFFICE_LOOP)
    assert r["coverage"] >= 0.95, r
    assert r["end_error"] < 0.1, r
    assert r["loops"] > 0, r
