"""Goal and progress checkers (Nav2 SimpleGoalChecker / SimpleProgressChecker semantics), and the
options plumbing from robot profiles."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nav.control import DwaOptions, GoalChecker, GoalCheckerOptions, ProgressChecker, ProgressCheckerOptions
from nav.control.trajectory import sample_twists
from nav.types import Pose2D, Twist2D
from robot.profiles import load_profile


def test_goal_checker_needs_position_and_heading() -> None:
    gc = GoalChecker()
    goal = Pose2D(1.0, 1.0, math.pi / 2)
    assert not gc.is_goal_reached(Pose2D(0.5, 1.0, math.pi / 2), goal)  # 0.5 m away
    gc.reset()
    assert not gc.is_goal_reached(Pose2D(1.2, 1.0, 0.0), goal)  # close, heading 90 deg off
    assert gc.is_goal_reached(Pose2D(1.2, 1.0, math.pi / 2 - 0.2), goal)


def test_goal_checker_is_stateful_once_inside_xy() -> None:
    goal = Pose2D(0.0, 0.0, 0.0)
    stateful, stateless = GoalChecker(), GoalChecker(GoalCheckerOptions(stateful=False))
    for gc in (stateful, stateless):
        assert not gc.is_goal_reached(Pose2D(0.2, 0.0, 1.5), goal)  # inside xy, wrong heading
    drifted = Pose2D(0.3, 0.0, 0.1)  # drifted out of xy while turning, heading now right
    assert stateful.is_goal_reached(drifted, goal)
    assert not stateless.is_goal_reached(drifted, goal)
    stateful.reset()
    assert not stateful.is_goal_reached(drifted, goal)


def test_stopped_goal_checker_wants_the_robot_stopped() -> None:
    gc = GoalChecker(GoalCheckerOptions(check_stopped=True))
    goal = Pose2D()
    assert not gc.is_goal_reached(Pose2D(0.1, 0.0, 0.0), goal, Twist2D(0.3, 0.0, 0.0))
    assert gc.is_goal_reached(Pose2D(0.1, 0.0, 0.0), goal, Twist2D(0.1, 0.0, 0.1))
    with pytest.raises(ValueError):
        GoalCheckerOptions(xy_goal_tolerance=0.0)


def test_progress_checker_times_out_without_movement() -> None:
    pc = ProgressChecker()
    assert pc.check(Pose2D(0.0, 0.0, 0.0), 0.0)
    assert pc.check(Pose2D(0.3, 0.0, 0.0), 9.9)  # still inside 0.5 m, within 10 s
    assert not pc.check(Pose2D(0.4, 0.0, 0.0), 10.1)
    assert pc.check(Pose2D(0.6, 0.0, 0.0), 10.2)  # left the circle: new baseline
    assert pc.time_without_progress(12.2) == pytest.approx(2.0)
    assert pc.check(Pose2D(0.6, 0.1, 0.0), 20.0) and not pc.check(Pose2D(0.6, 0.1, 0.0), 20.3)
    pc.reset()
    assert pc.check(Pose2D(0.6, 0.1, 0.0), 100.0)


def test_pose_progress_checker_counts_turning() -> None:
    pc = ProgressChecker(ProgressCheckerOptions(required_movement_angle=0.5))
    assert pc.check(Pose2D(), 0.0)
    assert pc.check(Pose2D(0.0, 0.0, 0.6), 9.0)  # turned enough: new baseline
    assert pc.check(Pose2D(0.0, 0.0, 0.7), 18.0)
    assert not pc.check(Pose2D(0.0, 0.0, 0.7), 19.1)


def test_options_from_robot_profiles() -> None:
    skid = DwaOptions.for_robot(load_profile("skid4"))
    assert not skid.holonomic and skid.max_vel_x == 0.26 and skid.max_vel_y == 0.0
    assert skid.footprint and skid.inscribed_radius == pytest.approx(0.10)
    assert skid.circumscribed_radius == pytest.approx(math.hypot(0.12, 0.10))
    omni = DwaOptions.for_robot(load_profile("omni4"), vy_samples=3)
    assert omni.holonomic and omni.max_vel_y == 1.5 and omni.min_vel_y == -1.5 and omni.vy_samples == 3
    assert not omni.footprint and omni.robot_radius == 0.25
    with pytest.raises(ValueError):
        DwaOptions.for_robot(load_profile("skid4"), no_such_field=1)
    with pytest.raises(ValueError):
        DwaOptions(critics=("NoSuchCritic",))


@settings(max_examples=60, deadline=None)
@given(
    vx=st.floats(-0.5, 0.5),
    wz=st.floats(-2.0, 2.0),
    acc=st.floats(0.1, 5.0),
    dt_hz=st.floats(5.0, 50.0),
)
def test_every_sample_is_reachable_and_within_limits(vx: float, wz: float, acc: float, dt_hz: float) -> None:
    o = DwaOptions(min_vel_x=-0.15, acc_lim_x=acc, decel_lim_x=-acc, controller_frequency=dt_hz)
    tw = sample_twists(o, Twist2D(vx, 0.0, wz))
    assert len(tw) > 0
    dt = 1.0 / dt_hz
    inside = min(max(vx, o.min_vel_x), o.max_vel_x)  # where an out-of-limits velocity is pulled to
    assert (tw[:, 0] >= o.min_vel_x - 1e-12).all() and (tw[:, 0] <= o.max_vel_x + 1e-12).all()
    assert (abs(tw[:, 2]) <= o.max_vel_theta + 1e-12).all()
    if inside == vx:
        assert (abs(tw[:, 0] - vx) <= acc * dt + 1e-9).all()
    if abs(wz) <= o.max_vel_theta:
        assert (abs(tw[:, 2] - wz) <= abs(o.acc_lim_theta) * dt + 1e-9).all()
    assert (tw[:, 1] == 0.0).all()
