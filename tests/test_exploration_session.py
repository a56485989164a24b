"""Navigate while mapping and explore with one click (issue 18): the server's session and features
on a virtual clock with the simulated robot, no prior map; and the exploration API."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.commands.explore import build_explore_stack, load_world
from app.features.exploration import ENDED, ExplorationOptions, ExplorationRefused, ExplorationState
from app.features.navigation import NavigationRefused
from app.modes import Mode
from bench.explore import compare
from nav.exploration import FrontierReport
from nav.types import LETHAL_OBSTACLE, OccupancyGrid, Pose2D, Twist2D
from robot.base import SensorFrame

APARTMENT_START = Pose2D(3.0, 3.5, 0.0)


def _stack(world: str = "apartment", start: Pose2D = APARTMENT_START):
    return build_explore_stack(load_world(world), start, seed=3)


def _run_until(stack, pred, limit: float) -> bool:
    s = stack.session
    t0 = s.clock.now()
    while s.clock.now() - t0 < limit:
        s.run_for(s.period)
        if pred():
            return True
    return False


def _halt_navigation(stack, why: str) -> bool:
    """Halt the navigator's controller (unless already stuck); True once a frontier goal failed."""
    nav = stack.navigation
    if nav.active and nav.navigator.state.value != "stuck":
        nav.navigator.halt("NoValidControl", why)
    return stack.exploration.goals_failed >= 1


def _known_free_goal(stack, near: Pose2D, at_least: float) -> Pose2D:
    """A goal in the live costmap's free space at least ``at_least`` m from ``near`` (map frame)."""
    cm = stack.navigation.global_costmap
    rows, cols = np.nonzero(cm.costs == 0)
    pts = cm.geometry.cell_to_world(rows, cols)
    d = np.hypot(pts[:, 0] - near.x, pts[:, 1] - near.y)
    ok = np.flatnonzero(d >= at_least)
    assert ok.size, "no free cell that far in the map yet"
    i = ok[np.argmin(d[ok])]
    return Pose2D(float(pts[i, 0]), float(pts[i, 1]), 0.0)


@pytest.mark.slow
@pytest.mark.timeout(1200)  # ~3.5 min of CPU on the virtual clock; several times that on a busy machine
def test_exploring_the_apartment_maps_it_to_the_end():
    stack = _stack()
    s, ex = stack.session, stack.exploration
    start_truth = stack.driver.truth_pose
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.state in ENDED, 1500.0), ex.status()
        st = ex.status()
        assert st["state"] == "complete", st
        assert s.collisions == 0
        assert s.modes.mode == Mode.IDLE  # mapping stopped at the end: the map is final
        assert st["save_offered"] and st["goals_sent"] >= 2
        events = [e for e in s.events if e["type"] == "mode"]
        # one session: mapping from the start to the end, never navigating or recovering between
        assert [e["to"] for e in events] == ["mapping", "idle"]
        cmp = compare(stack.mapping.current_map(), stack.world, start_truth, APARTMENT_START)
        assert cmp.explored >= 0.9, cmp
        assert cmp.agreement >= 0.95, cmp
    finally:
        s.close()


def test_goals_while_mapping_drive_without_leaving_mapping():
    stack = _stack()
    s, nav = stack.session, stack.navigation
    try:
        stack.mapping.start()
        with pytest.raises(NavigationRefused, match="still being built"):
            nav.set_goals([Pose2D(3.5, 3.5, 0.0)])  # before SLAM's first map
        assert _run_until(stack, nav.mapping_live, 5.0)
        goal = _known_free_goal(stack, s.pose, 1.5)
        nav.set_goals([goal])
        assert _run_until(stack, lambda: nav.last_outcome is not None and not nav.active, 120.0)
        assert nav.last_outcome["kind"] == "reached", nav.last_outcome
        assert s.modes.mode == Mode.MAPPING and stack.mapping.running
        assert s.pose.distance_to(goal) < 0.3
        assert s.collisions == 0
        modes = [e["to"] for e in s.events if e["type"] == "mode"]
        assert modes == ["mapping"]
    finally:
        s.close()


def test_a_stuck_goal_while_mapping_recovers_without_leaving_mapping():
    stack = _stack()
    s, nav = stack.session, stack.navigation
    try:
        stack.mapping.start()
        assert _run_until(stack, nav.mapping_live, 5.0)
        goal = _known_free_goal(stack, s.pose, 1.5)
        nav.set_goals([goal])
        assert _run_until(stack, lambda: nav.active and nav.navigator.state.value == "following", 10.0)
        nav.navigator.halt("NoValidControl", "test: blocked once")  # as if the controller found no way
        assert _run_until(stack, lambda: nav.recovering, 1.0)  # the recovery tree runs, in MAPPING
        assert s.modes.mode == Mode.MAPPING
        assert _run_until(stack, lambda: nav.last_outcome is not None and not nav.active, 120.0)
        assert nav.last_outcome["kind"] == "reached", nav.last_outcome
        recoveries = [e for e in s.events if e["type"] == "recovery"]
        assert [e for e in recoveries if e.get("status") == "started"], recoveries
        assert [e for e in recoveries if e.get("status") == "finished"], recoveries
        assert [e["to"] for e in s.events if e["type"] == "mode"] == ["mapping"]  # one session
        assert stack.mapping.running and loc_updates(stack) == 0  # AMCL stayed off
        assert s.collisions == 0
    finally:
        s.close()


def loc_updates(stack) -> int:
    return stack.navigation.localization.updates


def test_the_live_maps_walls_are_lethal_in_the_costmaps():
    """SLAM's live map holds probabilities (a wall cell 70..97, rarely 100): read as map_server's
    trinary map would be (occupied_thresh 0.65), not with the loaded map's threshold 100, which
    left the global costmap without walls once its obstacle layer had no marks."""
    stack = _stack()
    s, nav = stack.session, stack.navigation
    try:
        stack.mapping.start()
        assert _run_until(stack, nav.mapping_live, 5.0)
        s.run_for(4.0)  # a few more maps
        nav.clear_costmaps()  # the layers' lidar marks gone: what is left is the live map's
        live = nav.live_grid.data
        walls = live >= 65
        assert np.count_nonzero(walls & (live < 100)) > 20  # such walls exist
        gc = nav.global_costmap
        assert gc.geometry == nav.live_grid.geometry
        assert np.all(gc.costs[walls] == LETHAL_OBSTACLE)
        assert np.all(gc.costs[(live >= 0) & (live < 65)] < LETHAL_OBSTACLE)  # free stays free
        lc = nav.local_costmap
        rows, cols = gc.geometry.world_to_cell(lc.geometry.cell_to_world(*np.nonzero(lc.costs >= 0)))
        local_walls = walls[rows, cols].reshape(-1)
        assert np.count_nonzero(local_walls) > 0
        assert np.all(lc.costs[lc.costs >= 0].reshape(-1)[local_walls] == LETHAL_OBSTACLE)
    finally:
        s.close()


def test_amcl_stays_off_while_mapping():
    stack = _stack()
    s = stack.session
    try:
        stack.mapping.start()
        assert _run_until(stack, stack.navigation.mapping_live, 5.0)
        s.run_for(2.0)
        loc = stack.navigation.localization
        assert loc.updates == 0  # SLAM localizes; the particle filter never ran
    finally:
        s.close()


def test_driving_by_hand_takes_over_from_a_goal_while_mapping():
    stack = _stack()
    s, nav = stack.session, stack.navigation
    try:
        stack.mapping.start()
        assert _run_until(stack, nav.mapping_live, 5.0)
        nav.set_goals([_known_free_goal(stack, s.pose, 1.5)])
        s.run_for(2.0)
        assert nav.active
        s.set_teleop(Twist2D(0.0, 0.0, 0.3), "operator")
        s.run_for(0.2)
        assert not nav.active
        assert nav.last_outcome["kind"] == "cancelled" and nav.last_outcome["reason"] == "teleop"
        assert s.modes.mode == Mode.MAPPING
        for _ in range(20):  # the operator keeps the key down: their command drives now (ramped)
            s.set_teleop(Twist2D(0.0, 0.0, 0.3), "operator")
            s.run_for(s.period)
        assert s.last_command.wz == pytest.approx(0.3)
    finally:
        s.close()


def test_estop_interrupts_exploration_and_the_robot_stops():
    stack = _stack()
    s, ex = stack.session, stack.exploration
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.goals_sent > 0, 10.0)
        s.run_for(2.0)
        s.estop("test")
        s.run_for(0.2)
        assert ex.state == ExplorationState.INTERRUPTED
        assert "estop" in ex.reason
        assert s.last_command.is_zero()
        assert not stack.navigation.active
    finally:
        s.close()


def test_time_budget_ends_exploration_and_offers_the_map():
    stack = _stack()
    s, ex = stack.session, stack.exploration
    try:
        ex.start(time_budget=8.0)
        assert _run_until(stack, lambda: ex.state in ENDED, 12.0)
        st = ex.status()
        assert st["state"] == "time_budget" and st["time_left_s"] == 0.0
        assert st["save_offered"]
        assert s.modes.mode == Mode.IDLE
        assert stack.mapping.current_map().data.size > 0
    finally:
        s.close()


def test_stop_keeps_mapping_and_a_second_start_is_refused():
    stack = _stack()
    s, ex = stack.session, stack.exploration
    try:
        ex.start()
        with pytest.raises(ExplorationRefused, match="already exploring"):
            ex.start()
        with pytest.raises(ValueError, match="positive"):
            stack.exploration.start(time_budget=-1.0)
        assert _run_until(stack, lambda: ex.goals_sent > 0, 10.0)
        assert ex.stop("tester")
        s.run_for(0.2)
        assert ex.state == ExplorationState.STOPPED and ex.reason == "stopped by tester"
        assert s.modes.mode == Mode.MAPPING and not stack.navigation.active
        assert not ex.stop()
    finally:
        s.close()


def test_a_failed_frontier_goal_is_blacklisted_and_another_chosen():
    stack = _stack()
    s, ex = stack.session, stack.exploration
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.goals_sent > 0, 10.0)
        s.run_for(1.0)

        # the controller finds no way on (as if a door closed) until a goal fails
        assert _run_until(stack, lambda: _halt_navigation(stack, "test: blocked"), 60.0)
        failed = ex.explorer.blacklist[-1]
        assert _run_until(stack, lambda: ex._goal is not None, 10.0)
        assert math.dist(ex._goal, failed) > ex.options.frontiers.blacklist_radius
        assert ex.state == ExplorationState.EXPLORING
    finally:
        s.close()


def test_a_goal_the_robot_comes_no_closer_to_is_given_up_after_the_progress_timeout():
    # office:1: 310 s on a goal 1.9 m away by the distance field while the robot drove 14 m off
    # and back, the navigator content all along; explore_lite gives such a goal up
    stack = _stack()
    s, ex = stack.session, stack.exploration
    ex.options = ExplorationOptions(progress_timeout=4.0)
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.goals_sent > 0, 10.0)
        goal = ex._goal

        # the navigator keeps the goal but the robot gets no closer; a goal fails before the
        # recoveries' 6 retries are spent
        assert _run_until(stack, lambda: _halt_navigation(stack, "test: held"), 20.0)
        ev = [e for e in s.events if e["type"] == "exploration" and e["status"] == "frontier blacklisted"]
        assert ev[0]["goal"] == list(goal) and ev[0]["reason"] == "no progress towards the frontier"
        s.run_for(0.5)  # the navigator ends the cancelled request on its next tick
        # the explorer cancelled it: the navigator had not given it up itself
        ends = [e for e in s.events if e["type"] == "navigation" and "outcome" in e]
        assert ends[0]["outcome"] == "cancelled" and ends[0]["actor"] == "explorer", ends[0]
        assert ex.explorer.banned_places == [goal] and ex.state == ExplorationState.EXPLORING
    finally:
        s.close()


def test_a_frontier_is_judged_unobservable_only_on_a_map_published_after_arrival():
    # office:1: a goal counted reached at 0.5 m was blacklisted as unobservable in the same tick,
    # on the map of the arrival tick, before SLAM had put in what the lidar saw from there
    stack = _stack()
    s, ex, nav = stack.session, stack.exploration, stack.navigation
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.goals_sent > 0, 10.0)
        arrival, later = nav.live_grid, object()
        ex._arrival_grid = arrival
        here = (s.pose.x, s.pose.y)
        cells = np.array([here, (here[0] + 2.0, here[1])])  # the frontier it was chosen from
        report = FrontierReport([], None, 0, 1.0, unobservable=[here], unobservable_cells=[cells])
        ex._decide(report, arrival, s.pose, s.clock.now())
        assert ex.explorer.blacklist == []
        ex._decide(report, later, s.pose, s.clock.now())
        assert ex.explorer.blacklist == [here]
        # the whole frontier is banned, not a circle around its goal
        assert ex.explorer.is_banned((here[0] + 2.0, here[1]))
    finally:
        s.close()


def test_a_frontier_goal_counts_as_reached_within_min_goal_distance():
    # the lidar sees the frontier from there; the last turns onto a goal near furniture are no
    # progress for Nav2's progress checker (0.5 m) and used to end in NoProgress
    stack = _stack()
    s, ex = stack.session, stack.exploration
    reach = ex.options.frontiers.min_goal_distance
    try:
        ex.start()
        assert _run_until(stack, lambda: ex.goals_reached >= 1, 120.0), ex.status()
        ev = [e for e in s.events if e["type"] == "exploration" and e["status"] == "frontier reached"]
        assert len(ev) == 1, [e for e in s.events if e["type"] in ("exploration", "navigation")]
        d = math.dist(ev[0]["goal"], (s.pose.x, s.pose.y))  # the pose of the tick that ended it
        assert 0.25 < d <= reach  # outside the goal checker's xy tolerance: before the navigator's end
        # the explorer moved on to another frontier without the goal checker's 0.25 m and heading
        assert _run_until(stack, lambda: ex._goal is not None and tuple(ev[0]["goal"]) != ex._goal, 5.0)
    finally:
        s.close()


def test_exploration_api(client):
    r = client.get("/api/exploration")
    assert r.status_code == 200 and r.json()["state"] == "idle"
    r = client.post("/api/exploration/start", json={"time_budget_s": -5})
    assert r.status_code == 422
    r = client.post("/api/exploration/stop")
    assert r.status_code == 409 and r.headers["content-type"].startswith("application/problem+json")
    r = client.post("/api/exploration/start", json={"time_budget_s": 600})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["state"] == "exploring" and body["time_budget_s"] == 600
    assert client.get("/api/robot").json()["mode"] == "mapping"
    r = client.post("/api/exploration/start")
    assert r.status_code == 409 and "already exploring" in r.json()["detail"]
    r = client.post("/api/exploration/stop")
    assert r.status_code == 200 and r.json()["state"] == "stopped"


def test_a_live_map_rebuild_keeps_what_the_lidar_marked_in_the_local_costmap():
    """Issue 18 (exploration contact): each map SLAM publishes rebuilds the costmaps; the local one
    used to start over with an empty obstacle layer, so an obstacle the lidar had marked but the
    live map did not hold yet (a chair leg, below SLAM's occupied threshold) was gone from what the
    controller drove on until a scan saw it again. Here the published map holds no obstacle at all
    and no scan comes after it: every cell the lidar had marked lethal must still be lethal."""
    stack = _stack()
    s, nav, mapping = stack.session, stack.navigation, stack.mapping
    try:
        mapping.start()
        assert _run_until(stack, nav.mapping_live, 30.0)
        s.run_for(2.0)
        # a screen put up 1 m in front of the robot just now: the lidar marks it at once, the live
        # map (published once a second) holds it at the earliest from its next publication (the
        # live map and the costmaps share the map frame's cell lattice, so the lidar's marks of
        # the room's walls all lie in the map's walls)
        p = stack.driver.truth_pose
        ahead = np.array([math.cos(p.theta), math.sin(p.theta)])
        side = np.array([-ahead[1], ahead[0]])
        centre = np.array([p.x, p.y]) + 1.0 * ahead
        screen = [
            centre + 0.8 * side,
            centre + 0.8 * side + 0.1 * ahead,
            centre - 0.8 * side + 0.1 * ahead,
            centre - 0.8 * side,
        ]
        stack.world.add_polygon(np.array(screen))
        s.run_for(0.3)
        before = nav.local_costmap
        rows, cols = np.nonzero(before.costs == LETHAL_OBSTACLE)
        assert rows.size > 20, "local costmap without the walls the lidar saw"
        marked = before.geometry.cell_to_world(rows, cols)
        live = nav.live_grid
        # the lidar's marks: lethal cells the live map does not hold as walls (those are the static
        # layer's, and the empty map below takes them away by design)
        r, c = live.geometry.world_to_cell(marked)
        inside = live.geometry.in_bounds(r, c)
        in_map_wall = np.zeros(len(marked), dtype=bool)
        in_map_wall[inside] = live.data[r[inside], c[inside]] >= nav.options.live_map_occupied_threshold
        marked = marked[~in_map_wall]
        assert len(marked) > 20, "no lidar marks beyond the live map's walls"
        empty = OccupancyGrid(live.geometry, np.where(live.data > 0, 0, live.data).astype(live.data.dtype))
        nav.on_live_map(empty, mapping.generation)
        now = s.clock.now()
        nav.tick(s, SensorFrame(stamp=now), now)  # the rebuild, with no scan this tick
        assert nav.live_grid is empty
        after = nav.local_costmap.cost_at(marked)
        assert np.all(after == LETHAL_OBSTACLE), f"{np.count_nonzero(after != LETHAL_OBSTACLE)} marks lost"
    finally:
        s.close()
