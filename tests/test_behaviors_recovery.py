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


def _wall_behind(ctx: BehaviorContext) -> None:
    costs = ctx.costmap.costs.copy()
    costs[:, : costs.shape[1] // 2 - 3] = 254  # wall right behind the robot
    ctx.costmap = type(ctx.costmap)(ctx.costmap.geometry, costs)


def test_failed_behaviour_is_reported_and_counted_the_nav2_way() -> None:
    opts = RecoveryOptions(
        steps=(RecoveryStep("back_up", {"backup_dist": 0.3}), RecoveryStep("wait")), count_failed_starts=True
    )
    policy = RecoveryPolicy(opts)
    ctx, _ = make_ctx()
    _wall_behind(ctx)
    b = policy.on_failure(Trigger.NO_PROGRESS, ctx)
    assert b is not None and policy.active is None  # refused at start
    res = policy.events[-1]
    assert res.kind == "result" and res.status == "failed" and "refusing" in res.reason
    assert policy.attempts == 1
    assert policy.command.is_zero()
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait"


def test_a_refused_behaviour_spends_nothing_and_the_next_step_starts_at_once() -> None:
    # apartment TEB 61: a walker in the door, spin and back-up refused at start, each spent one
    # of the six retries without moving the robot
    opts = RecoveryOptions(
        steps=(RecoveryStep("back_up", {"backup_dist": 0.3}), RecoveryStep("wait", {"wait_duration": 1.0})),
        number_of_retries=2,
    )
    policy = RecoveryPolicy(opts)
    ctx, _ = make_ctx()
    _wall_behind(ctx)
    b = policy.on_failure(Trigger.NO_PROGRESS, ctx)
    assert b is not None and b.name == "wait" and policy.active is b  # the wait runs now
    kinds = [(e.kind, e.behavior, e.status) for e in policy.events]
    assert kinds == [("attempt", "back_up", ""), ("result", "back_up", "failed"), ("attempt", "wait", "")]
    assert policy.attempts == 1 and policy.retries_left == 1
    assert policy.run_to_end(ctx, step) is Status.SUCCEEDED
    # a step that ran counts: the refused back-up again, then the wait spends the last retry
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait"
    assert policy.exhausted


def test_when_every_step_is_refused_the_last_one_counts() -> None:
    opts = RecoveryOptions(steps=(RecoveryStep("back_up", {"backup_dist": 0.3}),), number_of_retries=2)
    policy = RecoveryPolicy(opts)
    ctx, _ = make_ctx()
    _wall_behind(ctx)
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx) is not None and policy.active is None
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx) is not None
    assert policy.exhausted and policy.on_failure(Trigger.NO_PROGRESS, ctx) is None


def _walker_ctx() -> tuple[BehaviorContext, list[bool]]:
    ctx, _ = make_ctx()
    on_path = [True]
    ctx.walker_on_path = lambda: on_path[0]
    return ctx, on_path


def test_a_walker_on_the_path_makes_the_robot_wait_without_spending_the_budget() -> None:
    policy = RecoveryPolicy(RecoveryOptions(walker_wait=10.0))
    ctx, on_path = _walker_ctx()
    b = policy.on_failure(Trigger.CONTROLLER_FAILURE, ctx, "PatienceExceeded")
    assert b is not None and b.name == "wait_for_walker"
    assert policy.attempts == 0 and policy.retries_left == 6
    for _ in range(30):  # 3 s: stopped while the walker stays
        step(ctx, policy.command)
        assert policy.tick(ctx) is Status.RUNNING and policy.command.is_zero()
    on_path[0] = False  # it stepped aside: once the path stays clear for clear_time (1 s)...
    for _ in range(9):
        step(ctx, policy.command)
        assert policy.tick(ctx) is Status.RUNNING
    on_path[0] = True  # (back for a scan: a walker turning drops out of tracking and back)
    step(ctx, policy.command)
    assert policy.tick(ctx) is Status.RUNNING
    on_path[0] = False
    statuses = []
    while not statuses or statuses[-1] is Status.RUNNING:
        step(ctx, policy.command)
        statuses.append(policy.tick(ctx))
    assert statuses[-1] is Status.SUCCEEDED and len(statuses) in (10, 11)  # ...the wait ends
    assert policy.walker_waited == pytest.approx(5.0, abs=0.11)
    # no walker at the next failure: the round robin from its first step, as before
    assert policy.on_failure(Trigger.CONTROLLER_FAILURE, ctx).name == "clear_local_costmap"
    assert policy.attempts == 1


def test_a_walker_that_stays_gets_the_recovery_list_after_the_wait() -> None:
    policy = RecoveryPolicy(RecoveryOptions(walker_wait=2.0))
    ctx, _ = _walker_ctx()
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait_for_walker"
    assert policy.run_to_end(ctx, step) is Status.FAILED
    assert 2.0 <= ctx.now <= 2.2 and "still on the path" in policy.events[-1].reason
    # the walker outlasted the wait: recover as without walkers, then waiting is allowed again
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "clear_local_costmap"
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait_for_walker"


def test_walker_waits_are_bounded_per_goal_and_not_for_a_lost_robot() -> None:
    policy = RecoveryPolicy(RecoveryOptions(walker_wait=2.0, walker_wait_total=3.0))
    ctx, _ = _walker_ctx()
    for _ in range(2):
        assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name == "wait_for_walker"
        policy.run_to_end(ctx, step)
        policy.on_failure(Trigger.NO_PROGRESS, ctx)  # the recovery after an outlasted wait
        policy.run_to_end(ctx, step)
    assert policy.walker_waited == pytest.approx(3.0, abs=0.11)  # the second wait got the rest
    assert policy.on_failure(Trigger.NO_PROGRESS, ctx).name != "wait_for_walker"
    policy.reset()  # a new goal: waits allowed again, but a lost robot does not wait
    assert policy.on_failure(Trigger.LOCALIZATION_DIVERGENCE, ctx).name == "spin_until_matched"


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
        ({"walker_wait": -1.0}, r"recovery\.walker_wait "),
        ({"walker_wait_total": float("nan")}, r"recovery\.walker_wait_total"),
        ({"walker_wait_triggers": ["no_progress", "rain"]}, r"walker_wait_triggers\[1\]"),
    ],
)
def test_bad_config_is_refused_naming_the_field(data: dict, field: str) -> None:
    with pytest.raises(RecoveryConfigError, match=field):
        RecoveryOptions.from_mapping(data)
