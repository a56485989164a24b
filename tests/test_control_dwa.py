"""DWA/DWB controller: sampling, arcs, footprint checks, critics and closed-loop driving."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage
from test_control_world import (
    RES,
    SKID_FOOTPRINT,
    box,
    footprint_hits_lethal,
    inflate,
    integrate,
    room,
)

from nav.control import (
    FOX_CRITICS,
    DwaController,
    DwaOptions,
    GoalChecker,
    InvalidPath,
    NoValidControl,
    PatienceExceeded,
)
from nav.control.critics import Oscillation, PreferForward
from nav.control.footprint import CostWindow, FootprintModel
from nav.control.footprint import _inside_polygon as inside_polygon
from nav.control.footprint_kernels import _lethal_sq_distance
from nav.control.geometry import polyline_distance, project_onto_polyline, project_poses
from nav.control.trajectory import sample_twists, simulate_arcs, time_steps, window_1d
from nav.costmap.footprint import circle_footprint
from nav.types import Costmap, GridGeometry, Path, Pose2D, Twist2D, wrap_angle
from robot.profiles import load_profile

SKID = DwaOptions(footprint=SKID_FOOTPRINT, min_vel_x=-0.15)
OMNI = DwaOptions(
    holonomic=True,
    robot_radius=0.25,
    max_vel_x=1.5,
    min_vel_x=-1.5,
    max_vel_y=1.5,
    min_vel_y=-1.5,
    max_speed_xy=1.5,
    max_vel_theta=0.5,
    acc_lim_x=1.0,
    acc_lim_y=1.0,
    acc_lim_theta=1.0,
    decel_lim_x=-1.0,
    decel_lim_y=-1.0,
    decel_lim_theta=-1.0,
)


def straight(x0: float, y0: float, x1: float, y1: float, theta: float | None = None, n: int = 80) -> Path:
    xs, ys = np.linspace(x0, x1, n), np.linspace(y0, y1, n)
    th = math.atan2(y1 - y0, x1 - x0)
    poses = np.column_stack((xs, ys, np.full(n, th)))
    if theta is not None:
        poses[-1, 2] = theta
    return Path(poses)


def drive(ctl: DwaController, pose: Pose2D, costmap, goal: Pose2D, seconds: float, dt: float = 0.05):
    """Closed loop with ideal velocity tracking; stops when a Nav2 goal checker is satisfied."""
    checker = GoalChecker()
    vel = Twist2D()
    poses, cmds, t = [pose], [], 0.0
    while t < seconds:
        if checker.is_goal_reached(pose, goal, vel):
            return poses, cmds, True
        cmd, _ = ctl.compute(pose, vel, costmap)
        pose = integrate(pose, cmd, dt)
        vel = cmd
        poses.append(pose)
        cmds.append(cmd)
        t += dt
    return poses, cmds, False


# --- sampling and simulation --------------------------------------------------------------------


def test_dynamic_window_respects_acceleration_limits_and_contains_zero() -> None:
    v = window_1d(0.1, -0.15, 0.26, 2.5, -2.5, 0.05, 20)
    assert v.min() == pytest.approx(0.1 - 0.125) and v.max() == pytest.approx(0.225)
    assert 0.0 in v and len(v) == 21
    v = window_1d(0.25, 0.0, 0.26, 2.5, -2.5, 0.05, 20)
    assert v.max() == pytest.approx(0.26) and v.min() == pytest.approx(0.125) and 0.0 not in v


def test_samples_diff_drive_have_no_lateral_velocity_and_omni_do() -> None:
    skid = sample_twists(SKID, Twist2D(0.1, 0.0, 0.2))
    assert np.all(skid[:, 1] == 0.0) and len(skid) >= 400
    assert np.all(np.abs(skid[:, 0] - 0.1) <= 0.125 + 1e-9)
    assert np.all(np.abs(skid[:, 2] - 0.2) <= 3.2 * 0.05 + 1e-9)
    omni = sample_twists(OMNI, Twist2D(0.5, 0.2, 0.0))
    assert len(np.unique(omni[:, 1])) >= 5
    assert np.all(np.hypot(omni[:, 0], omni[:, 1]) <= 1.5 + 1e-9)
    assert not np.any(np.all(omni == 0.0, axis=1))  # DWB never samples the all-zero twist


def test_closed_form_arcs_match_numerical_integration() -> None:
    rng = np.random.default_rng(3)
    twists = np.column_stack((rng.uniform(-1, 1, 40), rng.uniform(-1, 1, 40), rng.uniform(-2, 2, 40)))
    twists[:5, 2] = 0.0
    twists[5:8, 2] = 1e-8
    start = Pose2D(1.0, -2.0, 0.7)
    times = np.linspace(0.0, 1.7, 18)
    poses = simulate_arcs(start, twists, times)
    for k in range(0, 40, 7):
        p = start
        for j in range(1, len(times)):
            p = integrate(p, Twist2D(*twists[k]), times[j] - times[j - 1], substeps=400)
            assert poses[k, j, 0] == pytest.approx(p.x, abs=1e-4)
            assert poses[k, j, 1] == pytest.approx(p.y, abs=1e-4)
            assert float(wrap_angle(poses[k, j, 2] - p.theta)) == pytest.approx(0.0, abs=1e-9)


# --- footprint ------------------------------------------------------------------------------------


def test_footprint_check_agrees_with_brute_force() -> None:
    occ = box(room(3.0, 3.0), 1.2, 1.2, 1.5, 1.35)
    cm = inflate(occ, inscribed=0.1)
    poly = np.asarray(SKID_FOOTPRINT)
    model = FootprintModel.build(poly, RES, 16, round_robot=False)
    rng = np.random.default_rng(7)
    poses = np.column_stack((rng.uniform(0.6, 2.2, 600), rng.uniform(0.6, 2.0, 600), rng.uniform(-4, 4, 600)))
    window = CostWindow.around(cm, poses[:, :2], 0.2, unknown_is_lethal=False)
    flagged = window.footprint_lethal(poses, model)
    grown = poly * (1 + 2.5 * RES / 0.12)  # a safely larger polygon
    shrunk = poly * (1 - 2.5 * RES / 0.10)  # a safely smaller one
    for p, f in zip(poses, flagged, strict=True):
        pose = Pose2D(*p)
        if footprint_hits_lethal(cm, pose, shrunk):
            assert f, f"missed collision at {pose}"
        if not footprint_hits_lethal(cm, pose, grown):
            assert not f, f"false collision at {pose}"
    assert 50 < flagged.sum() < 550


def test_rotated_footprint_swaps_its_extent() -> None:
    poly = np.array([[0.3, 0.05], [-0.3, 0.05], [-0.3, -0.05], [0.3, -0.05]])
    model = FootprintModel.build(poly, RES, 16, round_robot=False)
    along_x = model.offsets[0]
    along_y = model.offsets[4]  # bin 4 of 16 = 90 degrees
    assert np.ptp(along_x[:, 1]) >= 12 and np.ptp(along_x[:, 0]) <= 6
    assert np.ptp(along_y[:, 0]) >= 12 and np.ptp(along_y[:, 1]) <= 6


# --- one cycle ------------------------------------------------------------------------------------


def test_compute_needs_a_valid_path() -> None:
    ctl = DwaController(SKID)
    with pytest.raises(InvalidPath):
        ctl.set_path(Path(np.zeros((0, 3))))
    with pytest.raises(InvalidPath):
        ctl.set_path(Path(np.array([[0.0, np.nan, 0.0]])))


def test_heads_along_the_path_and_reports_debug() -> None:
    cm = inflate(room(), inscribed=0.1)
    ctl = DwaController(SKID)
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0))
    cmd, dbg = ctl.compute(Pose2D(1.0, 3.0, 0.0), Twist2D(0.2, 0.0, 0.0), cm)
    assert cmd.vx > 0.2 and abs(cmd.wz) < 0.2
    k = len(dbg.twists)
    assert k >= 400 and dbg.trajectories.shape[0] == k and dbg.trajectories.shape[2] == 2
    assert dbg.chosen == int(np.argmin(dbg.costs))
    # facing away from the path, it turns towards it (path is to the left: turn left)
    forward_only = DwaController(DwaOptions(footprint=SKID_FOOTPRINT))
    forward_only.set_path(straight(1.0, 3.0, 5.0, 3.0))
    cmd, _ = forward_only.compute(Pose2D(1.0, 2.6, -0.8), Twist2D(), cm)
    assert cmd.wz > 0


def test_never_picks_a_colliding_trajectory() -> None:
    occ = box(room(), 1.45, 2.0, 1.6, 4.0)  # wall 0.3 m ahead of the robot's nose
    cm = inflate(occ, inscribed=0.1)
    ctl = DwaController(SKID)
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0))
    cmd, dbg = ctl.compute(Pose2D(1.0, 3.0, 0.0), Twist2D(0.26, 0.0, 0.0), cm)
    assert dbg.rejections.get("ObstacleFootprint", 0) > 0
    traj = dbg.chosen_trajectory
    poly = np.asarray(SKID_FOOTPRINT)
    t = np.linspace(0, SKID.sim_time, traj.shape[0])
    for (x, y), ti in zip(traj, t, strict=True):
        assert not footprint_hits_lethal(cm, Pose2D(x, y, ti * cmd.wz), poly)


def test_enclosed_robot_raises_no_valid_control_then_patience_exceeded() -> None:
    occ = room()
    occ[55:66, 15:26] = True
    occ[58:63, 18:23] = False  # a 0.25 m pocket: no room to move
    cm = inflate(occ, inscribed=0.1)
    ctl = DwaController(SKID)
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0))
    pose = Pose2D(1.025, 3.025, 0.0)
    with pytest.raises(NoValidControl) as first:
        ctl.compute(pose, Twist2D(), cm)
    assert not isinstance(first.value, PatienceExceeded)
    assert first.value.rejections
    with pytest.raises(PatienceExceeded):
        for _ in range(10):
            try:
                ctl.compute(pose, Twist2D(), cm)
            except PatienceExceeded:
                raise
            except NoValidControl:
                pass


def test_off_costmap_is_rejected_and_unknown_follows_the_option() -> None:
    cm = inflate(room(), inscribed=0.1)
    cm.costs[:, 70:] = 255  # unknown east of x = 3.5
    lethal_unknown = DwaController(DwaOptions(footprint=SKID_FOOTPRINT, unknown_is_lethal=True))
    free_unknown = DwaController(DwaOptions(footprint=SKID_FOOTPRINT))
    for ctl in (lethal_unknown, free_unknown):
        ctl.set_path(straight(3.0, 3.0, 5.0, 3.0))
    pose, vel = Pose2D(3.2, 3.0, 0.0), Twist2D()
    _, dbg_l = lethal_unknown.compute(pose, vel, cm)
    _, dbg_f = free_unknown.compute(pose, vel, cm)
    assert 0 < dbg_l.legal.sum() < dbg_f.legal.sum()
    # a costmap that simply ends at x = 3.5: off the grid is lethal whatever the unknown option
    cropped = Costmap(GridGeometry(RES, 70, cm.geometry.height, Pose2D()), cm.costs[:, :70].copy())
    _, dbg_c = free_unknown.compute(pose, vel, cropped)
    assert dbg_c.legal.sum() == dbg_l.legal.sum()


def test_rotates_in_place_inside_the_goal_window() -> None:
    cm = inflate(room(), inscribed=0.1)
    ctl = DwaController(SKID)
    ctl.set_path(straight(1.0, 3.0, 3.0, 3.0, theta=math.pi / 2))
    cmd, dbg = ctl.compute(Pose2D(2.9, 3.0, 0.0), Twist2D(0.1, 0.0, 0.0), cm)
    assert dbg.in_goal_window
    assert cmd.vx == 0.0 and cmd.vy == 0.0 and cmd.wz > 0


def test_oscillation_critic_forbids_flipping_back_until_moved() -> None:
    crit = Oscillation(SKID)
    p = Pose2D()
    crit.debrief(Twist2D(0.0, 0.0, 0.5), p)
    crit.debrief(Twist2D(0.0, 0.0, -0.5), p)  # flipped: positive rotation now oscillating
    assert crit.theta.oscillating(np.array([0.3, -0.3])).tolist() == [True, False]
    crit.debrief(Twist2D(0.0, 0.0, -0.5), Pose2D(0.0, 0.0, -0.1))
    assert crit.theta.flipped
    crit.debrief(Twist2D(0.0, 0.0, -0.5), Pose2D(0.0, 0.0, -0.25))  # turned > 0.2 rad: reset
    assert not crit.theta.flipped


def test_oscillation_ignores_near_stops_and_releases_a_stalled_robot() -> None:
    crit = Oscillation(SKID)
    p = Pose2D()
    crit.debrief(Twist2D(0.1, 0.0, 0.0), p)
    crit.debrief(Twist2D(-0.001, 0.0, 0.0), p)  # inside the deadband: not a direction
    assert not crit.x.flipped
    crit.debrief(Twist2D(-0.1, 0.0, 0.0), p)  # a real reversal: forward is vetoed
    assert crit.x.oscillating(np.array([0.1])).all()
    # the robot now only stops (forward vetoed, backward worse): it never moves reset_dist, so
    # after oscillation_stall_reset_time of stops under the veto the flags reset
    cycles = math.ceil(SKID.oscillation_stall_reset_time / SKID.sim_period)
    for i in range(cycles):
        assert crit.x.flipped, i
        crit.vetoed = True  # what score() records when it rejects trajectories
        crit.debrief(Twist2D(0.0, 0.0, 0.0), p)
    assert not crit.x.flipped
    # creeping too slowly to move reset_dist in that time counts as stalled too
    crit.debrief(Twist2D(0.1, 0.0, 0.0), p)
    crit.debrief(Twist2D(-0.1, 0.0, 0.0), p)
    for _ in range(cycles - 1):
        crit.vetoed = True
        crit.debrief(Twist2D(-0.02, 0.0, 0.0), p)
    assert crit.x.flipped  # not yet: one cycle short
    crit.debrief(Twist2D(-0.1, 0.0, 0.0), p)  # a real move restarts the count
    crit.vetoed = True
    crit.debrief(Twist2D(-0.02, 0.0, 0.0), p)
    assert crit.x.flipped


# --- closed loop ------------------------------------------------------------------------------------


def bent_path() -> Path:
    """A path from (1, 3) to (5, 3) bending north around a block at x 2.8..3.2, y 2.85..3.15,
    as the global planner would make it."""
    pts = np.array([[1.0, 3.0], [2.3, 3.0], [3.0, 3.75], [3.7, 3.0], [5.0, 3.0]])
    segs = [np.linspace(a, b, 30, endpoint=False) for a, b in itertools.pairwise(pts)]
    dense = np.vstack((*segs, pts[-1]))
    th = np.append(np.arctan2(*np.diff(dense, axis=0)[:, ::-1].T), 0.0)
    return Path(np.column_stack((dense, th)))


def polygon_of(opts: DwaOptions) -> np.ndarray:
    if opts.footprint:
        return np.asarray(opts.footprint)
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    return opts.robot_radius * np.column_stack((np.cos(a), np.sin(a)))


@pytest.mark.parametrize(
    "opts",
    [SKID, OMNI, DwaOptions(footprint=SKID_FOOTPRINT, critics=(*FOX_CRITICS, "RotateToGoal"))],
    ids=["skid", "omni", "fox"],
)
def test_drives_around_an_obstacle_to_the_goal_without_touching_it(opts: DwaOptions) -> None:
    occ = box(room(), 2.8, 2.85, 3.2, 3.15)  # a 0.4 x 0.3 m block sitting on the straight line
    cm = inflate(occ, inscribed=opts.inscribed_radius)
    ctl = DwaController(opts)
    ctl.set_path(bent_path())
    goal = Pose2D(5.0, 3.0, 0.0)
    poses, _, reached = drive(ctl, Pose2D(1.0, 3.0, 0.0), cm, goal, 60.0)
    assert reached
    assert not any(footprint_hits_lethal(cm, p, polygon_of(opts)) for p in poses[::2])
    assert max(p.y for p in poses) > 3.15 + opts.inscribed_radius  # it went round, north


def test_goal_approach_does_not_oscillate() -> None:
    """The angular command changes sign at most twice in the last 2 s before the goal is reached,
    even when the goal heading is 90 degrees off the approach direction."""
    cm = inflate(room(), inscribed=0.1)
    for goal_yaw in (math.pi / 2, -math.pi * 0.9):
        ctl = DwaController(SKID)
        goal = Pose2D(3.0, 3.0, goal_yaw)
        ctl.set_path(straight(1.0, 3.0, 3.0, 3.0, theta=goal_yaw))
        _, cmds, reached = drive(ctl, Pose2D(1.0, 3.0, 0.0), cm, goal, 40.0)
        assert reached
        wz = np.array([c.wz for c in cmds[-40:]])
        signs = np.sign(wz[np.abs(wz) > 1e-9])
        assert np.count_nonzero(np.diff(signs)) <= 2, wz


def test_fox_admissible_velocities_brake_before_an_obstacle() -> None:
    """With Fox's objective alone the robot heads straight for a goal behind a block: its
    admissible-velocity test must make it stop short of the block, never touch it."""
    occ = box(room(), 2.8, 3.05, 3.1, 3.35)
    cm = inflate(occ, inscribed=0.1)
    ctl = DwaController(DwaOptions(footprint=SKID_FOOTPRINT, critics=FOX_CRITICS))
    ctl.set_path(straight(1.0, 3.2, 5.0, 3.2))
    poses, cmds, reached = drive(ctl, Pose2D(1.0, 3.2, 0.0), cm, Pose2D(5.0, 3.2, 0.0), 12.0)
    assert not reached  # Fox's local minimum: the goal is straight through the block
    assert not any(footprint_hits_lethal(cm, p, np.asarray(SKID_FOOTPRINT)) for p in poses)
    assert 2.5 < poses[-1].x < 2.8 - 0.12 and cmds[-1].vx == 0.0


def test_fast_arrival_in_the_goal_window_brakes_then_turns() -> None:
    """Entering the goal window at 0.2 m/s (below trans_stopped_velocity, so RotateToGoal is in its
    rotating phase) while zero speed is not reachable in one period: brake, do not give up."""
    cm = inflate(room(), inscribed=0.1)
    ctl = DwaController(DwaOptions(footprint=SKID_FOOTPRINT, acc_lim_x=1.0, decel_lim_x=-1.0))
    ctl.set_path(straight(1.0, 3.0, 3.0, 3.0, theta=math.pi / 2))
    cmd, _ = ctl.compute(Pose2D(2.8, 3.0, 0.0), Twist2D(0.2, 0.0, 0.0), cm)
    assert cmd.vx == pytest.approx(0.15)
    cmd, _ = ctl.compute(Pose2D(2.81, 3.0, 0.0), cmd, cm)
    assert cmd.vx == pytest.approx(0.10)


def test_path_and_goal_critics_measure_cells_to_the_path_and_local_goal() -> None:
    cm = inflate(room(), inscribed=0.1)
    ctl = DwaController(SKID)
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0, n=9))  # vertices 0.5 m apart: tests the resampling
    _, dbg = ctl.compute(Pose2D(1.5, 2.8, 0.3), Twist2D(0.1, 0.0, 0.0), cm)
    end = dbg.trajectories[:, -1, :].astype(float)
    expected_path = np.abs(end[:, 1] - 3.0) / RES * SKID.path_dist_scale
    assert np.allclose(dbg.critic_costs["PathDist"], expected_path, atol=0.26 * SKID.path_dist_scale)
    local_goal = dbg.local_path[-1]
    assert local_goal[0] == pytest.approx(3.5)  # forward_prune_distance = 2 m past the nearest vertex
    # along the path: to the straight path (|y - 3|), then the rest of it to the local goal
    expected_goal = (np.abs(end[:, 1] - 3.0) + (local_goal[0] - end[:, 0])) / RES * SKID.goal_dist_scale
    assert np.allclose(dbg.critic_costs["GoalDist"], expected_goal, rtol=1e-4)


def test_goal_distance_follows_the_path_round_a_wall_end() -> None:
    """The local goal lies behind a wall the path bends round: a trajectory towards the wall gets
    nearer the goal in a straight line but not along the path, so GoalDist must not prefer it."""
    cm = inflate(box(room(), 2.0, 2.45, 2.1, 5.0), inscribed=0.1)  # a wall from y 2.45 up, x 2.0..2.1
    path = np.array([[1.5, 2.6], [1.7, 2.2], [2.05, 2.1], [2.4, 2.2], [2.6, 2.6], [2.6, 3.2]])
    segs = [np.linspace(a, b, 10, endpoint=False) for a, b in itertools.pairwise(path)]
    dense = np.vstack((*segs, path[-1]))
    ctl = DwaController(SKID)
    ctl.set_path(Path(np.column_stack((dense, np.zeros(len(dense))))))
    _, dbg = ctl.compute(Pose2D(1.5, 2.6, 0.0), Twist2D(0.0, 0.0, 0.0), cm)
    end = dbg.trajectories[:, -1, :].astype(float)
    g = dbg.local_path[-1]
    toward_goal = np.argmin(np.hypot(end[:, 0] - g[0], end[:, 1] - g[1]))  # straight at the wall
    along = np.argmin(np.hypot(end[:, 0] - 1.7, end[:, 1] - 2.2) + 10 * (dbg.twists[:, 0] < 0.05))
    assert dbg.critic_costs["GoalDist"][along] < dbg.critic_costs["GoalDist"][toward_goal]


def test_path_projection_is_exact_and_extends_behind_the_start() -> None:
    poly = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    pts = np.array([[0.5, 0.2], [1.3, 0.5], [-0.5, 0.1], [2.0, 2.0]])
    d, d_ext, s = project_onto_polyline(pts, poly)
    assert np.allclose(d_ext, [0.2, 0.3, 0.1, math.hypot(1.0, 1.0)])
    assert np.allclose(s, [0.5, 1.5, -0.5, 2.0])
    assert np.allclose(d, [0.2, 0.3, math.hypot(0.5, 0.1), math.hypot(1.0, 1.0)])
    assert np.array_equal(polyline_distance(pts, poly), d)


def test_path_projection_skips_only_segments_that_cannot_be_nearest() -> None:
    # a long winding path and points near its start: the kernel skips far segments; a brute force
    # over every segment must agree (distances, the extended-first-segment distance, arc length)
    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 6.0, 120)
    poly = np.column_stack((t, 0.6 * np.sin(1.3 * t)))
    poses = np.column_stack(
        (rng.uniform(-0.6, 0.8, 300), rng.uniform(-0.5, 0.5, 300), rng.uniform(-4, 4, 300))
    )
    for forward in (0.0, 0.1):
        pts = poses[:, :2] + forward * np.column_stack((np.cos(poses[:, 2]), np.sin(poses[:, 2])))
        d, d_ext, s = project_poses(poses, forward, poly)
        a, ab = poly[:-1], np.diff(poly, axis=0)
        rel = pts[:, None, :] - a[None]
        tt = (rel * ab).sum(-1) / (ab * ab).sum(-1)
        tc = np.clip(tt, 0.0, 1.0)
        seg_d = np.hypot(*(tc[..., None] * ab - rel).transpose(2, 0, 1))
        te = tc.copy()
        te[:, 0] = np.minimum(tt[:, 0], 1.0)  # the first segment extends backwards
        ext_d = np.hypot(*(te[..., None] * ab - rel).transpose(2, 0, 1))
        j = np.argmin(ext_d, axis=1)
        s0 = np.concatenate(([0.0], np.cumsum(np.hypot(ab[:, 0], ab[:, 1]))))
        np.testing.assert_allclose(d, seg_d.min(axis=1), atol=1e-12)
        np.testing.assert_allclose(d_ext, ext_d.min(axis=1), atol=1e-12)
        np.testing.assert_allclose(
            s, s0[j] + te[np.arange(len(j)), j] * np.hypot(ab[j, 0], ab[j, 1]), atol=1e-9
        )


def test_arcs_of_shared_turn_rates_equal_arcs_one_at_a_time() -> None:
    # the kernel reuses sin/cos per distinct w: bit-identical to simulating each twist alone
    vx, wz = np.meshgrid(np.linspace(-0.15, 0.26, 7), np.array([-1.0, -0.3, 0.0, 1e-10, 0.3, 1.0]))
    tw = np.column_stack((vx.ravel(), np.zeros(vx.size), wz.ravel()))[::-1]
    times = np.linspace(0.0, 1.7, 14)
    start = Pose2D(0.3, -1.2, 2.5)
    together = simulate_arcs(start, tw, times)
    alone = np.concatenate([simulate_arcs(start, tw[k : k + 1], times) for k in range(len(tw))])
    assert np.array_equal(together, alone)


def test_near_lethal_mask_and_gather_equal_the_distance_transform_test() -> None:
    rng = np.random.default_rng(4)
    poly = np.asarray(SKID_FOOTPRINT)
    model = FootprintModel.build(poly, RES, 16, round_robot=False)
    for trial in range(20):
        h, w = rng.integers(15, 50, 2)
        costs = rng.integers(0, 200, (h, w)).astype(np.uint8)
        costs[rng.random((h, w)) < rng.uniform(0.0, 0.1)] = 254
        theta = 0.0 if trial % 2 else 0.4  # rotated grids take the numpy path
        cm = Costmap(GridGeometry(RES, int(w), int(h), Pose2D(-0.3, 0.2, theta)), costs)
        local = rng.uniform(0.25, 0.75, (30, 6, 2)) * np.array([w, h]) * RES
        xy = cm.geometry.origin.transform_points(local.reshape(-1, 2)).reshape(local.shape)
        poses = np.concatenate((xy, rng.uniform(-4, 4, (30, 6, 1))), axis=-1)
        window = CostWindow.around(cm, poses, 0.2, unknown_is_lethal=False)
        for reach in (0.1, model.circumscribed + 0.75 * RES, 0.4):
            assert np.array_equal(window.near_lethal(reach), window.lethal_distance() <= reach)
        # reference: gather every pose, no pre-filter
        rows, cols = window.cells(poses)
        full = window._gather(rows.ravel(), cols.ravel(), poses[..., 2].ravel(), model).reshape(rows.shape)
        assert np.array_equal(window.footprint_lethal(poses, model), full >= 254)
        assert np.array_equal(window.footprint_costs(poses, model), full)
        assert np.array_equal(window.footprint_lethal(poses[:, 1:], model), full[:, 1:] >= 254)


def test_round_robot_collision_test_uses_the_exact_pose_not_its_cell() -> None:
    """A gap whose facing lethal cell centres lie 0.55 m apart (the greenhouse post's aisle with a
    noisy mark on each side) is passable for a 0.5 m round robot near its centre line, whichever
    cell the pose falls in. Snapping the pose to its cell flagged every pose of the gap (the cell
    centres either side of the line are exactly 0.25 m from a mark): DWA stopped in the aisle and
    the spin recovery ground the post's corner. Rotated grids give the same answer."""
    for theta in (0.0, 0.4):
        costs = np.zeros((20, 30), dtype=np.uint8)
        costs[4, :] = 254  # centres at y = 0.225 (grid frame)
        costs[15, :] = 254  # centres at y = 0.775
        cm = Costmap(GridGeometry(RES, 30, 20, Pose2D(0.1, -0.2, theta)), costs)
        model = FootprintModel.build(np.asarray(circle_footprint(0.25)), RES, 1, round_robot=True)
        ys = np.array([0.476, 0.49, 0.499, 0.5, 0.501, 0.51, 0.524])  # clear: both marks > 0.25 m away
        ys_hit = np.array([0.47, 0.474, 0.526, 0.53, 0.45])  # a mark < 0.25 m away
        local = np.column_stack((np.full(12, 0.725), np.concatenate((ys, ys_hit))))  # a column centre
        xy = cm.geometry.origin.transform_points(local)
        poses = np.column_stack((xy, np.linspace(-3.0, 3.0, 12)))[None]
        window = CostWindow.around(cm, poses, 0.3, unknown_is_lethal=False)
        got = window.footprint_lethal(poses, model)[0]
        assert not got[: len(ys)].any(), got
        assert got[len(ys) :].all(), got


def test_round_robot_collision_test_equals_the_exact_centre_distance() -> None:
    """Random costmaps, poses and grid rotations: a round footprint collides exactly when a lethal
    cell's centre lies strictly within the radius of the pose (TEB's ``centre_collisions``)."""
    rng = np.random.default_rng(11)
    for trial in range(24):
        radius = (0.25, 0.8, 0.02)[trial % 3]  # 0.02 m: smaller than half a cell diagonal
        model = FootprintModel.build(np.asarray(circle_footprint(radius)), RES, 1, round_robot=True)
        h, w = rng.integers(20, 50, 2)
        costs = rng.integers(0, 200, (h, w)).astype(np.uint8)
        costs[rng.random((h, w)) < 0.05] = 254
        cm = Costmap(GridGeometry(RES, int(w), int(h), Pose2D(-0.3, 0.2, 0.0 if trial % 2 else 0.4)), costs)
        local = rng.uniform(0.25, 0.75, (30, 6, 2)) * np.array([w, h]) * RES
        xy = cm.geometry.origin.transform_points(local.reshape(-1, 2)).reshape(local.shape)
        poses = np.concatenate((xy, rng.uniform(-4, 4, (30, 6, 1))), axis=-1)
        window = CostWindow.around(cm, poses, 0.3, unknown_is_lethal=False)
        rr, cc = np.nonzero(window.costs >= 254)
        centres = window.geometry.cell_to_world(rr, cc)
        d = np.hypot(poses[..., 0, None] - centres[:, 0], poses[..., 1, None] - centres[:, 1]).min(axis=-1)
        assert np.array_equal(window.footprint_lethal(poses, model), d < radius)
        assert np.array_equal(window.footprint_lethal(poses[:, 1:], model), d[:, 1:] < radius)


def test_footprint_step_spaces_poses_by_the_footprint_sweep() -> None:
    tw = np.array([[0.26, 0.0, 1.0], [0.0, 0.0, -1.0]])
    r = SKID.circumscribed_radius
    n = len(time_steps(SKID, tw)) - 1
    assert n == math.ceil((0.26 + r * 1.0) * SKID.sim_time / SKID.linear_granularity)
    poses = simulate_arcs(Pose2D(), tw, time_steps(SKID, tw))
    corners = np.asarray(SKID_FOOTPRINT)
    for k in range(2):  # no footprint corner moves more than linear_granularity between poses
        c, s = np.cos(poses[k, :, 2]), np.sin(poses[k, :, 2])
        wx = poses[k, :, 0, None] + c[:, None] * corners[:, 0] - s[:, None] * corners[:, 1]
        wy = poses[k, :, 1, None] + s[:, None] * corners[:, 0] + c[:, None] * corners[:, 1]
        assert np.hypot(np.diff(wx, axis=0), np.diff(wy, axis=0)).max() <= SKID.linear_granularity + 1e-9
    dwb = DwaOptions(footprint=SKID_FOOTPRINT, footprint_step=False)
    assert len(time_steps(dwb, tw)) - 1 == min(math.ceil(1.7 / dwb.angular_granularity), dwb.max_steps)


def test_footprint_touching_a_mark_by_the_raster_margin_is_not_a_deadlock() -> None:
    """A lethal cell the footprint's raster touches while its centre lies outside the polygon (the
    apartment's wall end, goal 11): every trajectory's first pose still touches it, so DWB's strict
    rule rejected them all and the robot stayed until the navigator gave up. The escape rule keeps
    the trajectories that never come closer to it; straight on into it stays illegal."""
    occ = room()
    leg = (round(3.0 / RES) + 1, round(3.0 / RES) + 2)  # (row, col): centre at (3.125, 3.075)
    occ[leg] = True
    cm = inflate(occ, inscribed=0.1)
    pose = Pose2D(2.99, 3.0, 0.0)  # front edge at x 3.11: crosses the leg's cell, 1.5 cm short of its centre
    ctl = DwaController(SKID)
    ctl.set_path(straight(2.5, 3.0, 5.0, 3.0))
    cmd, dbg = ctl.compute(pose, Twist2D(), cm)
    crit = next(c for c in ctl.critics if c.name == "ObstacleFootprint")
    assert crit.escaping  # the raster says touching ...
    assert dbg.legal.any() and not dbg.legal.all()  # ... yet there is a way out
    ahead = np.flatnonzero((dbg.twists[:, 0] > 0.1) & (np.abs(dbg.twists[:, 2]) < 1e-9))
    assert ahead.size and not dbg.legal[ahead].any()
    assert cmd.vx <= 0.0 or abs(cmd.wz) > 0.0


def test_footprint_already_touching_a_chair_leg_may_back_or_turn_out_but_not_deeper() -> None:
    """A 5 cm leg inside the footprint's front corner (a return marked a cell too close): DWB
    rejects every trajectory; the escape rule keeps those that never reach deeper into it."""
    occ = room()
    leg = (round(3.0 / RES) + 1, round(3.0 / RES) + 2)  # (row, col): centre at (3.125, 3.075)
    occ[leg] = True
    cm = inflate(occ, inscribed=0.1)
    leg_xy = np.array([(leg[1] + 0.5) * RES, (leg[0] + 0.5) * RES])
    ctl = DwaController(SKID)
    ctl.set_path(straight(3.0, 3.0, 5.0, 3.0))
    pose = Pose2D(3.02, 3.0, 0.0)  # the leg's centre 1.5 cm inside the front edge (x 0.12 m)
    cmd, dbg = ctl.compute(pose, Twist2D(), cm)
    crit = next(c for c in ctl.critics if c.name == "ObstacleFootprint")
    assert crit.escaping
    assert dbg.legal.any() and not dbg.legal.all()

    def depth(k: int) -> np.ndarray:  # how far the leg's centre is inside the 0.24 x 0.20 m box
        t = np.linspace(0.0, SKID.sim_time, dbg.trajectories.shape[1])
        th = pose.theta + dbg.twists[k, 2] * t
        d = leg_xy - dbg.trajectories[k].astype(float)
        x = np.cos(th) * d[:, 0] + np.sin(th) * d[:, 1]
        y = -np.sin(th) * d[:, 0] + np.cos(th) * d[:, 1]
        return np.clip(np.minimum(0.12 - np.abs(x), 0.10 - np.abs(y)), 0.0, None)

    start = depth(0)[0]
    assert start > 0.0
    for k in np.flatnonzero(dbg.legal):
        assert (depth(k) <= start + 1e-3).all()  # float32 trajectories: a mm of slack
    ahead = np.flatnonzero((dbg.twists[:, 0] > 0.1) & (np.abs(dbg.twists[:, 2]) < 1e-9))
    assert ahead.size and not dbg.legal[ahead].any()  # straight on into the leg is not allowed
    assert cmd.vx <= 0.0 or abs(cmd.wz) > 0.0


# --- PreferForward (DWB PreferForwardCritic) ---------------------------------------------------


def test_prefer_forward_scores_like_dwb() -> None:
    opts = replace(SKID, critics=(*SKID.critics, "PreferForward"), prefer_forward_penalty=7.0)
    ctl = DwaController(opts)
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0))
    cm = inflate(room(), inscribed=0.1)
    _, dbg = ctl.compute(Pose2D(1.0, 3.0, 0.0), Twist2D(0.05, 0.0, 0.1), cm)
    cost = dbg.critic_costs["PreferForward"]
    vx, wz = dbg.twists[:, 0], np.abs(dbg.twists[:, 2])
    w = dbg.twists[:, 2]
    fastest_each_way = (w == w.max()) | (w == w.min())  # turning as fast as the window allows
    back = vx < 0
    slow_straight = (vx >= 0) & (vx < 0.1) & (wz < 0.2) & ~fastest_each_way
    other = ~back & ~slow_straight
    assert back.any() and slow_straight.any() and other.any()
    assert np.all(cost[back] == 7.0) and np.all(cost[slow_straight] == 7.0)
    assert np.allclose(cost[other], 10.0 * wz[other])  # theta_scale x |w|
    # from a standstill the window's fastest turn (0.16 rad/s < strafe_theta) counts as turning:
    # otherwise standing still would cost as much as starting to turn
    ctl.reset()
    ctl.set_path(straight(1.0, 3.0, 5.0, 3.0))
    _, dbg = ctl.compute(Pose2D(1.0, 3.0, 0.0), Twist2D(), cm)
    cost, tw = dbg.critic_costs["PreferForward"], dbg.twists
    fastest = (tw[:, 0] == 0.0) & (np.abs(tw[:, 2]) == np.abs(tw[:, 2]).max())
    still = (tw[:, 0] == 0.0) & (tw[:, 2] == 0.0)
    assert fastest.any() and np.all(cost[fastest] < 7.0) and np.all(cost[still] == 7.0)
    # a robot already turning may brake its turn through the band without the penalty
    _, dbg = ctl.compute(Pose2D(1.0, 3.0, 0.0), Twist2D(0.0, 0.0, 0.3), cm)
    cost, tw = dbg.critic_costs["PreferForward"], dbg.twists
    braking = (tw[:, 0] >= 0.0) & (np.abs(tw[:, 2]) < 0.2)
    assert braking.any() and np.all(cost[braking] < 7.0)
    # the automatic penalty: what reversing can gain on the path and goal critics over one horizon
    auto = PreferForward(replace(opts, prefer_forward_penalty=-1.0))
    assert auto.penalty(RES) == pytest.approx((24.0 + 24.0 + 32.0 + 32.0) * 0.15 * 1.7 / RES)


def test_prefer_forward_is_on_for_reversing_skid_bases_only() -> None:
    skid, omni = load_profile("skid4"), load_profile("omni4")
    assert skid.limits.min_vel_x < 0  # the stock skid base can reverse
    assert "PreferForward" in DwaOptions.for_robot(skid).critics
    assert "PreferForward" not in DwaOptions.for_robot(omni).critics  # strafing is its point
    assert "PreferForward" not in DwaOptions.for_robot(skid, critics=DwaOptions().critics).critics


def _reversing_time(opts: DwaOptions, occ: np.ndarray, start: Pose2D, path: Path, seconds: float):
    ctl = DwaController(opts)
    ctl.set_path(path)
    goal = Pose2D.from_array(path.poses[-1])
    _, cmds, reached = drive(ctl, start, inflate(occ, inscribed=0.1), goal, seconds)
    return sum(0.05 for c in cmds if c.vx < -0.01), reached


def test_skid_base_turns_round_for_a_goal_behind_instead_of_reversing() -> None:
    opts = DwaOptions.for_robot(load_profile("skid4"))
    path = straight(4.5, 3.0, 1.0, 3.0)  # 3.5 m behind the robot, which faces +x
    back_s, reached = _reversing_time(opts, room(), Pose2D(4.5, 3.0, 0.0), path, 40.0)
    assert reached and back_s <= 0.25, back_s
    # Nav2's critic list alone reverses most of the way (what the dashboard showed)
    plain = replace(opts, critics=DwaOptions().critics)
    back_s, reached = _reversing_time(plain, room(), Pose2D(4.5, 3.0, 0.0), path, 40.0)
    assert back_s > 5.0


def test_skid_base_still_backs_out_of_a_dead_end() -> None:
    opts = DwaOptions.for_robot(load_profile("skid4"))
    # a 0.30 m wide dead end (the 0.20 x 0.24 m robot needs 0.31 m to turn round), its nose 8 cm
    # from the end: backing out is the only way
    occ = box(box(box(room(), 3.0, 2.75, 4.6, 2.85), 3.0, 3.15, 4.6, 3.25), 4.5, 2.75, 4.6, 3.25)
    path = straight(4.3, 3.0, 1.5, 3.0)
    back_s, _ = _reversing_time(opts, occ, Pose2D(4.3, 3.0, 0.0), path, 30.0)
    assert back_s > 1.0


def _reference_depth(crit, ctx) -> np.ndarray:
    """The escape rule's depth evaluated for every pose against every lethal cell in reach (the
    original all-pairs form) to check the pruned KD-tree form against."""
    w, poses = ctx.window, ctx.trajectories.poses
    rr, cc = np.nonzero(w.costs >= 254)
    cells = w.geometry.cell_to_world(rr, cc)
    poly = crit._polygon()
    flat = poses.reshape(-1, 3)
    dx = cells[None, :, 0] - flat[:, 0:1]
    dy = cells[None, :, 1] - flat[:, 1:2]
    c, s = np.cos(flat[:, 2:3]), np.sin(flat[:, 2:3])
    pts = np.stack((c * dx + s * dy, -s * dx + c * dy), axis=-1).reshape(-1, 2)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(((pts[:, None, :] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    edge = np.hypot(*(a + t[..., None] * ab - pts[:, None, :]).transpose(2, 0, 1)).min(axis=1)
    inside = inside_polygon(pts, poly)
    signed = np.where(inside, edge, -edge).reshape(flat.shape[0], -1).max(axis=1)
    return signed.reshape(poses.shape[:2])


@pytest.mark.parametrize("opts", [SKID, OMNI], ids=["skid", "omni"])
def test_escape_depth_keeps_the_same_trajectories_as_all_pairs_in_dense_clutter(opts) -> None:
    """Greenhouse-like clutter (posts every 0.3 m) around a robot touching one: the pruned depth
    (pose-cell pairs within the circumscribed radius + a cell) makes the same escape decisions as
    evaluating every pose against every lethal cell, which for an omni robot there grew to GiBs."""
    occ = room()
    for x in np.arange(1.0, 5.0, 0.3):
        for y in np.arange(1.0, 5.0, 0.3):
            occ[round(y / RES), round(x / RES)] = True
    cm = inflate(occ, inscribed=0.1)
    post = np.array([(round(3.1 / RES) + 0.5) * RES, (round(2.8 / RES) + 0.5) * RES])
    front = 0.12 if opts.footprint else opts.robot_radius
    pose = Pose2D(post[0] - front + 0.015, post[1], 0.0)  # the post's centre 1.5 cm inside the front
    ctl = DwaController(opts)
    ctl.set_path(straight(pose.x, pose.y, 4.8, pose.y))
    captured = {}
    crit = next(c for c in ctl.critics if c.name == "ObstacleFootprint")
    original = crit._depth

    def spy(ctx):
        captured["ctx"] = ctx
        return original(ctx)

    crit._depth = spy
    _cmd, dbg = ctl.compute(pose, Twist2D(), cm)
    assert crit.escaping and dbg.legal.any() and not dbg.legal.all()
    ctx = captured["ctx"]
    pruned, full = original(ctx), _reference_depth(crit, ctx)
    assert np.array_equal(pruned[:, 1:] > pruned[:, :1] + 1e-9, full[:, 1:] > full[:, :1] + 1e-9)
    assert np.allclose(pruned[:, 0], full[:, 0])  # the start's depth is exact


@pytest.mark.parametrize("radius", [0.1, 0.45, 1.0])
def test_footprint_costs_by_row_runs_equal_every_cell(radius: float) -> None:
    """The footprint's maximum cost, queried as row runs in a row-maximum table (a 1 m round robot
    is 41 runs per pose instead of 1300 cells; it used to be a ``maximum_filter`` over the whole
    window), equals a numpy gather over every footprint cell, for discs and for a rotated-bin polygon
    whose rows are not one run (an L shape), and so does the lethal test along trajectories."""
    rng = np.random.default_rng(int(radius * 100))
    ell = np.array(
        [[radius, 0.0], [radius, radius], [-radius, radius], [-radius, -radius], [0.0, -radius], [0.0, 0.0]]
    )
    models = (
        FootprintModel.build(np.asarray(circle_footprint(radius)), RES, 1, round_robot=True),
        FootprintModel.build(ell, RES, 16, round_robot=False),
    )
    disc = models[0]
    assert disc.spans[1][0] == len(np.unique(disc.offsets[0][:, 0]))  # one run per row of a disc
    for trial in range(6):
        h, w = rng.integers(60, 90, 2)
        costs = rng.integers(0, 250, (h, w)).astype(np.uint8)
        costs[rng.random((h, w)) < 0.002] = 254
        cm = Costmap(GridGeometry(RES, int(w), int(h), Pose2D(-0.3, 0.2, 0.0 if trial % 2 else 0.4)), costs)
        local = rng.uniform(0.3, 0.7, (20, 5, 2)) * np.array([w, h]) * RES
        xy = cm.geometry.origin.transform_points(local.reshape(-1, 2)).reshape(local.shape)
        poses = np.concatenate((xy, rng.uniform(-4, 4, (20, 5, 1))), axis=-1)
        for model in models:
            window = CostWindow.around(cm, poses, model.circumscribed, unknown_is_lethal=False)
            rows, cols = window.cells(poses)
            off = model.offsets[window._bins(poses[..., 2], model)]  # (20, 5, P, 2): numpy reference
            full = window.costs[rows[..., None] + off[..., 0], cols[..., None] + off[..., 1]].max(axis=-1)
            assert np.array_equal(window.footprint_costs(poses, model), full)
            if not model.round:
                assert np.array_equal(window.footprint_lethal(poses, model), full >= 254)


def test_compiled_distance_transform_equals_scipys() -> None:
    """The window's distance to the nearest lethal cell centre (a compiled two-pass exact
    transform, behind the round robots' collision test and the clearance) equals scipy's EDT."""
    rng = np.random.default_rng(5)
    for _ in range(60):
        h, w = rng.integers(1, 60, 2)
        costs = rng.integers(0, 256, (h, w)).astype(np.uint8)
        costs[rng.random((h, w)) < rng.uniform(0.0, 0.2)] = 254
        if not (costs >= 254).any():
            assert np.isinf(_lethal_sq_distance(costs)).all()
            continue
        want = ndimage.distance_transform_edt(costs < 254)
        np.testing.assert_allclose(np.sqrt(_lethal_sq_distance(costs)), want, rtol=0, atol=1e-12)
