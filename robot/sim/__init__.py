"""The simulator: a grid world with people, a rigid body with motors and encoders, lidar, gyro and IR
sensors, fault switches, behind the same ``Driver`` protocol as the real base."""

from robot.sim.driver import SimDriver
from robot.sim.faults import FaultSpecError, SimFaults
from robot.sim.people import Crowd, PeopleError, PersonInfo
from robot.sim.physics import SimOptions
from robot.sim.scenario import Scenario, ScenarioError, load_scenario
from robot.sim.world import World, WorldError

__all__ = [
    "Crowd",
    "FaultSpecError",
    "PeopleError",
    "PersonInfo",
    "Scenario",
    "ScenarioError",
    "SimDriver",
    "SimFaults",
    "SimOptions",
    "World",
    "WorldError",
    "load_scenario",
]
