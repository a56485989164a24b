"""Front-end behaviour that FR079 needed: every scan is matched (not only motion-filtered nodes), the
translation window absorbs odometry that lags the laser, and a poorly scoring match is searched
again in a wide window."""

from __future__ import annotations

import numpy as np

from nav.slam.synthetic import LOOP_WAYPOINTS, box_world, cast_scan, loop_trajectory
from nav.slam.system import GraphSlam, SlamOptions
from nav.types import Pose2D


def _lagged_run(options: SlamOptions, lag: int = 1) -> float:
    """Max position error (m) of all scans (front end only) when odometry is ``lag`` scans late."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS[:3], 0.12, turn_step=np.radians(12))[:70]
    odom = np.vstack([truth[:1]] * lag + [truth[:-lag]])  # odometry stamped late, like FR079's
    rng = np.random.default_rng(3)
    slam = GraphSlam(options)
    o0, t0 = Pose2D.from_array(odom[0]), Pose2D.from_array(truth[0])
    for k in range(len(truth)):
        scan = cast_scan(
            grid, res, Pose2D.from_array(truth[k]), 180, range_max=6.0, noise=0.01, rng=rng, stamp=0.2 * k
        )
        slam.add_scan(scan, Pose2D.from_array(odom[k]).relative_to(o0))
    est = slam.trajectory()[:, 1:3]
    rel = np.array([Pose2D.from_array(p).relative_to(t0).as_array()[:2] for p in truth])
    return float(np.hypot(*(est - rel).T).max())


def test_every_scan_matched_beats_odometry_between_nodes() -> None:
    # a coarse motion filter leaves most scans between nodes, where only matching can fix the lag
    base = SlamOptions(
        minimum_travel_distance=0.5,
        minimum_travel_heading=np.radians(40),
        match_every_scan=True,
        linear_search_window=0.2,
    )
    matched = _lagged_run(base)
    dead_reckoned = _lagged_run(SlamOptions(**{**base.__dict__, "match_every_scan": False}))
    assert matched < 0.08, matched
    assert dead_reckoned > 1.5 * matched, (dead_reckoned, matched)


def test_translation_window_covers_lagged_odometry() -> None:
    # odometry two scans late: the prediction is ~0.24 m off, beyond a 0.1 m window
    fixed = {
        "linear_search_window_per_radian": 0.0,
        "search_levels": 0,
        "match_every_scan": True,
        "wide_search_minimum_score": 0.0,  # no second, wider search: the fixed window alone
    }
    # a stiff pull towards the search's result (the old 10 / 40): the window alone decides
    stiff = {**fixed, "translation_weight": 10.0, "rotation_weight": 40.0}
    narrow = _lagged_run(SlamOptions(linear_search_window=0.1, **stiff), lag=2)
    wide = _lagged_run(SlamOptions(linear_search_window=0.3, **stiff), lag=2)
    assert wide < 0.1, wide
    assert narrow > wide, (narrow, wide)
    # with the default, weaker pull the refinement itself gets out of the narrow window's edge
    assert _lagged_run(SlamOptions(linear_search_window=0.1, **fixed), lag=2) < 0.1


def _slip_run(options: SlamOptions, slip: float = 0.35) -> float:
    """Max position error (m) when odometry jumps ``slip`` m sideways at scan 25 (a wheel slip)."""
    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS[:2], 0.12)[:40]
    odom = truth.copy()
    odom[25:, 1] += slip
    rng = np.random.default_rng(5)
    slam = GraphSlam(options)
    for k in range(len(truth)):
        scan = cast_scan(
            grid, res, Pose2D.from_array(truth[k]), 180, range_max=6.0, noise=0.01, rng=rng, stamp=0.2 * k
        )
        slam.add_scan(scan, Pose2D.from_array(odom[k]).relative_to(Pose2D.from_array(odom[0])))
    est = slam.trajectory()[:, 1:3]
    return float(np.hypot(*(est - (truth[:, :2] - truth[0, :2])).T).max())


def test_poor_match_is_searched_again_wider() -> None:
    # a 0.35 m odometry jump is beyond the 0.1 m window: the match scores poorly, which triggers
    # the second search in the wide (0.5 m, 30 deg) window, and that one finds the right pose
    without = _slip_run(SlamOptions(wide_search_minimum_score=0.0))
    with_wide = _slip_run(SlamOptions())
    assert with_wide < 0.08, with_wide
    assert without > 2 * with_wide, (without, with_wide)


def _corridor(length: float = 24.0, res: float = 0.05) -> np.ndarray:
    """A 2 m corridor (y 3-5) between rooms 4 m wide, with a door into each (the office world's
    layout at a smaller scale): along the corridor only the doors and the rooms' walls tell x."""
    g = np.zeros((round(8.0 / res), round(length / res)), dtype=bool)

    def box(x0: float, y0: float, x1: float, y1: float, value: bool = True) -> None:
        g[round(y0 / res) : round(y1 / res), round(x0 / res) : round(x1 / res)] = value

    box(0, 2.9, length, 3.0)
    box(0, 5.0, length, 5.1)
    box(0, 0, length, 0.1)
    box(0, 7.9, length, 8.0)
    box(0, 0, 0.1, 8.0)
    box(length - 0.1, 0, length, 8.0)
    for x in np.arange(4.0, length, 4.0):
        box(x, 0, x + 0.1, 2.9)
        box(x, 5.1, x + 0.1, 8.0)
        box(x - 2.4, 2.85, x - 1.6, 3.05, False)
        box(x - 1.0, 4.95, x - 0.2, 5.15, False)
    return g


def _corridor_drift(options: SlamOptions) -> float:
    """Max along-corridor error (m) of the front end's nodes over 20 m with exact odometry and a
    6 m lidar (the simulator's RPLidar): whatever moves the match away from the prediction is the
    matcher's own doing."""
    grid, res = _corridor(), 0.05
    rng = np.random.default_rng(0)
    slam = GraphSlam(options)
    xs = np.arange(1.0, 21.0, 0.1)
    for k, x in enumerate(xs):
        pose = Pose2D(float(x), 4.0, 0.0)
        scan = cast_scan(grid, res, pose, 360, range_max=6.0, noise=0.01, rng=rng, stamp=0.2 * k)
        slam.add_scan(scan, pose)
    stamps, poses = slam.front_end_nodes()
    k = np.rint(stamps / 0.2).astype(int)
    return float(np.abs(poses[:, 0] - (xs[k] - xs[0])).max())


def test_newly_seen_surfaces_do_not_drag_the_match_back() -> None:
    # Issue 3 (office corridor 0.1 m short after 25 m): each scan sees a little more of the walls
    # ahead (range limit, through doors) than the submap holds; those points have no counterpart
    # in the submap and the likelihood field pulled them onto the nearest mapped cell, always on
    # the side already seen, so every match lagged behind the robot. They are now left out.
    assert _corridor_drift(SlamOptions()) < 0.04
    # the drag on its own, without the grazing-ray rule (grazing_ray_margin), which keeps the walls
    # ahead sharper and by itself takes the dragged drift from 0.047 to 0.027 m (0.020 -> 0.024 m
    # with the points left out)
    fixed = _corridor_drift(SlamOptions(grazing_ray_margin=0.0))
    dragged = _corridor_drift(SlamOptions(match_unobserved_points=True, grazing_ray_margin=0.0))
    assert dragged > 1.5 * fixed, (dragged, fixed)


def test_no_return_clears_at_most_the_sensor_range() -> None:
    # a beam without return says nothing beyond range_max: its free ray stops there even when
    # missing_data_ray_length is longer (a 3 m lidar next to a wall 3.2 m away keeps the wall unseen)
    grid, res = _corridor(), 0.05
    slam = GraphSlam(SlamOptions(missing_data_ray_length=5.0))
    pose = Pose2D(2.0, 4.0, 0.0)
    for k in range(3):
        slam.add_scan(cast_scan(grid, res, pose, 360, range_max=3.0, stamp=0.2 * k), pose)
    sm = slam._submaps[0]
    rows, cols = np.nonzero(sm.grid.seen)
    centres = sm.grid.origin + (np.column_stack((cols, rows)) + 0.5) * res
    assert np.hypot(*centres.T).max() <= 3.0 + res


def _searched_point_sets(options: SlamOptions, lag: float) -> tuple[list[np.ndarray], Pose2D, GraphSlam]:
    """The point sets the front end searches with when matching a scan of the synthetic corridor
    0.3 m on from a submap seen from x 2 m (3 m lidar: the scan sees 0.3 m more of the walls),
    predicted ``lag`` m behind the truth; and the prediction in the submap's frame."""
    grid, res = _corridor(), 0.05
    start, truth = Pose2D(2.0, 4.0, 0.0), Pose2D(2.3, 4.0, 0.0)
    slam = GraphSlam(options)
    for k in range(3):
        slam.add_scan(cast_scan(grid, res, start, 360, range_max=3.0, stamp=0.2 * k), start)
    searched: list[np.ndarray] = []
    search = slam._search

    def spy(target, pts, prior, window):  # type: ignore[no-untyped-def]
        searched.append(pts.copy())
        return search(target, pts, prior, window)

    slam._search = spy  # type: ignore[method-assign]
    pts = slam._split(cast_scan(grid, res, truth, 360, range_max=3.0, stamp=1.0), Pose2D())[0]
    pred = Pose2D(truth.x - start.x - lag, 0.0, 0.0)  # the front end's frame starts at the first scan
    slam._match(pts, pred, Pose2D())
    return searched, pred.relative_to(slam._submaps[0].local_pose), slam


def test_unobserved_points_can_be_chosen_at_the_prediction_only() -> None:
    # Issue 18: a first match with all points is dragged back by the points on surfaces the submap
    # has not seen; choosing the points to leave out at that match (when it lands more than a cell
    # from the prediction) keeps them, as they land on observed cells there, and the drag stays
    # (office corridors 0.2-0.5 % short). With unobserved_points_at_prediction (the live mapping
    # stage, whose odometry is paired at the scan's stamp) they are chosen at the prediction.
    # A prediction 0.08 m behind puts the first match more than a cell away:
    # Chosen there, no first match with all points is needed: one search, the observed points only.
    searched, prior, slam = _searched_point_sets(SlamOptions(unobserved_points_at_prediction=True), 0.08)
    sm = slam._submaps[0]
    assert len(searched) == 1
    assert sm.observed(prior.transform_points(searched[0])).all()
    assert not sm.observed(prior.transform_points(_searched_point_sets(SlamOptions(), 0.08)[0][0])).all()
    # the default chooses them at that first match (FR079's lagging odometry), so its point set
    # holds points unobserved at the prediction
    searched, prior, slam = _searched_point_sets(SlamOptions(), 0.08)
    assert len(searched) == 2
    assert not slam._submaps[0].observed(prior.transform_points(searched[1])).all()
