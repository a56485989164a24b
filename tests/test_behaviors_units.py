"""Recovery behaviours one by one: spin, spin until matched, back up, drive on heading, wait,
clear costmaps. Worlds are hand-made costmaps; the robot follows commands ideally."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.behaviors import (
    BackUp,
    BackUpOptions,
    BehaviorConfigError,
    BehaviorContext,
    ClearCostmap,
    ClearCostmapOptions,
    DriveOnHeading,
    DriveOnHeadingOptions,
    Relocalize,
    RelocalizeOptions,
    Spin,
    SpinOptions,
    SpinUntilMatched,
    SpinUntilMatchedOptions,
    Status,
    Wait,
    WaitOptions,
    make_behavior,
)
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Pose2D, Twist2D, wrap_angle

RES = 0.05
SKID = np.array([[0.12, 0.10], [-0.12, 0.10], [-0.12, -0.10], [0.12, -0.10]])


def empty_map(size: float = 4.0) -> Costmap:
    n = round(size / RES)
    return Costmap(GridGeometry(RES, n, n, Pose2D(-size / 2, -size / 2, 0.0)), np.zeros((n, n), np.uint8))


def with_block(cm: Costmap, x0: float, y0: float, x1: float, y1: float) -> Costmap:
    costs = cm.costs.copy()
    g = cm.geometry
    r0, c0 = g.world_to_cell(np.array([[x0, y0]]))
    r1, c1 = g.world_to_cell(np.array([[x1, y1]]))
    costs[int(r0[0]) : int(r1[0]) + 1, int(c0[0]) : int(c1[0]) + 1] = LETHAL_OBSTACLE
    return Costmap(g, costs)


def step(ctx: BehaviorContext, cmd: Twist2D, dt: float = 0.1) -> None:
    """Ideal body-frame velocity tracking for ``dt``; advances the context clock."""
    p = ctx.pose
    c, s = math.cos(p.theta), math.sin(p.theta)
    ctx.pose = Pose2D(
        p.x + (cmd.vx * c - cmd.vy * s) * dt,
        p.y + (cmd.vx * s + cmd.vy * c) * dt,
        float(wrap_angle(p.theta + cmd.wz * dt)),
    )
    ctx.velocity = cmd
    ctx.now += dt


def run(behavior, ctx: BehaviorContext, max_ticks: int = 2000) -> tuple[Status, list[Twist2D]]:
    status = behavior.start(ctx)
    cmds = [behavior.command]
    for _ in range(max_ticks):
        if status is not Status.RUNNING:
            return status, cmds
        step(ctx, behavior.command)
        status = behavior.tick(ctx)
        cmds.append(behavior.command)
    return status, cmds


def ctx_at(pose: Pose2D | None = None, costmap: Costmap | None = None, **kw) -> BehaviorContext:
    return BehaviorContext(
        now=0.0, pose=pose or Pose2D(), costmap=costmap or empty_map(), footprint=SKID, **kw
    )


# --- spin ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [math.pi / 2, -math.pi / 2, 1.5 * math.pi])
def test_spin_turns_the_requested_angle_and_stops(angle: float) -> None:
    spin = Spin(SpinOptions(spin_dist=angle))
    ctx = ctx_at(Pose2D(0.0, 0.0, 0.3))
    status, cmds = run(spin, ctx)
    assert status is Status.SUCCEEDED
    assert spin.turned == pytest.approx(angle, abs=0.06)
    assert float(wrap_angle(ctx.pose.theta - 0.3 - angle)) == pytest.approx(0.0, abs=0.06)
    assert cmds[-1].is_zero()
    moving = [c.wz for c in cmds[:-1]]
    assert all(math.copysign(1, w) == math.copysign(1, angle) for w in moving)
    assert max(abs(w) for w in moving) <= 1.0 + 1e-9
    assert min(abs(w) for w in moving) >= 0.4 - 1e-9
    assert ctx.pose.x == 0.0 and ctx.pose.y == 0.0


def test_spin_respects_base_limit() -> None:
    from nav.behaviors import BehaviorLimits

    spin = Spin(SpinOptions(spin_dist=3.0))
    ctx = ctx_at(limits=BehaviorLimits(max_vel_theta=0.5))
    _, cmds = run(spin, ctx)
    assert max(abs(c.wz) for c in cmds) <= 0.5 + 1e-9


def test_spin_fails_when_a_corner_would_hit_an_obstacle() -> None:
    # A wall 0.02 m beyond the front-left corner's turning circle radius (0.156 m) is hit when turning.
    cm = with_block(empty_map(), 0.10, 0.11, 0.2, 0.2)
    spin = Spin(SpinOptions(spin_dist=math.pi))
    status, cmds = run(spin, ctx_at(costmap=cm))
    assert status is Status.FAILED
    assert "collision" in spin.reason
    assert cmds[-1].is_zero()


def test_spin_times_out() -> None:
    spin = Spin(SpinOptions(spin_dist=3.0, time_allowance=1.0))
    ctx = ctx_at()
    status = spin.start(ctx)
    for _ in range(30):  # the base does not move: ticks with an unchanged pose
        ctx.now += 0.1
        status = spin.tick(ctx)
        if status is not Status.RUNNING:
            break
    assert status is Status.FAILED and "time allowance" in spin.reason


def test_spin_until_matched_stops_when_the_score_recovers() -> None:
    ctx = ctx_at()
    turned_when_matched = 2.0

    def score() -> float:  # the scan matches again once the robot has turned 2 rad
        return 0.9 if abs(spin.turned) >= turned_when_matched else 0.2

    ctx.scan_match_score = score
    spin = SpinUntilMatched(SpinUntilMatchedOptions(match_score_threshold=0.6))
    status, cmds = run(spin, ctx)
    assert status is Status.SUCCEEDED
    assert turned_when_matched <= abs(spin.turned) < turned_when_matched + 0.15
    assert cmds[-1].is_zero()


def test_spin_until_matched_gives_up_after_a_full_turn() -> None:
    ctx = ctx_at(scan_match_score=lambda: 0.1)
    spin = SpinUntilMatched()
    status, _ = run(spin, ctx)
    assert status is Status.FAILED
    assert abs(spin.turned) == pytest.approx(2 * math.pi, abs=0.06)
    assert "no match" in spin.reason


def test_spin_until_matched_trusts_a_match_only_after_min_turn() -> None:
    ctx = ctx_at(scan_match_score=lambda: 0.9)  # matched from the start (a look-alike place)
    spin = SpinUntilMatched(SpinUntilMatchedOptions(min_turn=2.0))
    status, _ = run(spin, ctx)
    assert status is Status.SUCCEEDED
    assert 2.0 - 1e-3 <= abs(spin.turned) < 2.15


def test_relocalize_restarts_localization_then_turns_a_whole_turn() -> None:
    resets: list[float] = []
    ctx = ctx_at(scan_match_score=lambda: 0.9)
    ctx.reinitialize_localization = lambda: resets.append(ctx.now)
    b = Relocalize()
    status, _ = run(b, ctx, max_ticks=5000)
    assert status is Status.SUCCEEDED
    assert resets == [0.0]  # once, at the start
    assert 2 * math.pi - 1e-3 <= abs(b.turned) < 2 * math.pi + 0.15
    # no match at all: two turns, then it gives up
    ctx = ctx_at(scan_match_score=lambda: 0.3, reinitialize_localization=lambda: None)
    b = Relocalize(RelocalizeOptions(time_allowance=100.0))
    status, _ = run(b, ctx, max_ticks=5000)
    assert status is Status.FAILED and "no match" in b.reason
    assert abs(b.turned) == pytest.approx(4 * math.pi, abs=0.06)


def test_relocalize_turns_where_the_costmap_says_it_cannot() -> None:
    # the lost robot's estimate sits on a wall: a Spin refuses, Relocalize (whose estimate is void
    # after the reinitialize) turns and leaves stopping to the safety layer
    walled = empty_map()
    walled.costs[:] = LETHAL_OBSTACLE
    assert Spin().start(ctx_at(costmap=walled)) is Status.FAILED
    ctx = ctx_at(costmap=walled, scan_match_score=lambda: 0.9, reinitialize_localization=lambda: None)
    b = Relocalize()
    assert b.start(ctx) is Status.RUNNING and b.command.wz != 0.0


def test_relocalize_needs_a_way_to_reinitialize() -> None:
    b = Relocalize()
    assert b.start(ctx_at(scan_match_score=lambda: 0.9)) is Status.FAILED
    assert "reinitialize" in b.reason


def test_spin_until_matched_needs_a_score() -> None:
    spin = SpinUntilMatched()
    assert spin.start(ctx_at()) is Status.FAILED


# --- back up / drive on heading -------------------------------------------------------------------


def test_back_up_reverses_the_distance() -> None:
    ctx = ctx_at(Pose2D(0.0, 0.0, math.pi / 4))
    b = BackUp(BackUpOptions(backup_dist=0.3, backup_speed=0.15))
    status, cmds = run(b, ctx)
    assert status is Status.SUCCEEDED
    assert ctx.pose.distance_to(Pose2D()) == pytest.approx(0.3, abs=0.02)
    assert ctx.pose.x < 0 and ctx.pose.y < 0  # behind the robot
    assert all(c.vx <= 0 and c.wz == 0 for c in cmds)
    assert min(c.vx for c in cmds) >= -0.15 - 1e-9


def test_back_up_refuses_to_start_when_blocked_behind() -> None:
    cm = with_block(empty_map(), -0.40, -0.3, -0.30, 0.3)  # wall 0.18 m behind the rear edge
    b = BackUp(BackUpOptions(backup_dist=0.3))
    ctx = ctx_at(costmap=cm)
    assert b.start(ctx) is Status.FAILED
    assert "refusing" in b.reason
    assert b.command.is_zero()


def test_back_up_halts_when_an_obstacle_appears_ahead_of_the_motion() -> None:
    ctx = ctx_at()
    b = BackUp(BackUpOptions(backup_dist=1.0, backup_speed=0.15))
    assert b.start(ctx) is Status.RUNNING
    for _ in range(5):
        step(ctx, b.command)
        assert b.tick(ctx) is Status.RUNNING
    ctx.costmap = with_block(empty_map(), -0.50, -0.3, -0.45, 0.3)  # someone steps in behind
    step(ctx, b.command)
    assert b.tick(ctx) is Status.FAILED
    assert "collision ahead" in b.reason and b.command.is_zero()
    assert ctx.pose.x - 0.12 > -0.45


def test_drive_on_heading_goes_forward_and_ramps() -> None:
    ctx = ctx_at()
    d = DriveOnHeading(DriveOnHeadingOptions(dist_to_travel=0.5, speed=0.2, acceleration_limit=0.5))
    status, cmds = run(d, ctx)
    assert status is Status.SUCCEEDED
    assert ctx.pose.x == pytest.approx(0.5, abs=0.03)
    assert cmds[0].vx == pytest.approx(0.1)  # minimum_speed from standstill
    speeds = [c.vx for c in cmds if c.vx > 0]
    assert max(np.diff(speeds)) <= 0.5 * 0.1 + 1e-9


def test_drive_needs_a_costmap() -> None:
    d = DriveOnHeading()
    ctx = BehaviorContext(now=0.0, pose=Pose2D())
    assert d.start(ctx) is Status.FAILED


# --- wait, clear costmaps ------------------------------------------------------------------------


def test_wait_waits_its_duration() -> None:
    w = Wait(WaitOptions(wait_duration=1.0))
    ctx = ctx_at()
    status, cmds = run(w, ctx)
    assert status is Status.SUCCEEDED
    assert ctx.now == pytest.approx(1.0, abs=0.11)
    assert all(c.is_zero() for c in cmds)


@pytest.mark.parametrize(("which", "expect"), [("local", ["L"]), ("global", ["G"]), ("both", ["L", "G"])])
def test_clear_costmap_calls_the_callback(which: str, expect: list[str]) -> None:
    calls: list[str] = []
    ctx = ctx_at(
        clear_local_costmap=lambda: calls.append("L"), clear_global_costmap=lambda: calls.append("G")
    )
    c = ClearCostmap(ClearCostmapOptions(costmap=which))  # type: ignore[arg-type]
    assert c.start(ctx) is Status.SUCCEEDED
    assert c.tick(ctx) is Status.SUCCEEDED
    assert calls == expect


def test_clear_costmap_fails_without_callback_or_on_error() -> None:
    assert make_behavior("clear_global_costmap").start(ctx_at()) is Status.FAILED

    def boom() -> None:
        raise RuntimeError("gone")

    c = make_behavior("clear_local_costmap")
    assert c.start(ctx_at(clear_local_costmap=boom)) is Status.FAILED
    assert "gone" in c.reason


# --- options ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "params", "field"),
    [
        ("back_up", {"backup_dist": -0.3}, "backup_dist"),
        ("back_up", {"backup_speed": -0.1}, "backup_speed"),
        ("drive_on_heading", {"speed": -1.0}, "speed"),
        ("spin", {"max_rotational_vel": 0.0}, "max_rotational_vel"),
        ("wait", {"wait_duration": -1.0}, "wait_duration"),
        ("spin", {"spin_speed": 1.0}, "spin_speed"),
        ("spin_until_matched", {"match_score_threshold": 1.5}, "match_score_threshold"),
        ("spin_until_matched", {"min_turn": -1.0}, "min_turn"),
        ("relocalize", {"min_turn": 20.0}, "relocalize.min_turn"),
    ],
)
def test_bad_options_are_refused_naming_the_field(name: str, params: dict, field: str) -> None:
    with pytest.raises(BehaviorConfigError, match=field):
        make_behavior(name, params)


def test_tick_before_start_is_an_error() -> None:
    with pytest.raises(RuntimeError):
        Wait().tick(ctx_at())
