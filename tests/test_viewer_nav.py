"""What the navigation feature publishes for the 3D view (issue 5 item 6): the current behaviour's name,
recovery markers where attempts started, the TEB band; and the viewer drawing them from real snapshots."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from app.commands.sim_nav import build_sim_stack
from app.features.navigation import BehaviorRecovery
from app.viewer import palette
from app.viewer.scene import Viewer
from nav.recovery import RecoveryOptions
from nav.types import Pose2D
from robot.sim import World


@pytest.fixture
def viewer() -> Iterator[Viewer]:
    from app.bus import SnapshotBus

    v = Viewer(SnapshotBus())
    v.start()
    try:
        yield v
    finally:
        v.stop()


def blocked_room():
    """A 10 x 4 m room with a wall across it that the map does not have: the robot gets stuck."""
    room = World.box(10.0, 4.0)
    grid = room.grid.__class__(room.grid.geometry, room.grid.data.copy())
    world = World(grid, start_pose=Pose2D(2.0, 2.0, 0.0))
    world.add_polygon([(5.0, 0.0), (5.2, 0.0), (5.2, 4.0), (5.0, 4.0)])
    return room.grid, world


def test_recovery_behaviours_named_and_marked_where_they_started(viewer: Viewer) -> None:
    grid, world = blocked_room()
    st = build_sim_stack(grid, world, world.start_pose, localization="truth")
    st.navigation.recovery = BehaviorRecovery(RecoveryOptions(number_of_retries=3))
    s = st.session
    try:
        st.localization.set_initial_pose(world.start_pose)
        st.navigation.set_goals([Pose2D(8.0, 2.0, 0.0)])
        seen: set[str] = set()
        attempt_poses: list[tuple[float, float]] = []
        t0 = s.clock.now()
        while s.clock.now() - t0 < 150.0 and not ("spin" in seen and len(attempt_poses) == 3):
            before = len(attempt_poses)
            s.run_for(s.period)
            snap = s.bus.latest
            if snap.behavior:
                seen.add(snap.behavior)
            marks = snap.extras.get("recovery_markers", ())
            if len(marks) > before:  # the attempt started this tick, at this pose
                attempt_poses.append((snap.pose.x, snap.pose.y))
        st.navigation.cancel()
        s.run_for(5 * s.period)
        assert not st.navigation.active
        assert {"compute_path", "follow_path"} <= seen  # navigation itself is named too
        assert {
            "spin"
        } <= seen  # Nav2's default list: clear local, clear global, spin (one tick each for clears)
        marks = s.bus.latest.extras["recovery_markers"]
        assert [m[3] for m in marks] == ["clear_local_costmap", "clear_global_costmap", "spin"]
        for m, (x, y) in zip(marks, attempt_poses, strict=True):
            assert abs(m[0] - x) < 0.05 and abs(m[1] - y) < 0.05
        assert all(m[0] < 5.0 for m in marks)  # in front of the unmapped wall
        assert s.bus.latest.behavior is None  # cancelled: nothing runs
        viewer.apply(s.bus.latest)  # kept after the navigation ends, until the next request
        assert viewer.is_shown("/recoveries")
        cols = np.asarray(viewer.server.scene.get_handle_by_name("/recoveries/markers").colors).reshape(
            3, 8, 3
        )
        assert tuple(cols[2, 0]) == palette.BEHAVIOR_COLORS["spin"]
        st.navigation.set_goals([Pose2D(3.0, 3.0, 0.0)])  # a new request clears them
        s.run_for(s.period)
        assert "recovery_markers" not in s.bus.latest.extras
    finally:
        s.close()


def test_teb_band_published_and_drawn(viewer: Viewer) -> None:
    room = World.box(8.0, 4.0)
    st = build_sim_stack(room.grid, room, Pose2D(1.5, 2.0, 0.0), localization="truth", controller="teb")
    s = st.session
    try:
        st.localization.set_initial_pose(Pose2D(1.5, 2.0, 0.0))
        st.navigation.set_goals([Pose2D(6.0, 2.5, 0.0)])
        band = None
        for _ in range(40):
            s.run_for(s.period)
            band = s.bus.latest.extras.get("teb_band")
            if band is not None:
                break
        assert band is not None and band.ndim == 2 and band.shape[1] == 3 and len(band) >= 3
        snap = s.bus.latest
        assert snap.behavior == "follow_path"
        assert np.hypot(*(band[0, :2] - (snap.pose.x, snap.pose.y))) < 0.3  # the band starts at the robot
        viewer.apply(snap)
        assert viewer.is_shown("/plan/teb")
        assert viewer.server.scene.get_handle_by_name("/plan/teb/poses").points.shape == (3 * len(band), 2, 3)
    finally:
        s.close()


def test_people_walk_in_the_view(viewer: Viewer) -> None:
    from app.features.sim_view import SimPeopleStage

    room = World.box(8.0, 4.0)
    st = build_sim_stack(room.grid, room, Pose2D(1.0, 1.0, 0.0), localization="truth")
    s = st.session
    try:
        people = s.driver.people
        people.add_loop([[3.0, 1.0], [3.0, 3.0]], speed=1.0)
        people.add_loop([[6.0, 3.0], [5.0, 1.0]], speed=0.6)
        s.add_stage(SimPeopleStage(people))
        s.run_for(s.period)
        first = s.bus.latest.extras["people"].copy()
        assert first.shape == (2, 4) and np.allclose(first[:, 3], people.radius)
        viewer.apply(s.bus.latest)
        segs = viewer.server.scene.get_handle_by_name("/people").points
        assert viewer.is_shown("/people") and segs.shape == (2 * 17, 2, 3)  # outline + heading tick each
        s.run_for(1.0)
        moved = s.bus.latest.extras["people"]
        np.testing.assert_allclose(np.hypot(*(moved[:, :2] - first[:, :2]).T), [1.0, 0.6], atol=0.1)
        viewer.apply(s.bus.latest)
        centre = viewer.server.scene.get_handle_by_name("/people").points[16, 0, :2]  # first person's tick
        np.testing.assert_allclose(centre, moved[0, :2], atol=1e-5)
    finally:
        s.close()


def test_kidnapped_robot_initial_pose_clears_stale_marks() -> None:
    """Scans taken after a kidnap but placed at the old estimate mark obstacles where there are none; the
    operator's 2D Pose Estimate drops those marks from both costmaps (what the view's overlay shows)."""
    from scipy.ndimage import distance_transform_edt

    world = World.stock("apartment")
    st = build_sim_stack(world.grid, world, world.start_pose)
    s = st.session
    clearance = distance_transform_edt(~world.occupied) * world.geometry.resolution

    def stray_lethal() -> int:
        """Lethal cells of both costmaps more than 0.15 m from anything in the world."""
        n = 0
        for cm in (st.navigation.global_costmap, st.navigation.local_costmap):
            rr, cc = np.nonzero(cm.costs == 254)
            r2, c2 = world.geometry.world_to_cell(cm.geometry.cell_to_world(rr, cc))
            n += int(np.sum(clearance[r2, c2] > 0.15))
        return n

    try:
        st.localization.set_initial_pose(world.start_pose)
        s.run_for(1.5)
        assert stray_lethal() == 0
        st.driver.teleport(Pose2D(7.0, 3.6, s.pose.theta))  # 4 m away; the estimate stays put
        s.run_for(2.5)
        assert stray_lethal() > 20  # the other room's walls, drawn around the old estimate
        st.localization.set_initial_pose(st.driver.truth_pose)
        s.run_for(2.0)
        assert stray_lethal() == 0
        assert s.pose.distance_to(st.driver.truth_pose) < 0.1
        # the view's trail restarts at the new estimate: no 4 m line the robot never drove
        trail = s.bus.latest.trail
        assert trail is None or np.max(np.hypot(*np.diff(trail, axis=0).T), initial=0.0) < 0.3
    finally:
        s.close()
