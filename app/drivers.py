"""Build the driver named by ``--robot`` (``sim`` or a ``serial://`` URL)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from maps.mapio import MapFormatError
from maps.stock import available_worlds, stock_world_path
from nav.types import OccupancyGrid, Pose2D
from robot.base import Driver
from robot.clock import Clock
from robot.profiles import RobotProfile
from robot.serial.driver import SerialDriver, SerialError, parse_serial_url
from robot.sim import SimDriver, World, WorldError


class DriverConfigError(ValueError):
    """The robot URL, world or port is unusable; the message is one line for the operator."""


@dataclass
class DriverBundle:
    driver: Driver
    grid: OccupancyGrid | None  # the world map shown before any other map is chosen
    start_pose: Pose2D
    world_name: str | None
    lidar_timeout: float | None = None
    """s of lidar silence the driver itself tolerates (the robot URL's ``lidar_timeout``); the session's
    own silence limit is never shorter, or the URL's option could not lengthen it."""


def resolve_world(world: str) -> Path:
    path = Path(world)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise DriverConfigError(f"world file {world} does not exist")
        return path
    try:
        return stock_world_path(world)
    except (KeyError, ValueError, FileNotFoundError):
        raise DriverConfigError(
            f"unknown world {world!r}: give a map YAML path or one of {', '.join(available_worlds())}"
        ) from None


def make_driver(robot: str, profile: RobotProfile, world: str, clock: Clock, seed: int = 0) -> DriverBundle:
    if robot == "sim":
        path = resolve_world(world)
        try:
            sim_world = World.from_yaml(path)
        except (MapFormatError, WorldError) as exc:
            raise DriverConfigError(f"world {path}: {exc}") from exc
        start = sim_world.start_pose
        driver = SimDriver(sim_world, profile, clock, seed=seed, start_pose=start)
        return DriverBundle(driver, sim_world.grid, start, path.stem)
    if robot.startswith("serial://"):
        try:
            opts = parse_serial_url(robot)
            driver = SerialDriver.from_url_options(opts, profile, clock)
        except SerialError as exc:
            raise DriverConfigError(str(exc)) from exc
        return DriverBundle(driver, None, Pose2D(), None, lidar_timeout=opts.lidar_timeout)
    raise DriverConfigError(
        f"unknown robot {robot!r}: use 'sim' or 'serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1'"
    )
