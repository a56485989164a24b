"""The driver interface: one Protocol implemented by the simulator and by the serial hardware.

A driver turns the world into timestamped readings and takes velocity commands. It does not
integrate odometry (``robot.odometry`` does that from wheel ticks and the gyro, the same way for
every driver) and it does not decide anything: the session owns policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol, runtime_checkable

import numpy as np

from nav.types import LaserScan, Twist2D
from robot.profiles import RobotProfile


@dataclass(frozen=True)
class ImuReading:
    stamp: float
    gyro_z: float  # rad/s, counter-clockwise
    accel: tuple[float, float, float] = (0.0, 0.0, 9.81)  # m/s^2 in base_link


@dataclass(frozen=True)
class WheelTicks:
    """Cumulative encoder counts, one per wheel in the profile's wheel order
    (skid/diff: FL, RL, FR, RR; omni: front, left, rear, right)."""

    stamp: float
    counts: np.ndarray  # int64


@dataclass(frozen=True)
class IrReading:
    stamp: float
    triggered: np.ndarray  # bool per IR sensor in profile order
    ranges: np.ndarray  # metres to the nearest object (inf if none within range)


class LinkState(StrEnum):
    OK = "ok"
    DEGRADED = "degraded"
    LOST = "lost"


@dataclass(frozen=True)
class LinkStatus:
    state: LinkState = LinkState.OK
    reason: str = ""
    rx_frames: int = 0
    bad_frames: int = 0


@dataclass(frozen=True)
class SensorFrame:
    """Everything new since the last ``Driver.read()``; any field may be None if nothing arrived."""

    stamp: float
    scan: LaserScan | None = None
    ticks: WheelTicks | None = None
    imu: ImuReading | None = None
    ir: IrReading | None = None
    battery_v: float | None = None
    link: LinkStatus = field(default_factory=LinkStatus)
    base_stopped_by_obstacle: bool = False  # the base's own (firmware / sim) obstacle stop
    collision: bool = False  # simulator only: the body touched an obstacle this step
    fault: str | None = None  # a driver-level fault (lidar health error, port gone, ...)
    lidar_fault: str | None = None  # the lidar's part of ``fault`` (the status Link row shows it)


@runtime_checkable
class Driver(Protocol):
    """A robot base with its sensors. ``read`` and ``command`` are called from the control loop only."""

    profile: RobotProfile
    has_lidar: bool
    """False for a base without a lidar (``serial://...`` with no ``lidar=``): it drives by teleop,
    and mapping, localization and navigation are refused."""

    def read(self) -> SensorFrame: ...

    def command(self, cmd: Twist2D) -> None:
        """Set the body velocity (already limited by the caller); held until the next command."""
        ...

    def stop(self) -> None:
        """Command zero velocity."""
        ...

    def estop(self) -> None:
        """Latch an emergency stop in the base: motors off until ``reset``."""
        ...

    def reset(self) -> None:
        """Release the base's e-stop latch."""
        ...

    def close(self) -> None: ...
