"""TEB local planner: limits on the optimized band, corridor following, bending around an obstacle on
the path (diff and omni), warm start, failures and options."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from bench.teb import corridor, omni_options, skid_options, straight_path
from nav.control import ControllerError, InvalidPath, NoValidControl
from nav.control.errors import PatienceExceeded
from nav.control.teb import DistanceField, TebController, TebDebug, band_fold
from nav.control.teb_options import FORWARD_DRIVE_WEIGHT, TebConfigError, TebOptions
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Path, Pose2D, Twist2D, wrap_angle
from robot.profiles import load_profile

SKID_INSCRIBED = 0.10
DIFF = skid_options()
OMNI = omni_options()
INSCRIBED = {"diff": SKID_INSCRIBED, "omni": 0.25}
KINDS = {"diff": DIFF, "omni": OMNI}


def integrate(p: Pose2D, c: Twist2D, dt: float) -> Pose2D:
    ct, st = math.cos(p.theta), math.sin(p.theta)
    return Pose2D(
        p.x + (c.vx * ct - c.vy * st) * dt,
        p.y + (c.vx * st + c.vy * ct) * dt,
        float(wrap_angle(p.theta + c.wz * dt)),
    )


def drive(ctl: TebController, costmap: Costmap, goal: Pose2D, seconds: float, dt: float = 0.2):
    """Closed loop with ideal velocity tracking at 5 Hz (the command's own acceleration limiting
    uses the controller's period, 0.1 s, so the robot's speed changes at most 2x the limit)."""
    pose, vel = Pose2D(), Twist2D()
    poses, cmds, bands = [pose], [], []
    for _ in range(round(seconds / dt)):
        if pose.distance_to(goal) < ctl.options.xy_goal_tolerance:
            return poses, cmds, bands, True
        cmd, dbg = ctl.compute(pose, vel, costmap)
        pose, vel = integrate(pose, cmd, dt), cmd
        poses.append(pose)
        cmds.append(cmd)
        bands.append(dbg)
    return poses, cmds, bands, False


def assert_band_within_limits(dbg: TebDebug, o: TebOptions, slack: float) -> None:
    v, a = dbg.velocities, dbg.accelerations
    assert np.all(v[:, 0] <= o.max_vel_x * (1 + slack))
    assert np.all(v[:, 0] >= -o.max_vel_x_backwards * (1 + slack) - 1e-9)
    assert np.all(np.abs(v[:, 2]) <= o.max_vel_theta * (1 + slack))
    assert np.all(np.abs(a[:, 0]) <= o.acc_lim_x * (1 + slack))
    assert np.all(np.abs(a[:, 2]) <= o.acc_lim_theta * (1 + slack))
    if o.holonomic:
        assert np.all(np.abs(v[:, 1]) <= o.max_vel_y * (1 + slack))
        assert np.all(np.abs(a[:, 1]) <= o.acc_lim_y * (1 + slack))
    assert np.all(dbg.dts > 0)


# --- distance field ----------------------------------------------------------------------------


def test_distance_field_is_signed_and_continuous() -> None:
    cm = corridor((2.0, 0.0, 0.3))
    f = DistanceField(cm)
    pts = np.array([[2.0, 0.0], [2.6, 0.0], [3.0, 0.0], [2.0, 0.6]])
    d = f(pts)
    assert d[0] < -0.2  # deep inside the obstacle
    assert d[1] == pytest.approx(0.3, abs=0.06)
    assert d[2] == pytest.approx(0.7, abs=0.06)
    assert d[3] == pytest.approx(0.3, abs=0.06)
    xs = np.linspace(2.4, 2.8, 200)
    vals = f(np.column_stack((xs, np.zeros_like(xs))))
    assert np.max(np.abs(np.diff(vals))) < 0.01  # bilinear: no jumps between cells
    assert np.all(DistanceField(corridor(width=2.0)).field[5:-5] > 0)


# --- following and limits ------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["diff", "omni"])
def test_follows_a_straight_corridor_within_limits(kind: str) -> None:
    o = KINDS[kind]
    ctl = TebController(o)
    ctl.set_path(straight_path(2.0, 41))
    poses, cmds, bands, reached = drive(ctl, corridor(), Pose2D(2.0, 0.0), seconds=20.0)
    assert reached
    assert max(abs(p.y) for p in poses) < 0.05
    for dbg in bands[::5]:
        assert_band_within_limits(dbg, o, slack=0.05)
    vx = np.array([c.vx for c in cmds])
    assert vx.max() <= o.max_vel_x + 1e-9
    assert vx.max() > 0.7 * min(o.max_vel_x, math.sqrt(o.acc_lim_x * 2.0))  # it gets up to speed
    assert np.all(np.abs(np.diff(vx)) <= o.acc_lim_x * o.control_period + 1e-9)  # smoothed
    assert len(bands[0].band) <= o.max_samples


@pytest.mark.parametrize("kind", ["diff", "omni"])
def test_bends_around_an_obstacle_on_the_path(kind: str) -> None:
    o = KINDS[kind]
    obstacle = (1.0, 0.0, 0.15)
    cm = corridor(obstacle)
    ctl = TebController(o)
    ctl.set_path(straight_path())
    _, dbg = ctl.compute(Pose2D(), Twist2D(), cm)
    # the very first band already goes around, with clearance along its whole length
    centre_clear = np.hypot(dbg.band[:, 0] - obstacle[0], dbg.band[:, 1] - obstacle[1]) - obstacle[2]
    assert centre_clear.min() > INSCRIBED[kind]
    assert np.abs(dbg.band[:, 1]).max() > obstacle[2]
    assert_band_within_limits(dbg, o, slack=0.25)
    ctl.reset()
    ctl.set_path(straight_path(2.0, 41))
    poses, _, bands, reached = drive(ctl, cm, Pose2D(2.0, 0.0), seconds=20.0)
    assert reached
    xy = np.array([[p.x, p.y] for p in poses])
    robot_clear = np.hypot(xy[:, 0] - obstacle[0], xy[:, 1] - obstacle[1]) - obstacle[2]
    assert robot_clear.min() > INSCRIBED[kind]
    assert abs(poses[-1].y) < 0.15  # rejoining the global path
    for b in bands:
        bc = np.hypot(b.band[:, 0] - obstacle[0], b.band[:, 1] - obstacle[1]) - obstacle[2]
        assert bc.min() > INSCRIBED[kind] - 0.02


def test_diff_band_is_non_holonomic() -> None:
    ctl = TebController(DIFF)
    ctl.set_path(straight_path())
    cmd, dbg = ctl.compute(Pose2D(), Twist2D(), corridor((1.5, 0.0, 0.15)))
    assert cmd.vy == 0.0
    p = dbg.band
    d = np.diff(p[:, :2], axis=0)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    nh = (c[:-1] + c[1:]) * d[:, 1] - (s[:-1] + s[1:]) * d[:, 0]
    assert np.abs(nh).max() < 0.01  # headings stay tangent to the band (TEB's nh constraint)


def test_omni_may_move_sideways() -> None:
    ctl = TebController(OMNI)
    poses = np.column_stack((np.zeros(41), np.linspace(0.0, 2.0, 41), np.zeros(41)))
    ctl.set_path(Path(poses))
    cmd, _ = ctl.compute(Pose2D(), Twist2D(), corridor(width=5.0))
    assert cmd.vy >= 0.099 and abs(cmd.vx) < 0.5 * cmd.vy and abs(cmd.wz) < 0.1


# --- warm start ---------------------------------------------------------------------------------


def test_warm_start_keeps_the_band_around_the_obstacle() -> None:
    obstacle = (1.2, 0.0, 0.15)
    cm = corridor(obstacle)
    ctl = TebController(DIFF)
    ctl.set_path(straight_path())
    cmd, cold = ctl.compute(Pose2D(), Twist2D(), cm)
    assert not cold.warm_started
    side = np.sign(cold.band[np.argmin(np.abs(cold.band[:, 0] - obstacle[0])), 1])
    pose = integrate(Pose2D(), cmd, 0.1)
    _, warm = ctl.compute(pose, cmd, cm)
    assert warm.warm_started
    np.testing.assert_allclose(warm.band[0], pose.as_array())
    at_obstacle = warm.band[np.argmin(np.abs(warm.band[:, 0] - obstacle[0])), 1]
    assert np.sign(at_obstacle) == side  # same homotopy class
    # the warm band starts close to the optimum: a re-optimization from it costs less
    assert warm.cost <= cold.cost * 1.5
    ctl.set_path(Path(straight_path().poses[:, :] + [0.0, 0.0, 0.0]))  # same goal: band kept
    _, again = ctl.compute(pose, cmd, cm)
    assert again.warm_started
    ctl.set_path(straight_path(4.0))  # new goal: band dropped
    _, fresh = ctl.compute(pose, cmd, cm)
    assert not fresh.warm_started


def test_band_fold_measures_how_far_a_band_runs_backwards() -> None:
    ref = straight_path(3.0).poses
    xs = np.linspace(0.0, 2.0, 21)
    forward = np.column_stack((xs, 0.2 * np.sin(xs), np.zeros_like(xs)))
    assert band_fold(forward, ref) == pytest.approx(0.0, abs=1e-9)
    # out 1.5 m, back 1.0 m, out again: the band doubles back by 1 m
    xs = np.concatenate((np.linspace(0, 1.5, 16), np.linspace(1.4, 0.5, 10), np.linspace(0.6, 2.0, 15)))
    folded = np.column_stack((xs, np.zeros_like(xs), np.zeros_like(xs)))
    assert band_fold(folded, ref) == pytest.approx(1.0, abs=1e-6)


def _open_floor() -> Costmap:
    geo = GridGeometry(0.05, 240, 80, Pose2D(-6.0, -2.0, 0.0))
    return Costmap(geo, np.zeros((80, 240), np.uint8))


def _polyline(*corners: tuple[float, float], step: float = 0.05) -> Path:
    """A path through ``corners`` ending at heading 0 (the navigator sets the goal's heading last)."""
    pts = [np.asarray(corners[0], float)]
    for a, b in itertools.pairwise(corners):
        a, b = np.asarray(a, float), np.asarray(b, float)
        k = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        pts += [a + (b - a) * t for t in np.linspace(0, 1, k + 1)[1:]]
    xy = np.array(pts)
    th = np.arctan2(*np.diff(xy[:, ::-1], axis=0).T)
    return Path(np.column_stack((xy, np.append(th, 0.0))))


@pytest.mark.parametrize("kind", ["diff", "omni"])
def test_replan_onto_another_route_reinitializes_the_band(kind: str) -> None:
    """A replan to the same goal by another way (the greenhouse's blocked aisle: back out and round)
    moves the local goal behind the robot. Extending the old band to it folded the band back on
    itself; TEB re-initializes instead (force_reinit_new_goal_dist) and never sends a folded band."""
    cm = _open_floor()
    ctl = TebController(KINDS[kind])
    ctl.set_path(_polyline((0.0, 0.0), (5.0, 0.0)))
    pose, vel = Pose2D(), Twist2D()
    for _ in range(5):
        cmd, dbg = ctl.compute(pose, vel, cm)
        pose, vel = integrate(pose, cmd, 0.1), cmd
    assert dbg.warm_started and band_fold(dbg.band, dbg.reference) < 0.05
    # same goal, new route: back to x = -3, across, and along y = 1.2 to the goal
    ctl.set_path(_polyline((pose.x, pose.y), (-3.0, 0.0), (-3.0, 1.2), (5.0, 1.2), (5.0, 0.0)))
    _, dbg = ctl.compute(pose, vel, cm)
    assert not dbg.warm_started
    assert dbg.local_goal[0] < pose.x - 1.0  # the local goal is behind the robot now
    assert band_fold(dbg.band, dbg.reference) <= ctl.options.fold_reinit_dist
    assert dbg.band[1:, 0].max() < pose.x + 0.3  # the band heads back, not out and round


# --- goal, failures -----------------------------------------------------------------------------


def test_rotates_to_the_goal_heading_inside_the_tolerance() -> None:
    ctl = TebController(DIFF)
    poses = straight_path(1.0).poses.copy()
    poses[-1, 2] = math.pi / 2
    ctl.set_path(Path(poses))
    cmd, _ = ctl.compute(Pose2D(0.95, 0.0, 0.0), Twist2D(), corridor())
    assert cmd.vx == 0.0 and cmd.wz > 0
    cmd, _ = ctl.compute(Pose2D(0.95, 0.0, math.pi / 2 - 0.05), Twist2D(), corridor())
    assert cmd.is_zero()


def test_blocked_corridor_raises_no_valid_control_then_patience() -> None:
    cm = corridor((0.5, 0.0, 0.15), width=0.6)  # 0.15 m gaps beside the obstacle: no way through
    ctl = TebController(DIFF)
    ctl.set_path(straight_path())
    pose = Pose2D(0.2, 0.0, 0.0)
    with pytest.raises(NoValidControl) as info:
        ctl.compute(pose, Twist2D(), cm)
    assert not isinstance(info.value, PatienceExceeded)
    assert "collides" in str(info.value)
    with pytest.raises(PatienceExceeded):
        for _ in range(10):
            try:
                ctl.compute(pose, Twist2D(), cm)
            except PatienceExceeded:
                raise
            except NoValidControl:
                pass


def test_interface_errors() -> None:
    ctl = TebController(DIFF)
    with pytest.raises(ControllerError):
        ctl.compute(Pose2D(), Twist2D(), corridor())
    with pytest.raises(InvalidPath):
        ctl.set_path(Path(np.zeros((0, 3))))
    with pytest.raises(InvalidPath):
        ctl.set_path(Path(np.array([[0.0, np.nan, 0.0]])))
    ctl.set_path(straight_path())
    with pytest.raises(ControllerError):
        ctl.compute(Pose2D(math.inf, 0, 0), Twist2D(), corridor())


# --- options ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"max_vel_x": -1.0}, "max_vel_x"),
        ({"max_vel_x_backwards": -0.1}, "max_vel_x_backwards"),
        ({"dt_ref": 0.0}, "dt_ref"),
        ({"weight_obstacle": -5.0}, "weight_obstacle"),
        ({"min_samples": 2}, "min_samples"),
        ({"max_samples": 1000}, "max_samples"),
        ({"holonomic": True, "max_vel_y": 0.0}, "max_vel_y"),
        ({"min_obstacle_dist": 0.5, "inflation_dist": 0.2}, "inflation_dist"),
        ({"solver": "gauss_newton"}, "solver"),
        ({"solver_ftol": 1.0}, "solver_ftol"),
        ({"force_reinit_new_goal_dist": 0.0}, "force_reinit_new_goal_dist"),
        ({"fold_reinit_dist": -1.0}, "fold_reinit_dist"),
    ],
)
def test_bad_options_name_the_field(kw: dict, field: str) -> None:
    with pytest.raises(TebConfigError, match=field):
        TebOptions(**kw)


def test_options_for_robot_profiles() -> None:
    skid = TebOptions.for_robot(load_profile("skid4"))
    assert not skid.holonomic and skid.max_vel_x == 0.26 and skid.max_vel_x_backwards == 0.15
    assert skid.circumscribed_radius == pytest.approx(math.hypot(0.12, 0.10))
    omni = TebOptions.for_robot(load_profile("omni4"), max_samples=40)
    assert omni.holonomic and omni.max_vel_y == 1.5 and omni.robot_radius == 0.25 and omni.max_samples == 40
    with pytest.raises(TebConfigError, match="bogus"):
        TebOptions.for_robot(load_profile("omni4"), bogus=1)


def test_feasibility_treats_lethal_cells_as_points_at_their_centres() -> None:
    """A gap one cell wider than a 0.5 m round robot, with a lidar mark one cell into it on each
    side (the greenhouse post): cell edges 0.5 m apart, centres 0.55 m. The outline test closes it
    for good; the centre test leaves the robot +-2.5 cm, and still sees an obstacle inside the
    footprint, which the outline test misses."""
    from nav.control.teb import centre_collisions
    from nav.costmap.footprint import circle_footprint, footprint_cost

    res = 0.05
    costs = np.zeros((40, 40), dtype=np.uint8)
    costs[10, 15:25] = 254  # lower mark: cell y 0.50-0.55
    costs[21, 15:25] = 254  # upper mark: cell y 1.05-1.10 -> edges 0.55 / 1.05, centres 0.525 / 1.075
    cm = Costmap(GridGeometry(res, 40, 40, Pose2D()), costs)
    poly = circle_footprint(0.25)
    centred = np.array([[1.0, 0.80, 0.0]])
    up = np.array([0.0, 1.0, 0.0])
    assert footprint_cost(cm, centred + 0.001 * up, poly)[0] == 254  # knife edge: 1 mm off
    for round_radius in (None, 0.25):
        assert not centre_collisions(cm, centred + 0.02 * up, poly, round_radius)[0]
        assert not centre_collisions(cm, centred - 0.02 * up, poly, round_radius)[0]
        assert centre_collisions(cm, centred + 0.03 * up, poly, round_radius)[0]
    inside = np.zeros_like(costs)
    inside[16, 20] = 254  # one cell well inside the footprint, none on its outline
    cm_in = Costmap(cm.geometry, inside)
    assert footprint_cost(cm_in, centred, poly)[0] != 254
    assert centre_collisions(cm_in, centred, poly)[0] and centre_collisions(cm_in, centred, poly, 0.25)[0]
    # off the map: free unless unknown is lethal
    edge = np.array([[0.1, 1.0, 0.0]])
    assert not centre_collisions(cm, edge, poly)[0]
    assert centre_collisions(cm, edge, poly, None, unknown_is_lethal=True)[0]


def test_reversing_skid_base_gets_teb_forward_drive_weight_omni_does_not() -> None:
    assert TebOptions.for_robot(load_profile("skid4")).weight_kinematics_forward_drive == FORWARD_DRIVE_WEIGHT
    assert TebOptions.for_robot(load_profile("omni4")).weight_kinematics_forward_drive == 1.0
    # an explicit override still wins
    opts = TebOptions.for_robot(load_profile("skid4"), weight_kinematics_forward_drive=1.0)
    assert opts.weight_kinematics_forward_drive == 1.0


def test_band_seed_never_jumps_over_an_obstacle() -> None:
    """Two posts flank the path 0.5 m apart (0.18 m left, 0.32 m right: closer together than the
    band's clearance from both). Seeding the band, a pose beside the left post is moved only where
    it can go without nearing the post: the band stays between the posts. It used to be pushed on
    through the post to its far side (y 0.525), so the band zigzagged round the post and every
    cycle's band collided (a table's legs in apartment 8, world 679961800)."""
    left, right = (1.5, 0.18, 0.03), (1.5, -0.32, 0.03)
    cm = corridor(left)
    rows, cols = np.indices(cm.costs.shape)
    xy = cm.geometry.cell_to_world(rows.ravel(), cols.ravel())
    post = np.hypot(xy[:, 0] - right[0], xy[:, 1] - right[1]) <= right[2]
    cm.costs[post.reshape(cm.costs.shape)] = LETHAL_OBSTACLE
    ctl = TebController(DIFF)
    ctl.set_path(straight_path(3.0, 61))
    cmd, dbg = ctl.compute(Pose2D(1.0, 0.0, 0.0), Twist2D(0.2, 0.0, 0.0), cm)
    assert dbg.band[:, 1].max() < left[1] - left[2]
    assert dbg.band[:, 1].min() > right[1] + right[2]
    assert cmd.vx > 0.0
