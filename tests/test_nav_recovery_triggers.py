"""Recovery triggers the navigator cannot see itself, end to end in the simulator (issue 5): a
robot carried 5 m away while navigating (localization divergence) and a safety layer that keeps
stopping the robot (safety stop)."""

from __future__ import annotations

import math

from app.commands.sim_nav import build_sim_stack, drive
from bench.scenarios.kidnap import kidnap_trials
from nav.types import Pose2D
from robot.safety import SafetyFilter, SafetyOptions
from robot.sim import World


def test_kidnapped_robot_relocalizes_and_reaches_its_goal_within_30_s() -> None:
    # Trials 0 and 7 of the seeded apartment set (bench: scenarios.kidnap). In 7 the filter first
    # settles on a wrong place nearby (fit 0.67): only the divergence monitor notices, and the
    # spin_until_matched recovery finds the robot again.
    ks = kidnap_trials(8, only=frozenset({0, 7}))
    assert len(ks.trials) == 2
    for t in ks.trials:
        assert 4.5 <= t.distance_m <= 5.25, t
        assert t.ok, t  # reached, with the true pose at the goal
        assert t.back_on_way_s is not None and t.back_on_way_s <= 30.0, t
        assert t.result.result.collisions == 0
    lost = ks.trials[1]
    assert ("localization_divergence", "spin_until_matched") in lost.recoveries, lost.recoveries


def test_a_robot_refound_a_little_off_on_a_wall_recovers_as_lost() -> None:
    # Trial 1: the filter re-finds the carried robot 0.36 m off with a good fit (0.88), its
    # footprint on a wall of the map; nothing moves, so the filter never updates. Stuck there, the
    # navigator blames localization: the localization_divergence list runs (spin_until_matched,
    # then relocalize, which turns although the estimate is in a wall). Before PreferForward three
    # planner-failure recoveries ran first and both of the list ran (back on its way after 30.7 s);
    # now the first of the list suffices (8.3 s).
    ks = kidnap_trials(2, only=frozenset({1}))
    (t,) = ks.trials
    assert t.ok, t
    assert any(trigger == "localization_divergence" for trigger, _ in t.recoveries), t.recoveries
    assert t.result.result.collisions == 0


def test_a_safety_layer_that_keeps_stopping_the_robot_starts_the_safety_stop_recovery() -> None:
    # A safety layer configured far more cautious than the planner: a stop zone 2.2 m around the
    # footprint stops every forward command once the far wall is that close, 0.2 m before the
    # goal's tolerance; the controller keeps asking to go on. After safety_stop_timeout (5 s) the
    # navigator halts with SafetyStop and the safety_stop list runs (wait, then back up).
    grid = World.box(10.0, 4.0).grid
    world = World.box(10.0, 4.0)
    start = Pose2D(2.0, 2.0, 0.0)
    stack = build_sim_stack(grid, world, start, seed=3)
    try:
        stack.session.safety = SafetyFilter(
            stack.driver.profile,
            SafetyOptions(
                stop_margin=2.2, slowdown_margin=2.2, slowdown_enabled=False, approach_enabled=False
            ),
        )
        stack.localization.set_initial_pose(start)
        drive(stack, [Pose2D(8.0, 2.0, 0.0)], 45.0)
        events = stack.session.events
        attempts = [e for e in events if e["type"] == "recovery" and e.get("kind") == "attempt"]
        assert attempts, [e for e in events if e["type"] in ("recovery", "navigation")]
        first = attempts[0]
        assert first["trigger"] == "safety_stop" and first["behavior"] == "wait", first
        assert "SafetyStop" in first["detail"], first
        assert stack.session.collisions == 0
        started = [e for e in events if e["type"] == "recovery" and e.get("status") == "started"]
        assert started and started[0]["reason"] == "SafetyStop"
        assert math.isfinite(started[0]["t"]) and started[0]["t"] >= 5.0
    finally:
        stack.session.close()


def test_a_walker_on_the_path_at_a_failure_makes_the_robot_wait_then_go() -> None:
    # Greenhouse aisle (1.2 m wide): a walker paces the aisle 1.5-2 m ahead of the robot, then walks
    # on out of it. The navigation stops for a cause of its own (halt: the controller stood still)
    # with the walker on the path: the robot waits for it, stopped, without spending the retry
    # budget, and drives on once the walker has left (before: clear_local_costmap, then the rest
    # of the round robin, with the walker still there).
    world = World.stock("greenhouse")
    start = Pose2D(4.0, 6.2, 0.0)
    stack = build_sim_stack(world.grid, world, start, localization="truth", controller="dwa", seed=0)
    s, nav = stack.session, stack.navigation
    events: list[dict] = []
    add_event = s.add_event

    def record(kind: str, /, **data) -> None:
        if kind == "recovery" and "behavior" in data:
            events.append(data)
        add_event(kind, **data)

    try:
        s.add_event = record
        far_end = [[10.8, 9.6], [10.8, 9.0]] * 20  # it stays out of the way there
        stack.driver.people.add_loop([[5.6, 6.2], [6.2, 6.2]] * 3 + [[10.8, 6.2], *far_end], speed=0.5)
        stack.localization.set_initial_pose(start)
        nav.set_goals([Pose2D(11.0, 6.2, 0.0)])
        s.run_for(1.0)  # a path, and the walker tracked
        assert nav.walker_on_path(s.clock.now())
        nav.navigator.halt("Stalled", "the controller stood still")
        t0 = s.clock.now()
        commands_while_waiting = []
        while s.clock.now() - t0 < 60.0 and (nav.active or nav.last_outcome is None):
            s.run_for(s.period)
            if len(events) == 1:
                commands_while_waiting.append(s.last_command)
        wait, done = events[0], events[1]
        assert (wait["kind"], wait["behavior"], wait["attempt"]) == ("attempt", "wait_for_walker", 0)
        assert (done["kind"], done["behavior"], done["status"]) == ("result", "wait_for_walker", "succeeded")
        assert 2.0 < done["t"] - wait["t"] < 10.0  # until the walker left, not the full wait
        braking = round(0.5 / s.period)  # the base decelerates from its speed at the halt
        moving = [c for c in commands_while_waiting[braking:] if c is not None and not c.is_zero()]
        assert not moving, moving[:3]  # stopped while waiting
        assert nav.last_outcome is not None and nav.last_outcome["kind"] == "reached"
        assert nav.recovery.policy.attempts == 0  # the budget was not touched
    finally:
        s.close()
