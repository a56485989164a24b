"""People in the simulator: they walk, the lidar and IR see them, the robot collides with them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.types import Pose2D, Twist2D
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.sim import SimDriver, SimOptions, World
from robot.sim.people import GIVE_WAY_S, Crowd, PeopleError

QUIET = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False)


def run(driver: SimDriver, clock: VirtualClock, cmd: Twist2D, seconds: float, period: float = 0.05) -> list:
    frames = []
    for _ in range(round(seconds / period)):
        driver.command(cmd)
        clock.advance(period)
        frames.append(driver.read())
    return frames


def test_ray_disc_ranges_match_geometry() -> None:
    crowd = Crowd()
    crowd.add(3.0, 0.0, radius=0.15)
    angles = np.array([0.0, math.atan2(0.1, 3.0), math.pi / 2, math.pi])
    r = crowd.ranges(np.zeros(2), angles, 6.0)
    assert r[0] == pytest.approx(2.85)
    # a chord off the centre line: t = b - sqrt(r^2 - d^2), b along the beam, d across it
    a = math.atan2(0.1, 3.0)
    b, d_perp = 3.0 * math.cos(a), 3.0 * math.sin(a)
    assert r[1] == pytest.approx(b - math.sqrt(0.15**2 - d_perp**2))
    assert np.isinf(r[2]) and np.isinf(r[3])
    assert np.isinf(crowd.ranges(np.zeros(2), angles, 2.0)[0])  # beyond max_range
    assert crowd.ranges(np.array([3.05, 0.0]), angles, 6.0)[0] == 0.0  # origin inside the disc


def test_people_walk_loops_at_their_speed_and_are_listed() -> None:
    world = World.box(8.0, 6.0)
    crowd = world.people
    pid = crowd.add_loop([[1.0, 1.0], [6.0, 1.0]], speed=1.0)
    for _ in range(100):
        crowd.step(0.01, Pose2D(4.0, 4.5, 0.0))
    info = {p.id: p for p in crowd.list()}[pid]
    assert info.x == pytest.approx(2.0) and info.y == pytest.approx(1.0)
    assert info.behaviour == "loop" and info.heading == pytest.approx(0.0)
    for _ in range(500):  # 5 s more: reached (6, 1) after 5 m, then 1 m back
        crowd.step(0.01, Pose2D(4.0, 4.5, 0.0))
    assert crowd.poses()[0, 0] == pytest.approx(5.0, abs=0.02)  # arrival ends a stride
    assert crowd.poses()[0, 2] == pytest.approx(math.pi)
    crowd.remove(pid)
    assert len(crowd) == 0
    with pytest.raises(PeopleError):
        crowd.remove(pid)
    with pytest.raises(PeopleError, match="speed"):
        crowd.add_loop([[1, 1], [2, 2]], speed=3.0)


def test_random_walk_stays_in_free_space() -> None:
    world = World.stock("office")
    rng = np.random.default_rng(4)
    for _ in range(3):
        world.people.add_random(5.0, 10.0, rng, speed=1.2)
    free_pts = []
    for _ in range(3000):  # 30 s
        world.people.step(0.01, Pose2D(25.0, 10.0, 0.0))
        free_pts.append(world.people.xy.copy())
    pts = np.concatenate(free_pts)
    moved = np.hypot(*(free_pts[-1] - free_pts[0]).T)
    assert np.all(moved > 0.5)
    rows, cols = world.geometry.world_to_cell(pts)
    assert np.all(world.clearance_map[rows, cols] >= 0.15 - 1e-9)  # the disc never overlaps a wall centre


def test_moving_person_is_seen_by_the_lidar_and_ir() -> None:
    clock = VirtualClock()
    world = World.box(8.0, 6.0)
    d = SimDriver(world, load_profile("skid4"), clock, start_pose=Pose2D(2.0, 3.0, 0.0), options=QUIET)
    d.people.add_loop([[4.0, 1.0], [4.0, 5.0]], speed=1.0)  # crosses 2 m ahead of the robot
    frames = run(d, clock, Twist2D(), 3.0)
    ahead = [f.scan.ranges[180] for f in frames if f.scan is not None]  # beam 180 looks along +x
    assert min(ahead) == pytest.approx(2.0 - 0.15, abs=0.02)  # the person crosses the beam
    assert max(ahead) == pytest.approx(8.0 - 0.1 - 2.0, abs=0.02)  # the far wall otherwise
    assert world.occupied.sum() > world.static_occupied.sum()  # occupied includes the disc
    # a person standing 0.2 m in front of the IR sensors triggers them
    d.people.clear()
    d.people.add(2.0 + 0.12 + 0.2 + 0.15, 3.0)
    frames = run(d, clock, Twist2D(), 0.2)
    ir = [f.ir for f in frames if f.ir is not None][-1]
    assert ir.triggered.all() and np.all(ir.ranges == pytest.approx(0.2, abs=0.02))


def test_robot_driving_into_a_person_collides_and_reports_it() -> None:
    clock = VirtualClock()
    world = World.box(8.0, 6.0)
    opts = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False, ir_stop=False)
    d = SimDriver(world, load_profile("skid4"), clock, start_pose=Pose2D(2.0, 3.0, 0.0), options=opts)
    pid = d.people.add(3.0, 3.0)  # standing person 1 m ahead
    frames = run(d, clock, Twist2D(0.26, 0.0, 0.0), 6.0)
    assert any(f.collision for f in frames)
    assert d.collision_with == f"person:{pid}"
    # stopped touching the person, never inside the disc
    front = d.truth_pose.x + 0.12
    assert 3.0 - 0.15 - 0.02 < front <= 3.0 - 0.15 + 0.01


def test_people_wait_rather_than_walk_into_the_robot() -> None:
    clock = VirtualClock()
    world = World.box(8.0, 6.0)
    d = SimDriver(world, load_profile("skid4"), clock, start_pose=Pose2D(4.0, 3.0, 0.0), options=QUIET)
    d.people.add_loop([[1.0, 3.0], [7.0, 3.0]], speed=1.0)  # walks straight through the robot's spot
    frames = run(d, clock, Twist2D(), 5.0)
    assert not any(f.collision for f in frames)
    gap = math.hypot(*(d.people.xy[0] - [4.0, 3.0])) - 0.15 - d.people.robot_radius
    assert -0.02 < gap < 0.05  # waiting at the robot


def test_step_in_person_appears_about_0_3_m_ahead() -> None:
    clock = VirtualClock()
    world = World.box(10.0, 6.0)
    opts = SimOptions(slip_noise_std=0.0, lidar_noise=False, gyro_noise=False, ir_stop=False)
    d = SimDriver(world, load_profile("skid4"), clock, start_pose=Pose2D(1.0, 3.0, 0.0), options=opts)
    d.people.add_step_in(4.0, 3.7, trigger_distance=1.5, dwell=2.0)
    gaps = []
    for _ in range(200):  # 10 s at 0.26 m/s
        run(d, clock, Twist2D(0.26, 0.0, 0.0), 0.05)
        p = d.people.xy[0]
        if d.people.behaviours[0].state == "standing":  # arrived in the robot's path
            assert abs(p[1] - 3.0) < 0.02
            gaps.append(p[0] - 0.15 - (d.truth_pose.x + 0.12))
    assert gaps, "the person never stepped in"
    assert 0.2 < gaps[0] < 0.4  # about 0.3 m ahead of the robot's front edge when it arrives


def test_populate_places_walkers_in_free_space_away_from_the_robot() -> None:
    world = World.stock("apartment")
    rng = np.random.default_rng(1)
    start = world.start_pose
    ids = world.people.populate(5, rng, avoid=(start.x, start.y), min_gap=1.5)
    assert len(ids) == 5 == len(world.people)
    xy = world.people.xy
    assert np.all(np.hypot(xy[:, 0] - start.x, xy[:, 1] - start.y) >= 1.5)
    rows, cols = world.geometry.world_to_cell(xy)
    assert np.all(world.clearance_map[rows, cols] >= 0.5)
    assert all(0.5 <= p.speed <= 1.2 and p.behaviour == "random" for p in world.people.list())
    with pytest.raises(PeopleError, match="clearance"):
        World.box(1.0, 1.0).people.populate(1, rng, clearance=2.0)


def test_a_walker_kept_waiting_by_the_robot_turns_back() -> None:
    """A walker on an aisle loop meets a robot standing in the aisle: it waits (never steps into the
    robot) and after ``GIVE_WAY_S`` turns back the way it came. It used to wait for good, and a robot
    waiting for the walker then waited for good too (a greenhouse family trial ended PatienceExceeded
    with the two face to face for 80 s)."""
    world = World.box(12.0, 3.0)
    crowd = world.people
    crowd.robot_radius = 0.16
    crowd.add_loop([[1.0, 1.5], [11.0, 1.5]], speed=1.0)
    robot = Pose2D(6.0, 1.5, math.pi)
    xs = []
    for _ in range(round((4.5 + GIVE_WAY_S + 2.0) / 0.04)):
        crowd.step(0.04, robot)
        xs.append(float(crowd.xy[0, 0]))
        assert math.hypot(crowd.xy[0, 0] - 6.0, crowd.xy[0, 1] - 1.5) >= 0.15 + 0.16 - 1e-9
    closest = max(xs)
    assert closest > 6.0 - 0.15 - 0.16 - 0.05  # it came up to the robot and waited there
    assert xs[-1] < closest - 1.5  # then walked back towards (1, 1.5)
