"""In-process viewer tests: snapshots in, viser handles asserted directly (viser.md §9a)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

from app.bus import Snapshot, SnapshotBus
from app.viewer import palette
from app.viewer.pose_input import PoseInputError, ground_through, pose_from_press_drag, ray_ground
from app.viewer.scene import Viewer
from nav.types import Costmap, GridGeometry, LaserScan, OccupancyGrid, Path, Pose2D, Twist2D

OFFICE_ORIGIN = Pose2D(-5.0, -5.0, 0.0)
FOOTPRINT = np.array([[0.12, 0.10], [-0.12, 0.10], [-0.12, -0.10], [0.12, -0.10]])


def office_grid(width: int = 600, height: int = 400, origin: Pose2D = OFFICE_ORIGIN) -> OccupancyGrid:
    rng = np.random.default_rng(7)
    data = np.full((height, width), -1, np.int8)
    data[20:-20, 20:-20] = 0
    data[20, 20:-20] = data[-21, 20:-20] = 100
    data[rng.integers(0, height, 300), rng.integers(0, width, 300)] = 100
    return OccupancyGrid(GridGeometry(0.05, width, height, origin), data)


def make_scan(n: int = 360, r: float = 2.0) -> LaserScan:
    ranges = np.full(n, r)
    ranges[::10] = np.inf
    ranges[5] = np.nan
    return LaserScan(0.0, -math.pi, 2 * math.pi / n, ranges, 0.15, 6.0)


def snap(seq: int = 0, **kw: object) -> Snapshot:
    base: dict = dict(
        stamp=seq * 0.05,
        seq=seq,
        mode="navigating",
        pose=Pose2D(1.0, 2.0, 0.5),
        odom_pose=Pose2D(),
        velocity=Twist2D(0.2, 0.0, 0.1),
        command=Twist2D(),
    )
    base.update(kw)
    return Snapshot(**base)


@pytest.fixture
def viewer() -> Iterator[Viewer]:
    v = Viewer(SnapshotBus(), footprint=FOOTPRINT)
    v.start()
    try:
        yield v
    finally:
        v.stop()


def test_layers_follow_snapshot(viewer: Viewer) -> None:
    grid = office_grid()
    trail = np.column_stack((np.linspace(0, 1, 20), np.zeros(20)))
    path = Path(np.column_stack((np.linspace(0, 3, 30), np.linspace(0, 1, 30), np.zeros(30))))
    particles = np.random.default_rng(1).normal(size=(500, 3))
    viewer.apply(
        snap(grid=grid, grid_version=1, scan=make_scan(), trail=trail, path=path, particles=particles)
    )
    s = viewer.server.scene
    robot = s.get_handle_by_name("/robot")
    assert robot is not None
    np.testing.assert_allclose(robot.position, (1.0, 2.0, 0.0))
    np.testing.assert_allclose(robot.wxyz, (math.cos(0.25), 0, 0, math.sin(0.25)), atol=1e-9)
    bands = [s.get_handle_by_name(f"/scan/band_{i}") for i in range(len(palette.SCAN_BANDS))]
    scan_pts = np.concatenate([b.points for b in bands])
    assert scan_pts.shape == (360 - 36 - 1, 3)  # inf and nan dropped
    assert [len(b.points) for b in bands] == [0, 0, 360 - 36 - 1]  # all at 2 m: the far band
    # in the map frame around the robot at (1, 2) (not under /robot: a browser applying points late
    # must not turn them with the robot)
    np.testing.assert_allclose(np.hypot(scan_pts[:, 0] - 1.0, scan_pts[:, 1] - 2.0), 2.0, atol=1e-5)
    assert s.get_handle_by_name("/robot/footprint").points.shape == (4, 2, 3)
    np.testing.assert_allclose(s.get_handle_by_name("/robot/body").dimensions, (0.24, 0.20, 0.08))
    assert s.get_handle_by_name("/trail").points.shape == (19, 2, 3)
    assert s.get_handle_by_name("/plan/global").points.shape == (29, 2, 3)
    arrows = s.get_handle_by_name("/particles").points.reshape(-1, 3, 2, 3)[:, 0]  # shafts (+ 2 head strokes)
    assert arrows.shape == (500, 2, 3)
    np.testing.assert_allclose(arrows[:, 0, :2], particles[:, :2], atol=1e-5)
    assert len(viewer.map_layer.tile_names) == 20  # 600x400 cells in 128-cell tiles: 5 x 4
    assert all(s.get_handle_by_name(n) is not None for n in viewer.map_layer.tile_names)
    for node in ("/map", "/scan", "/trail", "/plan/global", "/particles"):
        assert viewer.is_shown(node), node
    for node in ("/costmap", "/plan/local", "/goal", "/graph/edges"):
        assert not viewer.is_shown(node), node

    # Next tick: the pose and scan move, the optional layers go away -> hidden, never removed.
    viewer.apply(snap(1, pose=Pose2D(-1.0, 0.5, -1.0), scan=make_scan(r=3.0), grid=grid, grid_version=1))
    np.testing.assert_allclose(robot.position, (-1.0, 0.5, 0.0))
    pts = s.get_handle_by_name(f"/scan/band_{len(palette.SCAN_BANDS) - 1}").points
    np.testing.assert_allclose(np.hypot(pts[:, 0] + 1.0, pts[:, 1] - 0.5), 3.0, atol=1e-5)
    for node in ("/trail", "/plan/global", "/particles"):
        assert not viewer.is_shown(node)
        assert s.get_handle_by_name(node) is not None


def test_changed_region_resends_only_its_tiles(viewer: Viewer) -> None:
    grid = office_grid()
    assert viewer.apply_grids(snap(grid=grid, grid_version=1)) == 20
    assert viewer.apply_grids(snap(grid=grid, grid_version=1)) == 0  # same version: nothing
    g2 = OccupancyGrid(grid.geometry, grid.data.copy())
    g2.data[130:140, 10:20] = 100  # inside tile (row 1, col 0)
    assert viewer.apply_grids(snap(grid=g2, grid_version=2)) == 1
    g3 = OccupancyGrid(grid.geometry, g2.data.copy())
    g3.data[250:260, 250:260] = 100  # straddles tiles (1,1), (1,2), (2,1), (2,2)
    assert viewer.apply_grids(snap(grid=g3, grid_version=3)) == 4
    assert viewer.map_layer.encodes == 25


def test_growing_map_keeps_old_tiles(viewer: Viewer) -> None:
    """A SLAM map that grows to the left/below by whole cells only re-sends tiles that changed."""
    small = office_grid(200, 200, Pose2D(0.0, 0.0, 0.0))
    assert viewer.apply_grids(snap(grid=small, grid_version=1)) == 4  # 2x2 tiles
    grown = np.full((200, 328), -1, np.int8)
    grown[:, 128:] = small.data  # 128 new columns on the left: exactly one tile width
    g = OccupancyGrid(GridGeometry(0.05, 328, 200, Pose2D(-128 * 0.05, 0.0, 0.0)), grown)
    assert viewer.apply_grids(snap(grid=g, grid_version=2)) == 2  # only the new left column of tiles
    # A different resolution re-anchors: everything is rebuilt.
    coarse = office_grid(100, 100, Pose2D(0.0, 0.0, 0.0))
    coarse = OccupancyGrid(GridGeometry(0.1, 100, 100, Pose2D()), coarse.data)
    assert viewer.apply_grids(snap(grid=coarse, grid_version=3)) == 1
    assert viewer.map_layer.tile_names == ["/map/tile_0_0"]


def test_rolling_costmap_moves_its_tile(viewer: Viewer) -> None:
    """A rolling-window local costmap keeps its size and slides by whole cells: same node, new place."""
    costs = np.zeros((60, 60), np.uint8)
    costs[30, 30] = 254
    geo = GridGeometry(0.05, 60, 60, Pose2D(-1.5, -1.5, 0.0))
    viewer.apply_grids(snap(extras={"costmap": Costmap(geo, costs)}))
    tile = viewer.server.scene.get_handle_by_name("/costmap/tile_0_0")
    np.testing.assert_allclose(tile.position, (1.5, 1.5, 0.0))
    moved = GridGeometry(0.05, 60, 60, Pose2D(-1.0, -1.5, 0.0))  # 10 cells along +x
    assert viewer.apply_grids(snap(extras={"costmap": Costmap(moved, costs.copy())})) == 1
    assert viewer.server.scene.get_handle_by_name("/costmap/tile_0_0") is tile
    np.testing.assert_allclose(tile.position, (2.0, 1.5, 0.0))
    assert tile.image[30 * 2, 30 * 2, 3] > 0 and tile.image[0, 0, 3] == 0  # lethal opaque, free clear


def test_large_map_gets_smaller_upsampling(viewer: Viewer) -> None:
    big = OccupancyGrid(GridGeometry(0.05, 2000, 2000, Pose2D()), np.zeros((2000, 2000), np.int8))
    assert viewer.map_layer._upsample_for(big.geometry) == 2  # default 16 Mpx budget
    assert viewer.map_layer._upsample_for(office_grid().geometry) == 4


def test_map_pose_and_tile_image_follow_grid(viewer: Viewer) -> None:
    grid = office_grid(130, 60, Pose2D(2.0, -1.0, 0.3))
    viewer.apply_grids(snap(grid=grid, grid_version=1))
    s = viewer.server.scene
    root = s.get_handle_by_name("/map")
    np.testing.assert_allclose(root.position, (2.0, -1.0, 0.0))
    np.testing.assert_allclose(root.wxyz, (math.cos(0.15), 0, 0, math.sin(0.15)), atol=1e-9)
    t00, t01 = s.get_handle_by_name("/map/tile_0_0"), s.get_handle_by_name("/map/tile_0_1")
    assert t00.render_width == pytest.approx(128 * 0.05) and t01.render_width == pytest.approx(2 * 0.05)
    np.testing.assert_allclose(t00.position, (64 * 0.05, 30 * 0.05, 0.0))
    img = t00.image
    assert img.shape == (60 * 4, 128 * 4, 4)  # nearest-upsampled by 4, row 0 = grid row 0
    lut = palette.map_palette()
    np.testing.assert_array_equal(img[0, 0], lut[np.uint8(grid.data[0, 0])])
    np.testing.assert_array_equal(img[20 * 4 + 1, 20 * 4 + 2], lut[100])  # wall row


def test_initial_camera_follows_the_active_map(viewer: Viewer) -> None:
    """New pages and "Reset View" look at the active map, also after it changed to another frame (a
    mapping session's map has its origin where mapping started, not the stock map's)."""
    cam = viewer.server.initial_camera
    viewer.apply_grids(snap(grid=office_grid(200, 100, Pose2D(0.0, 0.0, 0.0)), grid_version=1))
    np.testing.assert_allclose(cam.look_at, (5.0, 2.5, 0.0))
    viewer.apply_grids(snap(grid=office_grid(200, 100, Pose2D(-12.0, 4.0, 0.0)), grid_version=2))
    np.testing.assert_allclose(cam.look_at, (-7.0, 6.5, 0.0))
    assert cam.position[2] > 0 and cam.position[1] < cam.look_at[1]  # above, from the map's -y side


def test_optional_layers_and_checkboxes(viewer: Viewer) -> None:
    costs = np.zeros((50, 50), np.uint8)
    costs[20:30, 20:30] = 254
    cm = Costmap(GridGeometry(0.05, 50, 50, Pose2D(-1.0, -1.0, 0.0)), costs)
    samples = np.random.default_rng(2).normal(size=(30, 12, 2))
    edges = np.array([[[0.0, 0.0], [1.0, 1.0]], [[1.0, 0.0], [2.0, 2.0]]])
    s0 = snap(
        local_plan=samples,
        goal=Pose2D(3.0, 1.0, 1.0),
        behavior="spin",
        extras={
            "costmap": cm,
            "local_plan_best": 4,
            "graph_edges": edges,
            "waypoints": [Pose2D(1.0, 1.0, 0.0), (2.0, 0.5)],
        },
    )
    viewer.apply(s0)
    s = viewer.server.scene
    assert not viewer.is_shown("/costmap")  # hidden by default, like Rviz; its checkbox shows it
    viewer.set_layer_enabled("Costmap", True)
    for node in ("/costmap", "/plan/local", "/goal"):
        assert viewer.is_shown(node), node
    assert not viewer.is_shown("/graph/edges")  # loop closures are for the mapping session only
    assert s.get_handle_by_name("/plan/local/samples").points.shape == (30 * 11, 2, 3)
    best = s.get_handle_by_name("/plan/local/best").points
    np.testing.assert_allclose(best[:, 0, :2], samples[4, :-1], atol=1e-5)
    np.testing.assert_allclose(s.get_handle_by_name("/goal").position, (3.0, 1.0, 0.0))
    wp = s.get_handle_by_name("/goal/waypoints").points  # relative to the goal frame
    np.testing.assert_allclose(
        Pose2D(3.0, 1.0, 1.0).transform_points(wp[:, :2].astype(float)), [[1, 1], [2, 0.5]], atol=1e-3
    )
    assert s.get_handle_by_name("/robot/label").text == "spin"
    assert viewer.costmap_layer.encodes == 1
    assert "**navigating**" in viewer.status.content and "spin" in viewer.status.content

    viewer.set_layer_enabled("Costmap", False)
    assert not viewer.is_shown("/costmap")
    viewer.set_layer_enabled("Costmap", True)
    assert viewer.is_shown("/costmap")
    viewer.set_layer_enabled("Particles", False)
    viewer.apply(snap(particles=np.zeros((3, 3))))
    assert not viewer.is_shown("/particles")  # data present but unticked


def test_thread_follows_bus_at_bounded_rate() -> None:
    bus = SnapshotBus()
    v = Viewer(bus, rate_hz=10.0)
    v.start()
    try:
        t0 = time.monotonic()
        for i in range(40):  # 40 snapshots published at ~100 Hz
            bus.publish(snap(i, pose=Pose2D(0.1 * i, 0.0, 0.0), grid=office_grid(100, 100), grid_version=1))
            time.sleep(0.01)
        deadline = time.monotonic() + 3.0
        robot = v.server.scene.get_handle_by_name("/robot")
        while time.monotonic() < deadline and abs(robot.position[0] - 3.9) > 1e-9:
            time.sleep(0.02)
        elapsed = time.monotonic() - t0
        assert robot.position[0] == pytest.approx(3.9)  # the newest snapshot always lands
        assert v.stats.updates <= elapsed * 10.0 + 2  # but no faster than rate_hz
        assert v.map_layer.tile_names == ["/map/tile_0_0"]
        assert v.stats.errors == 0
    finally:
        v.stop()
    assert bus.subscriber_count == 0


def test_palettes_match_rviz() -> None:
    m = palette.map_palette(alpha=1.0)
    np.testing.assert_array_equal(m[0], (255, 255, 255, 255))
    np.testing.assert_array_equal(m[100], (0, 0, 0, 255))
    np.testing.assert_array_equal(m[np.uint8(np.int8(-1))], (0x70, 0x89, 0x86, 255))
    shown = palette.map_palette()  # blended over Rviz's background: free light grey
    assert 150 < shown[0, 0] < 230 and shown[100, 0] < 30
    c = palette.costmap_palette(alpha=1.0)
    np.testing.assert_array_equal(c[254], (255, 0, 255, 255))  # lethal purple
    np.testing.assert_array_equal(c[253], (0, 255, 255, 255))  # inscribed cyan
    assert c[0, 3] == 0 and c[255, 3] == 0
    assert c[1, 2] > c[1, 0] and c[252, 0] > c[252, 2]  # blue -> red
    bands = palette.scan_band(np.array([0.0, 0.49, 0.5, 1.9, 2.0, 6.0, np.inf]))
    np.testing.assert_array_equal(bands, [0, 0, 1, 1, 2, 2, 2])
    assert palette.SCAN_BANDS[0][1][0] > 200 and palette.SCAN_BANDS[-1][1][2] > 200  # red near, blue far


def test_pose_input_geometry() -> None:
    np.testing.assert_allclose(ray_ground((0, 0, 5), (0.6, 0, -0.8)), (3.75, 0.0))
    with pytest.raises(PoseInputError):
        ray_ground((0, 0, 5), (1, 0, 0))
    with pytest.raises(PoseInputError):
        ray_ground((0, 0, 5), (0, 0, 1))
    np.testing.assert_allclose(ground_through((0, 0, 4), (1, 1, 2)), (2, 2))
    p = pose_from_press_drag((1, 1), (1, 2))
    assert (p.x, p.y) == (1, 1) and p.theta == pytest.approx(math.pi / 2)
    assert pose_from_press_drag((1, 1), (1, 1), 0.7).theta == 0.7


def test_click_and_drag_call_on_pose_input(viewer: Viewer) -> None:
    got: list[tuple[str, Pose2D]] = []
    viewer.on_pose_input = lambda kind, pose, tab: got.append((kind, pose))
    viewer.apply(snap(pose=Pose2D(0.0, 0.0, 0.2)))

    class Ev:
        ray_origin = (0.0, 0.0, 5.0)
        ray_direction = (0.6, 0.0, -0.8)

    viewer._on_scene_click(Ev())  # type: ignore[arg-type]
    viewer.set_click_kind("", "initial_pose")
    viewer._on_scene_click(Ev())  # type: ignore[arg-type]
    assert (
        got[0][0] == "goal" and got[0][1].x == pytest.approx(3.75) and got[0][1].theta == pytest.approx(0.0)
    )
    assert got[1][0] == "initial_pose" and got[1][1].theta == pytest.approx(0.2)


def test_demo_scan_hits_the_corridor_walls() -> None:
    """The demo's ray-marched scan (used for manual checks) sees the corridor walls at y = -1 and +1."""
    from app.viewer.demo import local_costmap, march_scan, office_map

    grid = office_map()
    scan = march_scan(grid, Pose2D(-7.0, 0.0, 0.0))
    left, right = scan.ranges[270], scan.ranges[90]  # beams at +90 deg and -90 deg
    assert left == pytest.approx(1.0, abs=0.06) and right == pytest.approx(1.0, abs=0.06)
    cm = local_costmap(grid, Pose2D(-7.0, 0.0, 0.0))
    assert (cm.costs == 254).any() and cm.costs[30, 30] < 253  # walls lethal, robot cell free


def test_restart_redraws_everything() -> None:
    v = Viewer(SnapshotBus())
    grid = office_grid(100, 100)
    with v:
        v.apply(snap(grid=grid, grid_version=1))
        first_port = v.port
    assert not v.running
    with v:
        v.apply(snap(grid=grid, grid_version=1))  # same grid, new server: must be sent again
        assert v.map_layer.encodes == 1 and v.server.scene.get_handle_by_name("/map/tile_0_0") is not None
        assert v.port > 0 and isinstance(first_port, int)


def test_behavior_is_named_and_coloured(viewer: Viewer) -> None:
    s = viewer.server.scene
    ring, label = s.get_handle_by_name("/robot/behavior"), s.get_handle_by_name("/robot/label")
    viewer.apply(snap(extras={"footprint": FOOTPRINT}))
    assert ring.visible is False and label.visible is False and viewer.behavior_badge.visible is False
    radius = np.hypot(ring.points[:, 0, 0], ring.points[:, 0, 1])
    np.testing.assert_allclose(radius, np.hypot(0.12, 0.10) + 0.1, atol=1e-5)  # just outside the footprint

    colors = {}
    for name in ("follow_path", "spin", "back_up"):
        viewer.apply(snap(behavior=name, extras={"footprint": FOOTPRINT}))
        assert ring.visible and label.visible and label.text == name
        colors[name] = tuple(np.asarray(ring.colors).reshape(-1, 3)[0])
        assert colors[name] == palette.BEHAVIOR_COLORS[name]
        assert viewer.behavior_badge.visible
        assert palette.hex_color(palette.BEHAVIOR_COLORS[name]) in viewer.behavior_badge.content
        assert f">{name}<" in viewer.behavior_badge.content
    assert len(set(colors.values())) == 3  # each behaviour its own colour

    viewer.apply(snap(behavior="<b>my_plugin</b>", extras={"footprint": FOOTPRINT}))
    assert tuple(np.asarray(ring.colors).reshape(-1, 3)[0]) == palette.UNKNOWN_BEHAVIOR
    assert "<b>" not in viewer.behavior_badge.content  # escaped
    viewer.apply(snap(behavior=None, extras={"footprint": FOOTPRINT}))
    assert ring.visible is False and label.visible is False and viewer.behavior_badge.visible is False


def test_recovery_markers_where_attempts_started(viewer: Viewer) -> None:
    s = viewer.server.scene
    marks = ((1.0, 2.0, 0.0, "clear_local_costmap"), (1.5, 2.5, 1.0, "spin"), (2.0, 2.0, 0.0, "back_up"))
    viewer.apply(snap(extras={"recovery_markers": marks}))
    assert viewer.is_shown("/recoveries")
    markers = s.get_handle_by_name("/recoveries/markers")
    pts = markers.points.reshape(3, 4, 2, 3)
    np.testing.assert_allclose(pts[:, :, 0, :2].mean(axis=1), [m[:2] for m in marks], atol=1e-6)  # centred
    cols = np.asarray(markers.colors).reshape(3, 8, 3)
    for i, m in enumerate(marks):
        assert (cols[i] == palette.BEHAVIOR_COLORS[m[3]]).all()
    for i, m in enumerate(marks):
        lab = s.get_handle_by_name(f"/recoveries/label_{i}")
        assert lab.text == f"{i + 1}. {m[3]}" and lab.visible
        np.testing.assert_allclose(lab.position[:2], m[:2])

    viewer.set_layer_enabled("Recoveries", False)
    assert not viewer.is_shown("/recoveries")
    viewer.set_layer_enabled("Recoveries", True)
    assert viewer.is_shown("/recoveries")

    viewer.apply(snap(extras={"recovery_markers": marks[:1]}))  # fewer: spare labels hidden, not removed
    assert s.get_handle_by_name("/recoveries/label_1").visible is False
    assert markers.points.shape == (4, 2, 3)
    viewer.apply(snap(extras={}))  # a new navigation: no markers
    assert not viewer.is_shown("/recoveries")


def test_teb_band_poses(viewer: Viewer) -> None:
    s = viewer.server.scene
    n = 25
    band = np.column_stack((np.linspace(0, 2, n), 0.3 * np.sin(np.linspace(0, 3, n)), np.linspace(0, 1, n)))
    viewer.apply(snap(extras={"teb_band": band}))
    assert viewer.is_shown("/plan/teb")
    poses = s.get_handle_by_name("/plan/teb/poses").points.reshape(n, 3, 2, 3)[
        :, 0
    ]  # shafts (+ 2 head strokes)
    np.testing.assert_allclose(poses[:, 0, :2], band[:, :2], atol=1e-6)
    heading = np.arctan2(*(poses[:, 1, :2] - poses[:, 0, :2]).T[::-1])
    np.testing.assert_allclose(heading, band[:, 2], atol=1e-5)  # arrows point along each pose's theta
    assert s.get_handle_by_name("/plan/teb/band").points.shape == (n - 1, 2, 3)
    viewer.set_layer_enabled("TEB band", False)
    assert not viewer.is_shown("/plan/teb")
    viewer.set_layer_enabled("TEB band", True)
    viewer.apply(snap(extras={}))  # DWA drives: no band
    assert not viewer.is_shown("/plan/teb")


def test_behavior_palette_matches_dashboard() -> None:
    """frontend/js/behaviors.js must colour behaviours exactly as the 3D view does."""
    import pathlib
    import re

    js = (pathlib.Path(__file__).parents[1] / "frontend/js/behaviors.js").read_text()
    table = js[js.index("BEHAVIOR_COLORS = {") : js.index("};")]
    parsed = {k: tuple(map(int, v.split(","))) for k, v in re.findall(r"(\w+): \[([\d, ]+)\]", table)}
    assert parsed == palette.BEHAVIOR_COLORS
    unknown = re.search(r"UNKNOWN_BEHAVIOR = \[([\d, ]+)\]", js)
    assert unknown and tuple(map(int, unknown.group(1).split(","))) == palette.UNKNOWN_BEHAVIOR


def test_scan_bands_by_range_with_fixed_colours(viewer: Viewer) -> None:
    """Points move between range bands; a band's colour array is never re-sent (in the browser a new
    colour array means a new material and a shader recompile on every scan)."""
    s = viewer.server.scene
    bands = [s.get_handle_by_name(f"/scan/band_{i}") for i in range(len(palette.SCAN_BANDS))]
    colors_before = [b.colors for b in bands]
    ranges = np.array([0.3, 0.45, 1.0, 1.99, 2.5, 5.0, np.inf, 0.3])
    scan = LaserScan(0.0, 0.0, 0.1, ranges, 0.15, 6.0)
    viewer.apply(snap(scan=scan))
    assert [len(b.points) for b in bands] == [3, 2, 2]
    near = bands[0].points[:, :2] - (1.0, 2.0)  # the map frame, around the robot at (1, 2)
    np.testing.assert_allclose(np.hypot(near[:, 0], near[:, 1]), [0.3, 0.45, 0.3], atol=1e-5)
    # the first beam (angle 0) points along the robot's heading (0.5 rad), not the map's x axis
    np.testing.assert_allclose(near[0], 0.3 * np.array([math.cos(0.5), math.sin(0.5)]), atol=1e-5)
    viewer.apply(snap(seq=1, scan=LaserScan(0.1, 0.0, 0.1, np.full(8, 3.0), 0.15, 6.0)))
    assert [len(b.points) for b in bands] == [0, 0, 8]
    for b, before, (_edge, rgb) in zip(bands, colors_before, palette.SCAN_BANDS, strict=True):
        assert b.colors is before and tuple(np.asarray(b.colors).reshape(-1)[:3]) == rgb


def test_every_recovery_behaviour_has_its_own_colour() -> None:
    # an operator tells recoveries apart by colour: a new behaviour must not show as "unknown" grey
    from nav.behaviors import BEHAVIOR_NAMES

    missing = [n for n in BEHAVIOR_NAMES if n not in palette.BEHAVIOR_COLORS]
    assert not missing
    colours = [palette.BEHAVIOR_COLORS[n] for n in BEHAVIOR_NAMES]
    assert len(set(colours)) == len(colours)


def test_loop_closures_only_while_mapping(viewer: Viewer) -> None:
    """Issue 17 item 8: loop-closure lines belong to the mapping session; once mapping ends or navigation
    starts they would hide the path."""
    edges = np.array([[[0.0, 0.0], [1.0, 1.0]], [[1.0, 0.0], [2.0, 2.0]]])
    viewer.apply(snap(mode="mapping", extras={"graph_edges": edges}))
    assert viewer.is_shown("/graph/edges")
    assert viewer.server.scene.get_handle_by_name("/graph/edges").points.shape == (2, 2, 3)
    for mode in ("idle", "navigating", "teleop"):
        viewer.apply(snap(mode=mode, extras={"graph_edges": edges}))  # the map keeps its graph
        assert not viewer.is_shown("/graph/edges"), mode
    viewer.apply(snap(mode="mapping", extras={"graph_edges": edges}))
    assert viewer.is_shown("/graph/edges")


def test_viewer_prints_no_port_of_its_own(capfd: pytest.CaptureFixture[str]) -> None:
    """Issue 17 item 8: users open the dashboard's address; viser's internal port is not for them."""
    v = Viewer(SnapshotBus(), footprint=FOOTPRINT)
    v.start()
    port = v.port
    v.stop()
    out, err = capfd.readouterr()
    assert str(port) not in out + err and "viser" not in (out + err).lower(), out + err


def test_layers_and_click_mode_are_per_tab(viewer: Viewer) -> None:
    """Issue 17 item 7: a layer unticked or a click mode chosen in one tab leaves every other tab's."""
    viewer.apply(snap(particles=np.zeros((3, 3))))
    viewer.set_layer_enabled("Particles", False, "tab-a")
    viewer.set_click_kind("tab-a", "initial_pose")
    assert not viewer.is_shown("/particles", "tab-a")
    assert viewer.is_shown("/particles", "tab-b") and viewer.is_shown("/particles")
    assert viewer.click_kind("tab-a") == "initial_pose" and viewer.click_kind("tab-b") == "goal"
    with pytest.raises(ValueError):
        viewer.set_click_kind("tab-a", "teleport")


def test_initial_pose_click_is_one_shot(viewer: Viewer) -> None:
    """Issue 17 item 5: one click sets one initial pose, then the tab's clicks set goals; a refusal keeps
    the mode (the operator tries again)."""
    got: list[tuple[str, str]] = []
    answers = iter(["outside the map", None, None])
    viewer.on_pose_input = lambda kind, pose, tab: got.append((kind, tab)) or next(answers)

    class Ev:
        ray_origin = (0.0, 0.0, 5.0)
        ray_direction = (0.6, 0.0, -0.8)

    viewer.set_click_kind("", "initial_pose")
    viewer._on_scene_click(Ev())  # type: ignore[arg-type]  # refused
    assert viewer.click_kind("") == "initial_pose"
    viewer._on_scene_click(Ev())  # type: ignore[arg-type]  # taken
    assert viewer.click_kind("") == "goal"
    viewer._on_scene_click(Ev())  # type: ignore[arg-type]
    assert got == [("initial_pose", ""), ("initial_pose", ""), ("goal", "")]


def test_frontiers_and_the_chosen_one(viewer: Viewer) -> None:
    s = viewer.server.scene
    cells = np.array([[1.0, 2.0], [1.05, 2.0], [3.0, -1.0]], np.float32)
    viewer.apply(snap(mode="mapping", extras={"frontiers": cells, "frontier_goal": (1.0, 2.0)}))
    assert viewer.is_shown("/frontiers")
    np.testing.assert_allclose(s.get_handle_by_name("/frontiers/cells").points[:, :2], cells)
    np.testing.assert_allclose(s.get_handle_by_name("/frontiers/goal").points[0, :2], (1.0, 2.0))
    viewer.set_layer_enabled("Frontiers", False)
    assert not viewer.is_shown("/frontiers")
    viewer.set_layer_enabled("Frontiers", True)
    fewer = cells[:1].copy()
    viewer.apply(snap(mode="mapping", extras={"frontiers": fewer, "frontier_goal": None}))
    assert s.get_handle_by_name("/frontiers/cells").points.shape == (1, 3)
    assert s.get_handle_by_name("/frontiers/goal").points.shape == (0, 3)
    viewer.apply(snap(mode="idle", extras={}))  # exploration over: the layer empties
    assert not viewer.is_shown("/frontiers")
