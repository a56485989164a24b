"""Recovery policy: Nav2's round-robin order, the retry budget, per-trigger lists, events and
config validation."""

from __future__ import annotations

import math

import pytest
from test_behaviors_units import SKID, empty_map, step

from nav.behaviors import BehaviorContext, Status
from nav.recovery import (
    DEFAULT_STEPS,
    RecoveryConfigError,
    RecoveryEvent,
    RecoveryOptions,
    RecoveryPolicy,
    RecoveryStep,
    Trigger,
)
from nav.types import Pose2D


def make_ctx() -> tuple[BehaviorContext, list[str]]:
    cleared: list[str] = []
    ctx = BehaviorContext(
        now=0.0,
        pose=Pose2D(),
        costmap=empty_map(),
        footprint=SKID,
        clear_local_costmap=lambda: cleared.append("local"),
        clear_global_costmap=lambda: cleared.append("global"),
        scan_match_score=lambda: 0.0,
    )
    return ctx, cleared


def test_default_order_is_nav2s_round_robin() -> None:
    events: list[RecoveryEvent] = []
    policy = RecoveryPolicy(on_event=events.append)
    ctx, cleared = make_ctx()
    ran = []
    for _ in range(5):
        b = policy.on_failure(Trigger.CONTROLLER_FAILURE, ctx, detail="no valid control")
        assert b is not None
        ran.append(b.name)
        status = policy.run_to_end(ctx, lambda c, cmd: step(c, cmd))
        assert status is Status.SUCCEEDED, b.reason
    assert ran == ["clear_local_costmap", "clear_global_costmap", "spin", "wait", "back_up"]
    assert cleared == ["local", "global"]
    kinds = [(e.kind, e.behavior) for e in events]
    assert kinds[:4] == [
        ("attempt", "clear_local_costmap"),
        ("result", "clear_local_costmap"),
        ("attempt", "clear_global_costmap"),
        ("result", "clear_global_costmap"),
    ]
    results = [e for e in events if e.kind == "result"]
    assert all(e.status == "succeeded" for e in results)
    assert [e.attempt for e in results] == [1, 2, 3, 4, 5]
    assert events[0].detail == "no valid control"
    assert events[0].as_dict()["trigger"] == "controller_failure"


def run_attempts(
    policy: RecoveryPolicy, trigger: Trigger, ctx, n: int, expect: Status | None = None
) -> list[str]:
    """``n`` failures with ``trigger``, each recovery run to its end; the behaviours' names."""
    names = []
    for _ in range(n):
        b = policy.on_failure(trigger, ctx)
        assert b is not None
        names.append(b.name)
        status = policy.run_to_end(ctx, lambda c, cmd: step(c, cmd))
        assert expect is None or status is expect
    return names


def test_retry_budget_then_give_up() -> None:
    policy = RecoveryPolicy(RecoveryOptions(number_of_retries=6))
    ctx, _ = make_ctx()
    names = run_attempts(policy, Trigger.NO_PROGRESS, ctx, 6)
    assert names[5] == "clear_local_costmap"  # wrapped around the round robin
    assert policy.exhausted and policy.retries_left == 0
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx) is None
    assert policy.events[-1].kind == "exhausted"
    assert "number_of_retries" in policy.events[-1].reason
    n_events = len(policy.events)
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx) is None  # the navigator asks every tick...
    assert len(policy.events) == n_events  # ...and the run log says so once
    policy.on_goal_reached()
    b = policy.on_failure(Trigger.NO_PROGRESS, ctx)
    assert b is not None and b.name == "clear_local_costmap"


def test_localization_divergence_spins_until_matched_then_relocalizes() -> None:
    policy = RecoveryPolicy()
    ctx, _ = make_ctx()
    resets: list[float] = []
    ctx.reinitialize_localization = lambda: resets.append(ctx.now)
    ctx.scan_match_score = lambda: 0.9  # matched all along (e.g. a look-alike room)
    b = policy.on_failure(Trigger.LOCALIZATION_DIVERGENCE, ctx)
    assert b is not None and b.name == "spin_until_matched"
    assert policy.run_to_end(ctx, lambda c, cmd: step(c, cmd)) is Status.SUCCEEDED
    assert math.pi - 1e-3 <= abs(b.turned) < math.pi + 0.15  # half a turn before a match counts
    assert not resets
    # lost again: localization restarts over the whole map, and the robot turns a whole turn
    b = policy.on_failure(Trigger.LOCALIZATION_DIVERGENCE, ctx)
    assert b is not None and b.name == "relocalize"
    assert policy.run_to_end(ctx, lambda c, cmd: step(c, cmd)) is Status.SUCCEEDED
    assert len(resets) == 1 and abs(b.turned) >= 2 * math.pi - 1e-3
    # other triggers keep their own place in the default list
    assert policy.on_failure(Trigger.PLANNER_FAILURE, ctx).name == "clear_local_costmap"


def test_safety_stop_waits_then_backs_away() -> None:
    policy = RecoveryPolicy()
    ctx, _ = make_ctx()
    assert run_attempts(policy, Trigger.SAFETY_STOP, ctx, 2, expect=Status.SUCCEEDED) == ["wait", "back_up"]
    assert ctx.pose.x == pytest.approx(-0.30, abs=0.02)


def test_failed_behaviour_is_reported_and_counted() -> None:
    opts = RecoveryOptions(steps=(RecoveryStep("back_up", {"backup_dist": 0.3}), RecoveryStep("wait")))
    policy = RecoveryPolicy(opts)
    ctx, _ = make_ctx()
    costs = ctx.costmap.costs.copy()
    costs[:, : costs.shape[1] // 2 - 3] = 254  # wall right behind the robot
    ctx.costmap = type(ctx.costmap)(ctx.costmap.geometry, costs)
    b = policy.on_failure(Trigger.NO_PROGRESS, ctx)
    assert b is not None and policy.active is None  # refused at start
    res = policy.events[-1]
    assert res.kind == "result" and res.status == "failed" and "refusing" in res.reason
    assert policy.attempts == 1
    assert policy.command.is_zero()
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait"


def test_disabled_trigger_is_rejected() -> None:
    policy = RecoveryPolicy(RecoveryOptions(enabled_triggers=("planner_failure",)))
    ctx, _ = make_ctx()
    assert policy.on_failure(Trigger.SAFETY_STOP, ctx) is None
    assert policy.events[-1].kind == "rejected"
    assert policy.on_failure(Trigger.PLANNER_FAILURE, ctx) is not None


def test_command_follows_the_active_behaviour() -> None:
    policy = RecoveryPolicy(RecoveryOptions(steps=(RecoveryStep("spin", {"spin_dist": -1.0}),)))
    ctx, _ = make_ctx()
    policy.on_failure(Trigger.NO_PROGRESS, ctx)
    assert policy.command.wz < 0
    policy.run_to_end(ctx, lambda c, cmd: step(c, cmd))
    assert policy.command.is_zero()
    assert ctx.pose.theta == pytest.approx(-1.0, abs=0.06)


# --- configuration ------------------------------------------------------------------------------


def test_from_mapping_accepts_names_and_tables() -> None:
    opts = RecoveryOptions.from_mapping(
        {
            "steps": [
                "clear_costmaps",
                {"behavior": "back_up", "backup_dist": 0.2},
                {"behavior": "wait", "params": {}},
            ],
            "number_of_retries": 3,
            "trigger_steps": {"safety_stop": ["back_up"]},
        }
    )
    assert [s.behavior for s in opts.steps] == ["clear_costmaps", "back_up", "wait"]
    assert opts.steps[1].params == {"backup_dist": 0.2}
    assert opts.number_of_retries == 3
    assert RecoveryPolicy(opts).steps_for(Trigger.SAFETY_STOP)[0].behavior == "back_up"
    assert [s.behavior for s in RecoveryOptions().steps] == [s.behavior for s in DEFAULT_STEPS]


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"steps": ["spin", "moonwalk"]}, r"recovery\.steps\[1\]\.behavior"),
        (
            {"steps": [{"behavior": "back_up", "backup_dist": -0.3}]},
            r"recovery\.steps\[0\]\.back_up\.backup_dist",
        ),
        ({"steps": [{"behavior": "back_up", "backup_speed": -1}]}, "backup_speed"),
        ({"steps": [{"behavior": "drive_on_heading", "speed": -0.1}]}, "speed"),
        ({"steps": []}, r"recovery\.steps"),
        ({"number_of_retries": -1}, "number_of_retries"),
        ({"retries": 3}, r"recovery\.retries"),
        ({"trigger_steps": {"meteor": ["spin"]}}, r"trigger_steps\.meteor"),
        ({"trigger_steps": {"safety_stop": ["warp"]}}, r"trigger_steps\.safety_stop\[0\]"),
        ({"enabled_triggers": ["planner_failure", "bored"]}, r"enabled_triggers\[1\]"),
    ],
)
def test_bad_config_is_refused_naming_the_field(data: dict, field: str) -> None:
    with pytest.raises(RecoveryConfigError, match=field):
        RecoveryOptions.from_mapping(data)
