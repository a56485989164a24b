"""Issue 16's world families: the generators' guarantees (determinism per seed, start and goal in
free space with clearance, a route the footprint fits along, walkers' paths clear of the walls), the
family-specific shapes (legs, aisles, cylinders, corridors) and one trial per family end to end.
Every check is made on the *simulated* world the generator builds, independently of the generator's
own masks; the full sets (200 trials per controller and family) are benchmarks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt, label

from bench.scenarios import family_bench
from bench.scenarios.families import ContactLog, FamilySet, run_trial
from bench.scenarios.shards import budget_s
from bench.scenarios.suite import fresh_stack
from nav.types import Pose2D, Twist2D
from robot.profiles import load_profile
from robot.sim import World
from robot.sim.people import PERSON_RADIUS
from robot.sim.worldgen import FAMILIES, GeneratedWorld, WorldgenError, generate
from robot.sim.worldgen.forest import CYLINDER_RADIUS

SEEDS = range(6)


def _truth_clearance(gen: GeneratedWorld, start: Pose2D) -> tuple[World, np.ndarray]:
    """The simulated world and its clearance (m), computed here from the world's own obstacles."""
    world = gen.world(start)
    return world, distance_transform_edt(~world.static_occupied) * world.geometry.resolution


def _cell(world: World, p: Pose2D) -> tuple[int, int]:
    rows, cols = world.geometry.world_to_cell(np.array([[p.x, p.y]]))
    return int(rows[0]), int(cols[0])


@pytest.mark.parametrize("family", FAMILIES)
def test_same_seed_same_world_other_seed_other_world(family: str) -> None:
    a, b, c = generate(family, 11), generate(family, 11), generate(family, 12)
    assert np.array_equal(a.grid.data, b.grid.data) and a.params == b.params
    assert len(a.unmapped) == len(b.unmapped)
    assert all(np.array_equal(p, q) for p, q in zip(a.unmapped, b.unmapped, strict=True))
    assert a.sample_start_goal(np.random.default_rng(5)) == b.sample_start_goal(np.random.default_rng(5))
    assert a.grid.data.shape != c.grid.data.shape or not np.array_equal(a.grid.data, c.grid.data)


@pytest.mark.parametrize("family", FAMILIES)
def test_start_and_goal_free_with_clearance_and_joined_by_a_footprint_route(family: str) -> None:
    lo, hi = {"forest": (4.0, 20.0)}.get(family, (3.0, 10.0))
    for seed in SEEDS:
        gen = generate(family, seed)
        start, goal = gen.sample_start_goal(np.random.default_rng(seed), lo, hi)
        world, clear = _truth_clearance(gen, start)
        radius = load_profile(gen.profile).circumscribed_radius
        res = world.geometry.resolution
        for p in (start, goal):
            assert clear[_cell(world, p)] >= radius + gen.pose_clearance, (family, seed, p)
        assert lo <= start.distance_to(goal) <= hi
        # a route for the footprint at any heading: 8-connected cells whose centre clears it
        labels, _ = label(clear >= radius + res, structure=np.ones((3, 3), dtype=bool))
        assert labels[_cell(world, start)] != 0
        assert labels[_cell(world, start)] == labels[_cell(world, goal)], (family, seed)


@pytest.mark.parametrize("family", FAMILIES)
def test_walker_paths_keep_clear_of_walls_start_and_goal(family: str) -> None:
    for seed in SEEDS:
        gen = generate(family, seed)
        rng = np.random.default_rng(seed)
        start, goal = gen.sample_start_goal(rng, 3.0, 20.0)
        paths = gen.walker_paths(rng, 2, avoid=(start, goal))
        assert len(paths) == 2, (family, seed)
        world, clear = _truth_clearance(gen, start)
        for path in paths:
            assert min(np.hypot(path[:, 0] - start.x, path[:, 1] - start.y)) >= 1.5
            assert min(np.hypot(path[:, 0] - goal.x, path[:, 1] - goal.y)) >= 1.5
            legs = np.vstack(
                [
                    a + t * (b - a)
                    for a, b in zip(path, np.roll(path, -1, 0), strict=True)
                    for t in np.linspace(0.0, 1.0, 200)[:, None]
                ]
            )
            rows, cols = world.geometry.world_to_cell(legs)
            assert (clear[rows, cols] >= PERSON_RADIUS + 0.1).all(), (family, seed)


def test_apartments_have_four_legged_furniture_and_doors() -> None:
    tables = 0
    for seed in SEEDS:
        gen = generate("apartment", seed)
        assert gen.params["rooms"] == 4 and gen.params["doors"] >= 3
        assert 0.8 <= gen.params["door_width_m"] <= 0.95
        tables += gen.params["tables"]
        legs = np.array(gen.items["leg"])
        assert len(legs) == 4 * (gen.params["tables"] + gen.params["chairs"])
        # every 4 cm leg is on the map: a 5 cm cell within half a cell of its centre is occupied
        world = gen.world()
        near = legs[:, None, :] + np.array(
            [[dx, dy] for dx in (-0.025, 0, 0.025) for dy in (-0.025, 0, 0.025)]
        )
        assert (~world.is_free(near.reshape(-1, 2)).reshape(len(legs), 9)).any(axis=1).all()
    assert tables >= len(SEEDS)  # a table (and its chairs) in most rooms


def test_offices_have_a_corridor_rooms_and_desk_chairs() -> None:
    for seed in SEEDS:
        gen = generate("office", seed)
        assert 1.6 <= gen.params["corridor_width_m"] <= 2.4
        assert gen.params["rooms"] >= 6 and gen.params["doors"] >= gen.params["rooms"]
        assert len(gen.items["leg"]) == 4 * gen.params["rooms"]


def test_greenhouse_parameters_and_every_aisle_drivable_past_its_mounds() -> None:
    for seed in SEEDS:
        gen = generate("greenhouse", seed)
        p = gen.params
        assert 3 <= p["rows"] <= 7 and 0.3 <= p["row_width_m"] <= 0.8
        assert 0.8 <= p["aisle_width_m"] <= 1.6 and 1.0 <= p["headland_m"] <= 2.0
        world, clear = _truth_clearance(gen, Pose2D())
        radius = load_profile(gen.profile).circumscribed_radius
        ok = clear >= radius + world.geometry.resolution
        x0 = 0.1 + p["headland_m"]
        xs = np.arange(x0, x0 + p["row_length_m"], 0.05)
        edges = [0.1, *(hi for _, hi in gen.items["row_y"])]
        for lo in edges:  # along the whole aisle, some cell across it fits the robot
            ys = np.arange(lo, lo + p["aisle_width_m"], 0.05)
            pts = np.array([(x, y) for x in xs for y in ys])
            rows, cols = world.geometry.world_to_cell(pts)
            across = ok[rows, cols].reshape(len(xs), len(ys)).any(axis=1)
            assert across.all(), (seed, lo)


def test_forest_cylinders_are_15_cm_and_start_goal_in_their_clear_areas() -> None:
    assert pytest.approx(0.15) == 2 * CYLINDER_RADIUS
    for seed in SEEDS:
        gen = generate("forest", seed)
        trees = np.array(gen.items["cylinder"])
        assert len(trees) == gen.params["cylinders"] > 10
        world = gen.world()
        # each tree's centre is solid, a point 0.15 m from it (and from every other tree) is free
        assert not world.is_free(trees).any()
        ring = trees + np.array([0.15, 0.0])
        others = np.hypot(ring[:, None, 0] - trees[None, :, 0], ring[:, None, 1] - trees[None, :, 1]).min(1)
        lone = ring[(others >= 0.149) & (ring[:, 0] < gen.size[0] - 0.2)]
        assert world.is_free(lone).all()
        start, goal = gen.sample_start_goal(np.random.default_rng(seed), 4.0, 20.0)
        for p, z in ((start, gen.start_zone), (goal, gen.goal_zone)):
            assert z is not None and math.hypot(p.x - z.x, p.y - z.y) <= z.radius


def test_unknown_family_is_a_clear_error() -> None:
    with pytest.raises(WorldgenError, match="unknown world family 'moon'"):
        generate("moon", 1)


def _idle_stack(world: World, start: Pose2D):
    return fresh_stack(world.grid, start, seed=1, safety=False, world=world)


def test_contact_with_a_moving_robot_counts_once_per_contact() -> None:
    world = World.box(4.0, 4.0)
    start = Pose2D(3.6, 2.0, math.pi)  # backs into the east wall (the IR sensors look forward)
    stack = _idle_stack(world, start)
    s, log, seen = stack.session, ContactLog(), 0
    try:
        s.request_mode("teleop")
        for _ in range(80):
            s.set_teleop(Twist2D(-0.15, 0.0, 0.0), "test")
            s.clock.sleep_until(s.clock.now() + s.period)
            s.step()
            log.observe(stack, s.collisions > seen)
            seen = s.collisions
    finally:
        s.close()
    assert log.ticks > 1  # it kept pushing against the wall ...
    assert log.moving_obstacle == 1 and log.while_moving == 1  # ... one contact, the robot's
    assert log.walker_into_stopped == 0 and log.stopped_obstacle == 0


def test_walker_into_a_standing_robot_is_not_the_robots_contact() -> None:
    world = World.box(4.0, 4.0)
    start = Pose2D(2.0, 2.0, 0.0)
    stack = _idle_stack(world, start)
    s, log, seen = stack.session, ContactLog(), 0
    try:
        for k in range(40):
            if k == 20:  # someone steps onto the standing robot's side
                world.people.add(2.0, 2.2)
            s.clock.sleep_until(s.clock.now() + s.period)
            s.step()
            log.observe(stack, s.collisions > seen)
            seen = s.collisions
    finally:
        s.close()
    assert log.walker_into_stopped == 1
    assert log.while_moving == 0 and log.stopped_obstacle == 0


@pytest.mark.parametrize("family", FAMILIES)
def test_one_trial_per_family_end_to_end(family: str) -> None:
    t = run_trial(family, 0, seed=0, controller="dwa")
    assert t.walkers == 2 and t.result.controller == "dwa"
    assert t.result.time_s > 0 and t.result.path_length_m > 0.5  # it drove off towards the goal
    assert t.result.min_person_clearance_m is not None
    assert t.outcome == "reached", t.outcome
    assert t.contacts.while_moving == 0
    again = run_trial(family, 0, seed=0, controller="dwa", timeout=1.0)
    assert (again.world_seed, again.start, again.goal) == (t.world_seed, t.start, t.goal)
    assert again.outcome == "timeout"
    figs = {f.name: f for f in family_bench.family_figures(FamilySet(family, "dwa", [t, again]))}
    assert figs[f"{family} (dwa) reached (1/2)"].value == 50.0
    assert figs[f"{family} (dwa) timeouts (1/2)"].value == 50.0
    moving = figs[f"{family} (dwa) contacts while moving"]
    assert moving.value == 0 and moving.ok is True


@pytest.mark.parametrize("trial", [8, 16])
def test_teb_reaches_apartment_goals_it_used_to_give_up(trial: int) -> None:
    """Two apartment trials TEB gave up on (PatienceExceeded after six recoveries, no contact):
    trial 8 (world 679961800), where the band's seed jumped a table leg so every band collided,
    and trial 16 (world 361274677), where each walker in the band's way spent the controller's
    patience. TEB now reaches both goals without touching anything while moving."""
    t = run_trial("apartment", trial, seed=0, controller="teb")
    assert t.outcome == "reached", t.outcome
    assert t.contacts.while_moving == 0


def test_family_benchmarks_registered_per_controller(monkeypatch: pytest.MonkeyPatch) -> None:
    names = {b.name for b in family_bench.BENCHMARKS}
    assert names == {f"scenarios.family.{f}_{c}" for f in FAMILIES for c in ("dwa", "teb")}
    assert all(b.group == "slow" for b in family_bench.BENCHMARKS)
    monkeypatch.delenv(family_bench.BUDGET_VAR, raising=False)
    assert budget_s(family_bench.BUDGET_VAR) is None
    monkeypatch.setenv(family_bench.BUDGET_VAR, "-3")
    with pytest.raises(ValueError, match=family_bench.BUDGET_VAR):
        budget_s(family_bench.BUDGET_VAR)
