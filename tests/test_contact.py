"""Issue 16 "never trapped" and "zero contact while moving": a robot in contact can always leave (the
simulator takes any motion that does not deepen the contact, the safety layer lets it back out or
turn away, teleop and navigation get it out of the tightest spot of each stock world), and every
rotation checks the swept footprint, not only its end pose."""

from __future__ import annotations

import contextlib
import dataclasses
import math

import numpy as np
import pytest
from conftest import make_settings

from app.commands.sim_nav import build_sim_stack
from app.features import safety as safety_feature
from app.runtime import Runtime
from app.telemetry import snapshot_dict
from bench.contact import TIGHT_SPOTS, escape_trial
from nav.behaviors.base import BehaviorContext, Status
from nav.behaviors.spin import Spin, SpinOptions
from nav.control.errors import ControllerError, NoValidControl
from nav.control.footprint import swept_poses, swept_turn
from nav.control.teb import TebController, centre_collisions
from nav.control.teb_options import TebOptions
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, LaserScan, Path, Pose2D, Twist2D
from nav.walkers import PERSON_RADIUS, WalkerTracker
from robot.base import SensorFrame
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.safety import SafetyFilter
from robot.sim import SimDriver, SimOptions, World
from robot.sim.contact import cell_depths, disc_depths

QUIET = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False, ir_stop=False)
# A 0.51 x 0.43 m rectangular base (issue 16's cylinder-field robot)
BIG = np.array([[0.255, 0.215], [-0.255, 0.215], [-0.255, -0.215], [0.255, -0.215]])


def step(driver: SimDriver, clock: VirtualClock, cmd: Twist2D, seconds: float) -> int:
    """Command ``cmd`` for ``seconds`` (20 Hz); returns how many frames reported a contact."""
    hits = 0
    for _ in range(round(seconds / 0.05)):
        driver.command(cmd)
        clock.advance(0.05)
        hits += driver.read().collision
    return hits


def moved(a: Pose2D, b: Pose2D) -> float:
    return math.hypot(a.x - b.x, a.y - b.y) + abs(math.remainder(a.theta - b.theta, 2 * math.pi)) * 0.12


# ------------------------------------------------------------------------------------------ physics
def test_a_base_pushing_an_arc_into_a_wall_still_turns_away() -> None:
    """A front corner against a wall, forward + turn away: the whole motion presses in, its rotation
    alone frees the corner: the body turns (the old physics rejected the whole substep and the robot
    stood, pushing)."""
    clock = VirtualClock()
    start = Pose2D(3.4, 1.5, 0.5)
    d = SimDriver(World.box(4.0, 3.0), load_profile("skid4"), clock, seed=0, start_pose=start, options=QUIET)
    assert step(d, clock, Twist2D(0.2, 0.0, 0.0), 6.0) > 0  # front-right corner at the wall x = 3.9
    before = d.truth_pose
    hits = step(d, clock, Twist2D(0.2, 0.0, -0.8), 1.0)
    after = d.truth_pose
    assert hits > 0  # the push still reports a contact...
    assert before.theta - after.theta > 0.3  # ...but the base turned away from the wall
    assert d.body.penetration(d.world, after)[0] <= d.options.contact_skin + 1e-9  # never further in


def test_an_overlapping_base_can_leave_but_never_goes_deeper() -> None:
    """A post appears under the front of the footprint (an obstacle set down on the robot): pushing
    on does not move it deeper, backing out does."""
    clock = VirtualClock()
    world = World.box(4.0, 3.0)
    d = SimDriver(
        world, load_profile("skid4"), clock, seed=0, start_pose=Pose2D(2.0, 1.5, 0.0), options=QUIET
    )
    world.add_polygon(np.array([[2.08, 1.45], [2.16, 1.45], [2.16, 1.55], [2.08, 1.55]]))
    deep0, _ = d.body.penetration(world, d.truth_pose)
    assert deep0 > 0.0
    step(d, clock, Twist2D(0.2, 0.0, 0.0), 1.0)
    assert d.body.penetration(world, d.truth_pose)[0] <= deep0 + 1e-9
    step(d, clock, Twist2D(-0.15, 0.0, 0.0), 2.0)
    assert d.truth_pose.x < 2.0 - 0.1  # backed out
    assert not d.body.collides(world, d.truth_pose)


# A pocket among the apartment's dining-chair legs where random keys left the base for good: the
# leg's cell pokes its corner ~1 cm into the base's right edge between two edge samples.
POCKET = Pose2D(3.5446, 1.8158, 2.0872)
SKID4 = load_profile("skid4")


@pytest.mark.parametrize(
    ("cmd", "freed"),
    [
        (Twist2D(0.0, 0.0, 0.8), "turns"),
        (Twist2D(-0.15, 0.0, 0.0), "moves"),
        (Twist2D(0.15, 0.0, 0.0), "moves"),
    ],
)
def test_a_base_with_a_leg_corner_in_its_edge_turns_away_backs_out_and_slides_along(cmd, freed) -> None:
    """Turning away, backing out and sliding along the leg each move the base, and the leg never
    gets deeper. With the depth sampled at footprint points (a sample inside the cell's corner
    reads min(dx, dy), which grows as the body slides or turns) the turn stopped after 0.03 rad
    and backing or driving moved it less than a millimetre: trapped."""
    clock = VirtualClock()
    d = SimDriver(
        World.stock("apartment"), load_profile("skid4"), clock, seed=0, start_pose=POCKET, options=QUIET
    )
    deep0, _ = d.body.penetration(d.world, POCKET)
    assert deep0 > 0.0  # pressed in
    step(d, clock, cmd, 1.0)
    p = d.truth_pose
    if freed == "turns":
        assert p.theta - POCKET.theta > 0.5
    else:
        assert math.hypot(p.x - POCKET.x, p.y - POCKET.y) > 0.1
    assert d.body.penetration(d.world, p)[0] <= max(deep0, d.options.contact_skin) + 1e-9


def test_the_turn_into_the_leg_is_refused() -> None:
    clock = VirtualClock()
    d = SimDriver(
        World.stock("apartment"), load_profile("skid4"), clock, seed=0, start_pose=POCKET, options=QUIET
    )
    deep0, _ = d.body.penetration(d.world, POCKET)
    assert step(d, clock, Twist2D(0.0, 0.0, -0.8), 1.0) > 0
    assert d.body.penetration(d.world, d.truth_pose)[0] <= deep0 + 1e-9


def test_cell_depths_are_the_exact_overlap_of_polygon_and_cell() -> None:
    """Cell units: a unit square at the origin against a square sticking 0.1 into it from the
    left, a diamond whose corner pokes 0.2 into it (the corner between any two edge samples), and
    one clear of it."""
    cells = np.array([[0.0, 0.0]])
    left = np.array([[-2.0, 0.2], [0.1, 0.2], [0.1, 0.8], [-2.0, 0.8]])
    assert np.allclose(cell_depths(left, cells), [0.1])
    diamond = np.array([[0.5, 1.2], [-0.5, 2.2], [0.5, 3.2], [1.5, 2.2]]) - [0.0, 0.4]  # tip at y 0.8
    assert np.allclose(cell_depths(diamond, cells), [0.2])
    clear = left - [0.2, 0.0]
    assert np.allclose(cell_depths(clear, cells), [0.0])


def test_disc_depths_inside_and_outside_a_polygon() -> None:
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    centres = np.array(
        [[1.2, 0.0], [0.8, 0.0], [1.0 + 0.3 / math.sqrt(2) + 0.1, 1.0 + 0.3 / math.sqrt(2) + 0.1]]
    )
    assert np.allclose(disc_depths(square, centres, np.full(3, 0.3)), [0.1, 0.5, 0.0])


# --------------------------------------------------------------- random keys out of the tightest spots
@pytest.mark.parametrize("world_name", sorted(TIGHT_SPOTS))
def test_random_keys_get_out_of_the_tightest_spot(world_name: str) -> None:
    """``contact.escape`` at CI size: pressed into the spot for 15 s (safety layer overridden), then
    random keys with the safety layer on: out within 60 s, and the base never sat still for 5 s
    while keys were held (with the sampled contact depths, apartment seed 2 sat in a pocket among
    the chair's legs for 49 s until the limit, every key refused)."""
    for seed in (0, 1, 2):
        r = escape_trial(world_name, seed)
        assert r.out, f"seed {seed}: not out after {r.seconds:.0f} s, stuck at {r.stuck}"
        assert r.longest_stall < 5.0, f"seed {seed}: {r.longest_stall:.1f} s without moving"


# ------------------------------------------------------------------------------- swept rotations
def big_skid():
    return dataclasses.replace(load_profile("skid4"), footprint=tuple(map(tuple, BIG.tolist())))


def post_scan(stamp: float, radius: float, angle: float, beams: int = 3600) -> LaserScan:
    """A scan (laser at base_link) with four returns from a thin post at (radius, angle)."""
    r = np.full(beams, np.inf)
    inc = 2 * math.pi / beams
    k = round((angle + math.pi) / inc)
    r[k - 2 : k + 2] = radius
    return LaserScan(stamp, -math.pi, inc, r, 0.15, 6.0)


def test_safety_limits_a_turn_whose_corner_would_sweep_through_a_post() -> None:
    """0.51 x 0.43 m base, a thin post 0.31 m from base_link at 55 deg, outside the footprint now and
    after each 0.1 s of a 1.8 rad/s turn (0.18 rad steps), inside it between 11 and 20 deg of
    turn: the swept check limits the turn; checking every 0.1 s only, it passed unchanged."""
    f = SafetyFilter(big_skid())
    a = math.radians(55.0)
    for k in (0, 1, 2):  # the post is outside the footprint at 0, 0.18 and 0.36 rad of turn
        body = np.array([0.31 * math.cos(a - 0.18 * k), 0.31 * math.sin(a - 0.18 * k)])
        assert abs(body[0]) > 0.255 or abs(body[1]) > 0.215
    out, reason = f(Twist2D(0.0, 0.0, 1.8), SensorFrame(stamp=0.0, scan=post_scan(0.0, 0.31, a)))
    assert out.wz < 0.5 * 1.8 and reason is not None and reason.startswith("approach")
    away, _ = f(Twist2D(0.0, 0.0, -1.8), SensorFrame(stamp=0.05))
    # turning the near corner away: only the far corner, 0.7 s of turn later, limits it
    assert away.wz <= -1.0


def post_costmap(cell_xy: tuple[float, float]) -> Costmap:
    g = GridGeometry(0.05, 60, 60)
    costs = np.zeros((60, 60), dtype=np.uint8)
    rows, cols = g.world_to_cell(np.array([cell_xy]))
    costs[rows[0], cols[0]] = LETHAL_OBSTACLE
    return Costmap(g, costs)


def test_teb_refuses_a_rotation_to_the_goal_heading_that_sweeps_a_post() -> None:
    """Inside the goal's xy tolerance, TEB turns in place; a post inside the corner's sweep but
    outside the footprint at the start and goal headings: neither way round is free, so it
    refuses (it used to command the turn, checking nothing)."""
    teb = TebController(TebOptions(footprint=tuple(map(tuple, BIG.tolist()))))
    costmap = post_costmap((1.5 + 0.31 * math.cos(math.radians(55)), 1.5 + 0.31 * math.sin(math.radians(55))))
    start, goal = np.array([1.5, 1.5, 0.0]), np.array([1.5, 1.5, math.pi / 2])
    assert not centre_collisions(costmap, np.vstack((start, goal)), BIG).any()  # both ends free
    assert centre_collisions(costmap, swept_turn(start, math.pi / 2, 0.34, 0.025), BIG).any()
    teb.set_path(Path(np.vstack((start, goal))))
    with pytest.raises(NoValidControl, match="sweep"):
        teb.compute(Pose2D(*start), Twist2D(), costmap)
    # without the post the same turn is commanded
    teb.reset()
    teb.set_path(Path(np.vstack((start, goal))))
    cmd, _ = teb.compute(Pose2D(*start), Twist2D(), Costmap(costmap.geometry, np.zeros((60, 60), np.uint8)))
    assert cmd.wz > 0.0


def test_spin_checks_the_swept_footprint() -> None:
    """A spin whose corner would sweep through the post fails before it starts turning; the
    other way round (the corner moving away) it turns."""
    costmap = post_costmap((1.5 + 0.31 * math.cos(math.radians(55)), 1.5 + 0.31 * math.sin(math.radians(55))))
    ctx = BehaviorContext(now=0.0, pose=Pose2D(1.5, 1.5, 0.0), costmap=costmap, footprint=BIG)
    ccw = Spin(SpinOptions(spin_dist=0.5))
    assert ccw.start(ctx) == Status.FAILED and "collision" in ccw.reason
    cw = Spin(SpinOptions(spin_dist=-0.5))
    assert cw.start(ctx) == Status.RUNNING and cw.command.wz < 0.0


def test_swept_poses_bound_the_motion_between_samples() -> None:
    poses = np.array([[0.0, 0.0, 3.0], [0.1, 0.0, -3.0]])  # a short hop across the +-pi seam
    sweep = swept_poses(poses, reach=0.3, step=0.01)
    d = np.diff(sweep, axis=0)
    dth = np.abs((d[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    assert np.all(np.hypot(d[:, 0], d[:, 1]) + 0.3 * dth <= 0.01 + 1e-12)
    assert np.allclose(sweep[0], poses[0]) and np.allclose(sweep[-1, :2], poses[1, :2])
    assert math.isclose(math.remainder(sweep[-1, 2] - poses[1, 2], 2 * math.pi), 0.0, abs_tol=1e-12)


# --------------------------------------------------------------------- the tightest spot of each world
ESCAPES = {
    "back": Twist2D(-0.15, 0.0, 0.0),
    "turn left": Twist2D(0.0, 0.0, 0.8),
    "turn right": Twist2D(0.0, 0.0, -0.8),
    "forward": Twist2D(0.15, 0.0, 0.0),
}


def press_into(session, world_name: str) -> Pose2D:
    """Teleop into the spot with the safety layer and the base's IR stop off (an obstacle the
    sensors do not see, or an operator's override), until the base reports contact for 2 s."""
    start, push = TIGHT_SPOTS[world_name].start, TIGHT_SPOTS[world_name].push
    session.driver.options = dataclasses.replace(session.driver.options, ir_stop=False)
    session.driver.teleport(start)
    safety = session.safety

    def override(cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, None]:
        safety(cmd, frame)  # the filter still sees every frame, its verdict is ignored
        return cmd, None

    session.safety = override
    contact = 0
    for _ in range(round(20.0 / session.period)):
        session.set_teleop(push, "test")
        before = session.collisions
        session.run_for(session.period)
        contact = contact + 1 if session.collisions > before else 0
        if contact * session.period >= 2.0:
            break
    session.safety = safety
    assert contact * session.period >= 2.0, "never reached contact"
    return session.driver.truth_pose


@pytest.mark.parametrize("world_name", sorted(TIGHT_SPOTS))
def test_teleop_gets_out_of_the_tightest_spot_following_the_dashboard(tmp_path, world_name: str) -> None:
    """Pressed into the spot, the dashboard says "in contact" and which way is free; an operator who
    holds the first free motion for half a second at a time, safety layer on, gets the robot out."""
    rt = Runtime.build(make_settings(tmp_path, world=world_name), clock=VirtualClock())
    try:
        feature = safety_feature.setup(rt)
        s = rt.session
        s.request_mode("teleop")
        stuck = press_into(s, world_name)
        tele = snapshot_dict(s.bus.latest, "skid4")["contact"]
        assert tele["in_contact"] and tele["with"] == "obstacle" and tele["nearest_m"] is not None
        assert any(tele["free"].values()), tele  # some way out is shown
        t0 = s.clock.now()
        while moved(s.driver.truth_pose, stuck) < 0.15 and s.clock.now() - t0 < 30.0:
            free = feature.contact(s.clock.now())["free"] or {"back": True}
            key = next(k for k in ESCAPES if free.get(k))
            for _ in range(round(0.5 / s.period)):
                s.set_teleop(ESCAPES[key], "test")
                s.run_for(s.period)
        assert moved(s.driver.truth_pose, stuck) >= 0.15, f"still stuck after {s.clock.now() - t0:.1f} s"
        s.set_teleop(Twist2D(), "test")
        s.run_for(1.0)
        assert not snapshot_dict(s.bus.latest, "skid4")["contact"]["in_contact"]
    finally:
        rt.close()


NAV_OUT = {
    "apartment": Pose2D(3.0, 1.0, math.pi),
    "office": Pose2D(4.0, 10.0, 0.0),
    "greenhouse": Pose2D(10.0, 6.2, 0.0),
}


@pytest.mark.parametrize("world_name", sorted(TIGHT_SPOTS))
def test_navigation_gets_out_of_the_tightest_spot(world_name: str) -> None:
    """Pressed into the spot, a goal 1.5-2 m away (DWA, localization from the simulator's truth, the
    safety layer on, as the server wires it) is reached without the robot staying in contact."""
    world = World.stock(world_name)
    stack = build_sim_stack(
        world.grid, world, TIGHT_SPOTS[world_name].start, localization="truth", controller="dwa"
    )
    s = stack.session
    try:
        s.safety = SafetyFilter(stack.driver.profile)
        s.request_mode("teleop")
        stuck = press_into(s, world_name)
        s.set_teleop(Twist2D(), "test")
        s.request_mode("idle")
        stack.localization.set_initial_pose(stack.driver.truth_pose)
        stack.navigation.set_goals([NAV_OUT[world_name]])
        t0, outcome = s.clock.now(), None
        while s.clock.now() - t0 < 90.0 and outcome is None:
            s.run_for(s.period)
            if stack.navigation.last_outcome is not None and not stack.navigation.active:
                outcome = stack.navigation.last_outcome
        assert outcome is not None and outcome["kind"] == "reached", outcome
        assert moved(stack.driver.truth_pose, stuck) > 0.5
    finally:
        s.close()


# ------------------------------------------------------------------------- walkers' predicted motion
def person_scan(stamp: float, x: float, y: float = 0.0, beams: int = 720) -> LaserScan:
    """A scan (laser at base_link) of a 0.3 m disc (a walker) centred at (x, y), nothing else."""
    a = -math.pi + 2 * math.pi / beams * np.arange(beams)
    c, s = np.cos(a), np.sin(a)
    b = c * x + s * y
    disc = b * b - (x * x + y * y - 0.15**2)
    with np.errstate(invalid="ignore"):
        r = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    return LaserScan(stamp, -math.pi, 2 * math.pi / beams, np.where(r > 0, r, np.inf), 0.15, 6.0)


def test_safety_predicts_a_walker_coming_head_on() -> None:
    """A walker 1.0 m ahead closing at 1 m/s, the robot asked to creep forward at 0.1 m/s: on the
    static readings the collision is 7 s away and the command passes; with the walker's motion
    predicted it is 0.7 s away and the robot is slowed to (nearly) wait. A walker standing still
    at the same place does not slow it."""
    cmd = Twist2D(0.1, 0.0, 0.0)
    f = SafetyFilter(load_profile("skid4"))
    f(cmd, SensorFrame(stamp=0.0, scan=person_scan(0.0, 1.1)))
    out, reason = f(cmd, SensorFrame(stamp=0.1, scan=person_scan(0.1, 1.0)))
    assert out.vx < 0.7 * cmd.vx and reason is not None and reason.startswith("approach")
    g = SafetyFilter(load_profile("skid4"))
    g(cmd, SensorFrame(stamp=0.0, scan=person_scan(0.0, 1.0)))
    assert g(cmd, SensorFrame(stamp=0.1, scan=person_scan(0.1, 1.0))) == (cmd, None)
    # a walker crossing far ahead, moving away from the robot's path, is not a reason to slow down
    h = SafetyFilter(load_profile("skid4"))
    h(cmd, SensorFrame(stamp=0.0, scan=person_scan(0.0, 1.0, 0.5)))
    assert h(cmd, SensorFrame(stamp=0.1, scan=person_scan(0.1, 1.0, 0.6))) == (cmd, None)


@pytest.mark.parametrize("seed", [0, 2, 4])
def test_teb_meets_a_walker_in_a_greenhouse_aisle_without_contact(seed: int) -> None:
    """TEB drives down a 1.2 m greenhouse aisle (safety layer on, as the server wires it) while a
    walker comes the other way along it, off-centre by up to 0.3 m at 0.6-1.2 m/s: they meet
    (closer than 0.6 m centre to centre), and the robot never touches the walker while moving
    (it waits or backs off; a walker never steps into the robot in the simulator)."""
    world = World.stock("greenhouse")
    start = Pose2D(4.0, 6.2, 0.0)
    stack = build_sim_stack(world.grid, world, start, localization="truth", controller="teb", seed=seed)
    s = stack.session
    try:
        s.safety = SafetyFilter(stack.driver.profile)
        rng = np.random.default_rng(seed)
        y = 6.2 + rng.uniform(-0.3, 0.3)
        stack.driver.people.add_loop([[10.0, y], [3.0, y]], speed=float(rng.uniform(0.6, 1.2)))
        stack.localization.set_initial_pose(start)
        stack.navigation.set_goals([Pose2D(11.0, 6.2, 0.0)])
        closest, moving_contacts = math.inf, 0
        t0 = s.clock.now()
        while s.clock.now() - t0 < 30.0 and (
            stack.navigation.active or stack.navigation.last_outcome is None
        ):
            before = s.collisions
            s.run_for(s.period)
            truth = stack.driver.truth_pose
            closest = min(closest, float(np.hypot(*(stack.driver.people.xy[0] - [truth.x, truth.y]))))
            if s.collisions > before and not s.last_command.is_zero():
                moving_contacts += 1
        assert closest < 0.6  # the walker did come past the robot
        assert moving_contacts == 0
    finally:
        s.close()


# ---------------------------------------------------------------- TEB: walkers as dynamic obstacles
def corridor_teb() -> tuple[TebController, Costmap]:
    """TEB (0.51 x 0.43 m base) on a free 4 x 3 m costmap, path straight along y = 1.5."""
    teb = TebController(TebOptions(footprint=tuple(map(tuple, BIG.tolist()))))
    costmap = Costmap(GridGeometry(0.05, 80, 60), np.zeros((60, 80), np.uint8))
    teb.set_path(Path(np.array([[0.5 + 0.1 * k, 1.5, 0.0] for k in range(31)])))
    return teb, costmap


def test_teb_waits_for_a_walker_coming_head_on() -> None:
    """A walker 1.6 m ahead walking at the robot at 1 m/s: TEB's band waits (its first segment
    nearly at rest) and the command slows down, or TEB stops outright; the same walker standing
    still there (no predicted motion: room for 1 m of travel), or no walker, and it speeds up."""
    pose, v = Pose2D(0.5, 1.5, 0.0), Twist2D(0.2, 0.0, 0.0)
    teb, costmap = corridor_teb()
    cmd, _ = teb.compute(pose, v, costmap)
    assert cmd.vx >= v.vx
    teb, costmap = corridor_teb()
    teb.set_walkers(np.array([[2.1, 1.5]]), np.zeros((1, 2)))
    cmd, _ = teb.compute(pose, v, costmap)
    assert cmd.vx >= v.vx
    teb, costmap = corridor_teb()
    teb.set_walkers(np.array([[2.1, 1.5]]), np.array([[-1.0, 0.0]]))
    try:
        cmd, debug = teb.compute(pose, v, costmap)
    except NoValidControl as exc:
        assert "walker" in str(exc)
    else:
        assert cmd.vx < v.vx and debug.velocities[0, 0] < 0.1


def test_teb_waits_or_backs_off_for_a_walker_without_spending_its_patience() -> None:
    """A walker 0.75 m ahead coming at the robot (0.3 m/s), for 1 s of 10 Hz cycles: every cycle
    TEB stands or backs away, never drives at the walker, and says so with a command: it used to
    refuse every band that kept less than its walker clearance, backing away included, so after
    0.3 s (failure_tolerance) it raised PatienceExceeded and the navigator started a recovery
    (apartment 16, world 361274677: six recoveries, then the goal failed)."""
    pose, v = Pose2D(0.5, 1.5, 0.0), Twist2D(0.0, 0.0, 0.0)
    teb, costmap = corridor_teb()
    teb.set_walkers(np.array([[1.25, 1.5]]), np.array([[-0.3, 0.0]]))
    for _ in range(10):
        cmd, _ = teb.compute(pose, v, costmap)
        assert cmd.vx <= 0.0


def test_teb_drives_away_from_a_walker_standing_beside_it() -> None:
    """A walker standing 0.5 m behind the robot (inside the band's walker clearance, as the
    simulator's walkers stop next to a robot): driving on along the path only takes the robot
    farther from it, so TEB drives instead of waiting for a walker that waits for it."""
    pose, v = Pose2D(0.5, 1.5, 0.0), Twist2D(0.1, 0.0, 0.0)
    teb, costmap = corridor_teb()
    teb.set_walkers(np.array([[0.0, 1.5]]), np.zeros((1, 2)))
    assert teb._radius + PERSON_RADIUS > 0.5  # the walker is within the clearance the band keeps
    cmd, debug = teb.compute(pose, v, costmap)
    assert debug.waiting_for == ""
    assert cmd.vx > v.vx


def test_teb_band_keeps_clear_of_a_walkers_predicted_positions() -> None:
    """A walker crossing the corridor ahead (1 m/s along +y) passes the path where the band
    would be ~1 s later: the optimized band keeps the footprint's circle off the walker's body at
    every pose's own time (TEB's EdgeDynamicObstacle), where without the walker it runs straight
    through that place and time."""
    pose, v = Pose2D(0.5, 1.5, 0.0), Twist2D(0.3, 0.0, 0.0)
    start, vel = np.array([[1.1, 0.3]]), np.array([[0.0, 1.0]])

    def gaps(teb: TebController) -> np.ndarray:
        dbg = teb.last_debug
        t = np.concatenate(([0.0], np.cumsum(dbg.dts)))
        at = start + vel * t[:, None]
        return np.hypot(*(at - dbg.band[:, :2]).T) - PERSON_RADIUS

    teb, costmap = corridor_teb()
    teb.compute(pose, v, costmap)
    blind = gaps(teb).min()
    teb, costmap = corridor_teb()
    teb.set_walkers(start, vel)
    with contextlib.suppress(NoValidControl):
        teb.compute(pose, v, costmap)
    seen = gaps(teb).min()
    assert blind < teb._radius  # without prediction the band meets the walker
    assert seen > blind + 0.1


def test_teb_rejects_bad_walkers() -> None:
    teb, _ = corridor_teb()
    with pytest.raises(ControllerError):
        teb.set_walkers(np.array([[1.0, np.nan]]), np.zeros((1, 2)))
    with pytest.raises(ControllerError):
        teb.set_walkers(np.zeros((2, 2)), np.zeros((1, 2)))


def test_walker_tracker_follows_a_person_sized_cluster() -> None:
    """A 0.3 m disc moving 0.1 m between scans 0.1 s apart is a walker at 1 m/s; a wall-sized
    cluster moving the same is not; a still disc is not."""

    def disc_points(x: float, y: float) -> np.ndarray:
        scan = person_scan(0.0, x, y)
        return scan.points()

    tr = WalkerTracker()
    tr.update(disc_points(1.5, 0.0), 0.0)
    vel = tr.update(disc_points(1.4, 0.0), 0.1)
    assert vel.shape[0] > 3 and np.allclose(vel, [-1.0, 0.0], atol=0.05)
    assert tr.centres.shape == (1, 2) and np.allclose(tr.velocities, [[-1.0, 0.0]], atol=0.05)
    tr = WalkerTracker()
    tr.update(disc_points(1.5, 0.0), 0.0)
    assert not tr.update(disc_points(1.5, 0.0), 0.1).any() and tr.centres.shape == (0, 2)
    wall = np.column_stack((np.full(40, 1.5), np.linspace(-1.0, 1.0, 40)))
    tr = WalkerTracker()
    tr.update(wall, 0.0)
    assert not tr.update(wall - [0.1, 0.0], 0.1).any()


def points_scan(stamp: float, pts: np.ndarray, beams: int = 3600) -> LaserScan:
    """A scan (laser at base_link) with one return at each of the (N, 2) points."""
    r = np.full(beams, np.inf)
    inc = 2 * math.pi / beams
    k = np.round((np.arctan2(pts[:, 1], pts[:, 0]) + math.pi) / inc).astype(int) % beams
    r[k] = np.hypot(pts[:, 0], pts[:, 1])
    return LaserScan(stamp, -math.pi, inc, r, 0.15, 6.0)


def test_a_turn_that_presses_a_touching_leg_in_is_neither_offered_nor_passed() -> None:
    """A chair leg 2 mm inside the front edge of a 0.51 x 0.43 m base (pressed in within the
    simulator's contact skin): turning right takes it deeper (the simulator refuses that turn),
    turning left frees it. The dashboard's ``free`` list offers only the left turn and the filter
    stops the right one; readings inside the footprint used to be ignored by the turn check, so
    both turns were offered and the right one never moved the robot."""
    leg = np.column_stack((np.full(4, 0.253), np.linspace(0.15, 0.18, 4)))
    f = SafetyFilter(big_skid())
    f(Twist2D(), SensorFrame(stamp=0.0, scan=points_scan(0.0, leg)))
    free = f.free_motions(0.0)
    assert free["turn left"] and not free["turn right"] and not free["forward"] and free["back"]
    right, reason = f(Twist2D(0.0, 0.0, -0.8), SensorFrame(stamp=0.05))
    assert abs(right.wz) < 0.1 and reason is not None
    left, _ = f(Twist2D(0.0, 0.0, 0.8), SensorFrame(stamp=0.1))
    assert left.wz > 0.7


@pytest.mark.parametrize("beams", [360, 720])
@pytest.mark.parametrize("near", [0.153, 0.155])
def test_a_turn_whose_corner_would_clip_a_standing_walker_is_limited(near: float, beams: int) -> None:
    """Greenhouse TEB trials 170 and 6 (family sets, stops 30-31): a walker stood 0.30-0.31 m from the
    skid base's centre, its near side 1-3 mm inside the circle the corners sweep (0.156 m), and TEB
    turned in place at 1 rad/s. At any one pose of the turn the corner overlaps the walker by a
    sliver holding one or two of its lidar returns, never ``min_points`` (4), and between two checked
    poses (a corner moves up to ``SWEEP_STEP``, 2 cm) the returns a millimetre inside its arc are in
    neither pose's footprint: the turn passed and the corner clipped the walker. The readings the
    footprint sweeps over (the union over the turn, its arcs between poses included) count: the turn
    toward the walker is limited; the turn away is not."""
    a = math.radians(60.0)  # the front-left corner (39.8 deg) turns toward it when turning left
    c = near + 0.15  # the walker's near side ``near`` m from base_link
    scan = person_scan(0.0, c * math.cos(a), c * math.sin(a), beams=beams)
    f = SafetyFilter(load_profile("skid4"))
    out, reason = f(Twist2D(0.0, 0.0, 1.0), SensorFrame(stamp=0.0, scan=scan))
    assert out.wz < 0.5 and reason is not None and reason.startswith("approach"), (out, reason)
    g = SafetyFilter(load_profile("skid4"))
    away, _ = g(Twist2D(0.0, 0.0, -1.0), SensorFrame(stamp=0.0, scan=scan))
    assert away.wz < -0.5  # the corner turning away only meets it after most of a half turn


def test_a_corner_meeting_a_walker_return_by_return_is_limited_at_the_first() -> None:
    """Greenhouse TEB trial 6: a walker stood with its near side 0.148 m from the skid base's centre,
    beside a rear corner (0.156 m), and TEB turned the corner into it at 0.35 rad/s. The corner meets
    its returns one by one: counting ``min_points`` (4) of them predicted the contact 0.9 s away and
    passed 0.26 rad/s, and the corner touched it. A return of a solid object (one of >= min_points
    consecutive returns) counts alone: the turn is held to a crawl. A single stray return still
    limits nothing."""
    a, c = math.radians(-129.6), 0.148 + 0.15
    walker = person_scan(0.0, c * math.cos(a), c * math.sin(a), beams=360)
    f = SafetyFilter(load_profile("skid4"))
    out, reason = f(Twist2D(0.0, 0.0, 0.35), SensorFrame(stamp=0.0, scan=walker))
    assert out.wz < 0.1 and reason is not None and reason.startswith("approach"), (out, reason)
    stray = np.full(360, np.inf)
    stray[45] = 0.152  # one return at -135 deg, on the rear-right corner's arc
    g = SafetyFilter(load_profile("skid4"))
    scan = LaserScan(0.0, -math.pi, 2 * math.pi / 360, stray, 0.15, 6.0)
    assert g(Twist2D(0.0, 0.0, 0.35), SensorFrame(stamp=0.0, scan=scan)) == (Twist2D(0.0, 0.0, 0.35), None)
