"""The localization and navigation features in a simulated session on a virtual clock (no HTTP)."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

import app.features.navigation as navigation_feature
from app.commands.sim_nav import SimStack, build_sim_stack
from app.features.localization import LocalizationRequestError
from app.features.navigation import GoalRejected, NavigationRefused
from app.modes import Mode
from maps.stock import stock_world_path
from nav.control.dwa import _prune
from nav.planning.bucket_search import _SEARCH
from nav.types import Pose2D
from robot.sim import World

APARTMENT_START = Pose2D(3.0, 3.5, 0.0)


def apartment(seed: int = 0, localization: str = "amcl", planner: str = "astar") -> SimStack:
    world = World.from_yaml(stock_world_path("apartment"))
    return build_sim_stack(
        world.grid, world, APARTMENT_START, seed=seed, localization=localization, planner=planner
    )


def run_until_done(stack: SimStack, limit: float = 90.0) -> dict:
    s = stack.session
    t0 = s.clock.now()
    while s.clock.now() - t0 < limit:
        s.run_for(s.period)
        if stack.navigation.last_outcome is not None and not stack.navigation.active:
            return stack.navigation.last_outcome
    raise AssertionError(f"no outcome in {limit} s: {stack.navigation.state()}")


def nav_events(stack: SimStack) -> list[dict]:
    return [e for e in stack.session.events if e["type"] == "navigation" and "outcome" in e]


@pytest.fixture
def stack():
    st = apartment()
    yield st
    st.session.close()


def test_navigation_refused_without_localization(stack: SimStack) -> None:
    with pytest.raises(NavigationRefused, match="not localized"):
        stack.navigation.set_goals([Pose2D(3.0, 1.2, 0.0)])
    assert stack.session.modes.mode == Mode.IDLE


def test_goal_reached_with_amcl_and_outcome_event(stack: SimStack) -> None:
    # The operator's pose is 0.25 m and 0.1 rad off: AMCL must pull the estimate onto the truth.
    stack.localization.set_initial_pose(Pose2D(3.2, 3.35, 0.1))
    goal = Pose2D(3.0, 1.2, -math.pi / 2)
    stack.navigation.set_goals([goal])
    assert stack.session.modes.mode == Mode.NAVIGATING
    out = run_until_done(stack)
    assert out["kind"] == "reached", out
    truth = stack.driver.truth_pose
    assert truth.distance_to(goal) < 0.25 + 0.08  # xy_goal_tolerance plus localization error
    assert stack.session.pose.distance_to(truth) < 0.08
    assert abs(math.remainder(truth.theta - goal.theta, 2 * math.pi)) < 0.25 + 0.1
    assert stack.session.modes.mode == Mode.IDLE
    assert nav_events(stack)[-1]["outcome"] == "reached"
    assert stack.session.collisions == 0
    loc = stack.localization.state()
    assert loc["localized"] and loc["particles"] >= 500 and loc["quality"] > 0.5


@pytest.mark.parametrize(
    ("goal", "reason"),
    [
        (Pose2D(-2.0, 3.0, 0.0), "off the map"),
        (Pose2D(0.02, 0.02, 0.0), "inside an obstacle"),
    ],
)
def test_bad_goals_refused_with_nearest_free_pose(stack: SimStack, goal: Pose2D, reason: str) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    with pytest.raises(GoalRejected) as info:
        stack.navigation.set_goals([goal])
    assert info.value.reason == reason
    free = info.value.nearest_free
    assert free is not None and free.distance_to(goal) < 3.0
    stack.navigation.check_goal(free)  # the suggestion itself is accepted
    assert stack.session.modes.mode == Mode.IDLE


def test_goal_inside_inscribed_radius_refused(stack: SimStack) -> None:
    cm = stack.navigation.global_costmap
    assert cm is not None
    rows, cols = np.nonzero(cm.costs == 253)
    xy = cm.geometry.cell_to_world(rows[:1], cols[:1])[0]
    stack.localization.set_initial_pose(APARTMENT_START)
    with pytest.raises(GoalRejected, match="inscribed radius") as info:
        stack.navigation.set_goals([Pose2D(float(xy[0]), float(xy[1]), 0.0)])
    assert info.value.nearest_free is not None


def test_second_waypoint_refusal_names_its_index(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    with pytest.raises(GoalRejected) as info:
        stack.navigation.set_goals([Pose2D(3.0, 1.2, 0.0), Pose2D(50.0, 1.0, 0.0)])
    assert info.value.index == 1 and "goal 2" in str(info.value)


def test_initial_pose_in_wall_or_off_map_refused(stack: SimStack) -> None:
    with pytest.raises(LocalizationRequestError, match="inside a wall"):
        stack.localization.set_initial_pose(Pose2D(0.02, 0.02, 0.0))
    with pytest.raises(LocalizationRequestError, match="off the map"):
        stack.localization.set_initial_pose(Pose2D(100.0, 0.0, 0.0))
    assert not stack.localization.localized


def test_cancel_stops_and_reports(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    stack.navigation.set_goals([Pose2D(7.0, 4.0, 0.0)])
    stack.session.run_for(3.0)
    assert stack.navigation.active and stack.session.velocity.vx != 0.0
    assert stack.navigation.cancel()
    out = run_until_done(stack, 2.0)
    assert out["kind"] == "cancelled"
    stack.session.run_for(1.0)
    assert abs(stack.driver.truth_velocity.vx) < 1e-3
    assert stack.session.modes.mode == Mode.IDLE
    assert nav_events(stack)[-1]["outcome"] == "cancelled"


def test_operator_taking_over_cancels(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    stack.navigation.set_goals([Pose2D(7.0, 4.0, 0.0)])
    stack.session.run_for(1.0)
    stack.session.request_mode("teleop")
    stack.session.run_for(0.2)
    assert not stack.navigation.active
    assert stack.navigation.last_outcome["kind"] == "cancelled"


def test_estop_refuses_navigation(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    stack.session.estop("test")
    with pytest.raises(NavigationRefused, match="estop"):
        stack.navigation.set_goals([Pose2D(3.0, 1.2, 0.0)])


def test_waypoints_are_visited_in_order() -> None:
    st = apartment(localization="truth")
    try:
        st.localization.set_initial_pose(APARTMENT_START)
        goals = [Pose2D(3.0, 1.2, 0.0), Pose2D(6.5, 2.5, math.pi / 2)]
        st.navigation.set_goals(goals)
        seen = set()
        for _ in range(60 * 20):
            st.session.run_for(st.session.period)
            snap = st.session.bus.latest
            nav = snap.extras["navigation"]
            if st.navigation.active:
                seen.add(nav["goal_index"])
                assert snap.extras["waypoints"].shape == (len(goals) - nav["goal_index"], 3)
                assert snap.goal == goals[nav["goal_index"]]
            if not st.navigation.active and st.navigation.last_outcome:
                break
        out = st.navigation.last_outcome
        assert out is not None and out["kind"] == "reached" and out["goals_reached"] == 2
        assert seen == {0, 1}
        assert st.driver.truth_pose.distance_to(goals[1]) < 0.3
    finally:
        st.session.close()


def test_snapshot_carries_path_local_plan_costmap_and_particles(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    stack.navigation.set_goals([Pose2D(7.0, 4.0, 0.0)])
    stack.session.run_for(1.0)
    snap = stack.session.bus.latest
    assert snap.path is not None and len(snap.path) > 10
    assert snap.local_plan is not None and snap.local_plan.ndim == 3
    assert 0 <= snap.extras["local_plan_best"] < snap.local_plan.shape[0]
    assert snap.extras["costmap"].costs.shape == (160, 200)
    assert snap.particles is not None and snap.particles.shape[1] == 3
    nav = snap.extras["navigation"]
    assert nav["state"] == "following" and nav["distance_remaining"] > 1.0 and nav["eta_s"] > 0
    assert {"quality", "covariance", "particles", "localized"} <= set(snap.extras["localization"])


def test_unreachable_goal_fails_with_typed_reason() -> None:
    world = World.box(6.0, 4.0)
    world.grid.data[:, 58:62] = 100  # a wall from floor to ceiling splits the room in two
    world = World(world.grid, name="split", start_pose=Pose2D(1.5, 2.0, 0.0))
    st = build_sim_stack(world.grid, world, world.start_pose, localization="truth")
    try:
        st.localization.set_initial_pose(world.start_pose)
        st.navigation.set_goals([Pose2D(4.5, 2.0, 0.0)])
        out = run_until_done(st, 5.0)
        assert out["kind"] == "failed" and out["reason"] == "NoValidPathFound"
        assert st.session.modes.mode == Mode.IDLE
        assert nav_events(st)[-1]["reason"] == "NoValidPathFound"
    finally:
        st.session.close()


def _doorway_world() -> World:
    """A 6 x 4 m room split by a wall at x = 3 with one 0.8 m doorway at y = 2."""
    world = World.box(6.0, 4.0)
    world.grid.data[:, 58:62] = 100
    world.grid.data[32:48, 58:62] = 0  # rows 32..47: y 1.6 .. 2.4 m
    return World(world.grid, name="doorway", start_pose=Pose2D(1.5, 2.0, 0.0))


@pytest.mark.parametrize("map_alone_check", [True, False])
def test_a_person_in_the_only_doorway_delays_the_goal_instead_of_failing_it(map_alone_check: bool) -> None:
    """The first plan finds no path while a person stands in the doorway (sensed, not on the map):
    the navigator recovers and waits, as Nav2's planner-failure recovery, and reaches the goal once
    the person walks on. Without the map-alone check the goal failed at once (NoValidPathFound)."""
    world = _doorway_world()
    world.people.add_loop([[3.0, 2.0], [5.4, 3.4]], speed=0.5)  # from the doorway away, and back
    st = build_sim_stack(world.grid, world, world.start_pose, localization="truth")
    try:
        if not map_alone_check:
            st.navigation.navigator.path_on_map_alone = None
        st.localization.set_initial_pose(world.start_pose)
        st.session.run_for(0.5)  # the lidar sees the person in the doorway
        st.navigation.set_goals([Pose2D(4.5, 1.0, 0.0)])
        out = run_until_done(st, 120.0)
        if map_alone_check:
            assert out["kind"] == "reached", out
            assert st.navigation.recoveries >= 1
        else:
            assert out["kind"] == "failed" and out["reason"] == "NoValidPathFound"
    finally:
        st.session.close()


def test_set_map_resets_localization_and_costmaps(stack: SimStack) -> None:
    stack.localization.set_initial_pose(APARTMENT_START)
    stack.session.run_for(0.5)
    office = World.from_yaml(stock_world_path("office")).grid
    stack.localization.set_map(office, map_id=7)
    assert not stack.localization.localized
    stack.session.run_for(0.2)
    cm = stack.navigation.global_costmap
    assert cm is not None and cm.geometry == office.geometry
    assert stack.localization.state()["map_id"] == 7
    assert stack.session.grid is office


def test_dijkstra_planner_selectable() -> None:
    st = apartment(localization="truth", planner="dijkstra")
    try:
        st.localization.set_initial_pose(APARTMENT_START)
        st.navigation.set_goals([Pose2D(3.0, 1.2, 0.0)])
        assert run_until_done(st)["kind"] == "reached"
        assert st.navigation.state()["planner"] == "dijkstra"
    finally:
        st.session.close()


@pytest.mark.parametrize(("world_name", "seed"), [("office", 1), ("apartment", 2)])
def test_global_localization_rotates_until_converged(world_name: str, seed: int) -> None:
    world = World.from_yaml(stock_world_path(world_name))
    st = build_sim_stack(world.grid, world, world.start_pose, seed=seed)
    try:
        st.localization.start_global()
        assert st.session.modes.mode == Mode.LOCALIZING
        st.session.run_for(0.5)
        assert st.driver.truth_velocity.wz > 0.1  # rotating in place, as source A does
        t = 0.5
        while st.localization.global_running and t < 20.0:
            st.session.run_for(0.25)
            t += 0.25
        assert st.localization.localized, st.localization.state()
        assert st.session.modes.mode == Mode.IDLE
        st.session.run_for(0.5)
        truth = st.driver.truth_pose
        assert st.session.pose.distance_to(truth) < 0.15
        assert abs(math.remainder(st.session.pose.theta - truth.theta, 2 * math.pi)) < 0.1
        ev = [e for e in st.session.events if e["type"] == "localization"]
        assert ev[-1]["status"] == "localized"
    finally:
        st.session.close()


class SpinRecovery:
    """A minimal recovery policy for the hook: rotate in place for ``seconds``, at most ``limit`` times
    (the real behaviours live in nav/behaviors)."""

    def __init__(self, seconds: float = 1.0, limit: int = 2) -> None:
        self.seconds, self.limit, self.started, self._until = seconds, limit, 0, 0.0

    def start(self, feature, reason: str, now: float) -> bool:
        if self.started >= self.limit:
            return False
        self.started += 1
        self._until = now + self.seconds
        feature.clear_costmaps()
        return True

    def tick(self, feature, now: float):
        from nav.types import Twist2D

        return Twist2D(0.0, 0.0, 0.5), now >= self._until


def test_recovery_hook_runs_policy_in_recovering_mode() -> None:
    room = World.box(10.0, 4.0)
    world = World(
        room.grid.__class__(room.grid.geometry, room.grid.data.copy()), start_pose=Pose2D(2.0, 2.0, 0.0)
    )
    world.add_polygon([(5.0, 0.0), (5.2, 0.0), (5.2, 4.0), (5.0, 4.0)])  # unmapped wall across the room
    st = build_sim_stack(room.grid, world, world.start_pose, localization="truth")
    policy = SpinRecovery()
    st.navigation.recovery = policy
    try:
        st.localization.set_initial_pose(world.start_pose)
        st.navigation.set_goals([Pose2D(8.0, 2.0, 0.0)])
        out = run_until_done(st, 120.0)
        modes = [e["to"] for e in st.session.events if e["type"] == "mode"]
        assert "recovering" in modes
        assert st.navigation.recoveries == policy.started == 2
        assert out["kind"] == "failed"
        assert st.session.collisions == 0
        assert st.session.modes.mode == Mode.IDLE
    finally:
        st.session.close()


def test_nav2_recovery_behaviours_run_then_goal_aborts() -> None:
    from app.features.navigation import BehaviorRecovery
    from nav.recovery import RecoveryOptions

    room = World.box(10.0, 4.0)
    grid = room.grid.__class__(room.grid.geometry, room.grid.data.copy())
    world = World(grid, start_pose=Pose2D(2.0, 2.0, 0.0))
    world.add_polygon([(5.0, 0.0), (5.2, 0.0), (5.2, 4.0), (5.0, 4.0)])  # unmapped wall across the room
    st = build_sim_stack(room.grid, world, world.start_pose, localization="truth")
    st.navigation.recovery = BehaviorRecovery(RecoveryOptions(number_of_retries=2))
    try:
        st.localization.set_initial_pose(world.start_pose)
        st.navigation.set_goals([Pose2D(8.0, 2.0, 0.0)])
        out = run_until_done(st, 150.0)
        attempts = [e for e in st.session.events if e["type"] == "recovery" and e.get("kind") == "attempt"]
        assert [a["behavior"] for a in attempts] == ["clear_local_costmap", "clear_global_costmap"]
        assert st.navigation.recoveries == 2
        assert out["kind"] == "failed" and st.session.collisions == 0
    finally:
        st.session.close()


@pytest.mark.parametrize("controller", ["dwa", "teb"])
def test_skid_robot_turns_round_instead_of_backing_along_a_route_behind_it(controller: str) -> None:
    """Issue 17: on a 5 m route the robot drove backwards at -0.15 m/s for long stretches. The
    skid4 base can reverse (its profile's min_vel_x), but its lidar and IR look forwards: with the
    PreferForward critic (DWA) or TEB's forward-drive weight it turns round and drives forwards
    (before: DWA reversed 33.8 s of 33.8 s, TEB 1.5 s of 24.2 s)."""
    world = World.from_yaml(stock_world_path("apartment"))
    start, goal = Pose2D(3.0, 1.5, -math.pi / 2), Pose2D(1.0, 5.6, math.pi)  # the route starts behind it
    stack = build_sim_stack(world.grid, world, start, seed=3, controller=controller)
    try:
        stack.localization.set_initial_pose(start)
        stack.navigation.set_goals([goal])
        s = stack.session
        reversing = driving = 0.0
        t0 = s.clock.now()
        while stack.navigation.last_outcome is None and s.clock.now() - t0 < 120.0:
            s.run_for(s.period)
            if abs(s.velocity.vx) > 0.02:
                driving += s.period
                reversing += s.period if s.velocity.vx < -0.02 else 0.0
        out = stack.navigation.last_outcome
        assert out is not None and out["kind"] == "reached", out
        assert driving > 10.0  # it did drive the route (about 5 m at up to 0.26 m/s)
        assert reversing <= 0.5, f"{reversing:.2f} s of {driving:.2f} s driving was backwards"
        assert s.collisions == 0
    finally:
        stack.session.close()


def test_warm_up_runs_the_navigation_kernels_on_a_worker_before_any_goal(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first goal showed "waiting for a path" for 5.8 s: on a fresh checkout the first plan
    compiled the A* kernels, and the first DWA cycle then compiled its kernels on the loop thread.
    With ``warm_up`` (on by default with a real clock) the feature does that on a worker at
    start-up, with its own planner and controllers."""
    threads: list[str] = []
    real = navigation_feature.warm_up_navigation

    def spy(*args, **kwargs):
        threads.append(threading.current_thread().name)
        return real(*args, **kwargs)

    monkeypatch.setattr(navigation_feature, "warm_up_navigation", spy)
    st = apartment(localization="truth")
    try:
        assert st.navigation.warmed_up is None  # a simulated run on a virtual clock: not unless asked
        navigation = navigation_feature.Navigation(
            st.session, st.localization, navigation_feature.NavigationOptions(warm_up=True)
        )
        assert navigation.warmed_up is not None
        timings = navigation.warmed_up.result(timeout=600)
    finally:
        st.session.close()
    assert threads and threads[0].startswith("worker")  # off the loop thread
    assert set(timings) == {"costmaps", "plan", "dwa", "teb"}
    # the A* search (a costmap: the bucket kernel) and DWA's pruning are compiled
    assert _SEARCH[False].signatures and _prune.signatures
    assert not [e for e in st.session.events if e["type"] == "navigation"]  # no goal was involved
