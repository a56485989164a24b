"""Issue 23 item 4: after an e-stop or a fault reset nothing moves until a fresh teleop command: a key
held (or a stick deflected) through the reset is ignored until a zero command (the key released, the
stick back through zero). Virtual clock: what was commanded is checked, tick by tick."""

from __future__ import annotations

from app.modes import Mode
from app.session import Session
from nav.types import Twist2D
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.sim import SimDriver, World

TURN = Twist2D(0.0, 0.0, 0.6)


def make_session() -> Session:
    clock = VirtualClock()
    world = World.stock("apartment")
    driver = SimDriver(world, load_profile("skid4"), clock, seed=3, start_pose=world.start_pose)
    return Session(driver, clock=clock, grid=world.grid, start_pose=world.start_pose)


def hold(s: Session, cmd: Twist2D, seconds: float) -> list[bool]:
    """The operator's client resends ``cmd`` every tick (a held key); whether each was taken."""
    taken = []
    for _ in range(round(seconds / s.period)):
        taken.append(s.set_teleop(cmd, "dashboard"))
        s.run_for(s.period)
    return taken


def test_a_command_held_through_an_estop_reset_is_ignored_until_released() -> None:
    s = make_session()
    s.request_mode("teleop")
    assert all(hold(s, TURN, 0.5))
    s.estop("another client")
    hold(s, TURN, 0.3)
    assert s.reset() == Mode.IDLE
    theta = s.driver.truth_pose.theta
    assert not any(hold(s, TURN, 1.0))  # the key is still down: nothing moves
    assert s.last_command.is_zero() and s.driver.truth_velocity.is_zero()
    assert s.driver.truth_pose.theta == theta
    assert s.set_teleop(Twist2D(), "dashboard")  # released ...
    s.request_mode("teleop")
    assert all(hold(s, TURN, 1.0))  # ... and pressed again: it turns
    assert s.last_command.wz > 0.5 and s.driver.truth_pose.theta - theta > 0.3


def test_a_fault_reset_needs_a_fresh_command_too() -> None:
    s = make_session()
    s.request_mode("teleop")
    hold(s, TURN, 0.3)
    s.driver.lidar_enabled = False  # the lidar goes silent: FAULT
    hold(s, TURN, 2.0)
    assert s.modes.mode == Mode.FAULT
    s.driver.lidar_enabled = True
    s.run_for(0.5)
    assert s.reset() == Mode.IDLE
    s.request_mode("teleop")
    assert not any(hold(s, TURN, 0.5)) and s.last_command.is_zero()
    assert s.set_teleop(Twist2D(), "dashboard") and all(hold(s, TURN, 0.5))
    assert s.last_command.wz > 0.3


def test_a_client_that_let_go_before_the_estop_drives_on_its_next_press() -> None:
    """Only a motion held through the e-stop or reset is disarmed: a key released before it (or a
    client that was not driving) is a fresh press afterwards."""
    s = make_session()
    s.request_mode("teleop")
    hold(s, TURN, 0.3)
    assert s.set_teleop(Twist2D(), "dashboard")  # released before the e-stop
    s.estop("another client")
    s.run_for(0.3)
    assert s.reset() == Mode.IDLE
    s.request_mode("teleop")
    assert all(hold(s, TURN, 0.5)) and s.last_command.wz > 0.3
    assert s.set_teleop(Twist2D(0.1, 0.0, 0.0), "another client")  # never held anything
