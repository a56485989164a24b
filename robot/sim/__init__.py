"""The simulator: a grid world, a rigid body with motors and encoders, lidar, gyro and IR sensors,
behind the same ``Driver`` protocol as the real base."""

from robot.sim.driver import SimDriver
from robot.sim.physics import SimOptions
from robot.sim.world import World, WorldError

__all__ = ["SimDriver", "SimOptions", "World", "WorldError"]
