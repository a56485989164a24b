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
