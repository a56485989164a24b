"""``EmulatorPair``: an emulated base and an emulated RPLidar A1 sharing one simulated robot.

Both emulators subscribe to one ``SimPump``, so the lidar sees the world from wherever the base
has driven. This is the default of ``navdeck emulate base``: a robot's base and lidar must share a
world, and two processes could not share one simulator without an IPC channel of their own.
"""

from __future__ import annotations

from pathlib import Path

from nav.types import Pose2D
from robot.profiles import RobotProfile
from robot.serial.emulate_base import BaseEmulator
from robot.serial.emulate_rplidar import RPLidarEmulator
from robot.serial.pty import PtyPort
from robot.serial.simlink import SimPump


class EmulatorPair:
    """A simulated robot behind two pseudo-terminals: ``base_path`` and ``lidar_path``."""

    def __init__(
        self,
        profile: RobotProfile,
        world: str = "office",
        seed: int = 0,
        start_pose: Pose2D | None = None,
        link_dir: str | Path | None = None,
        lidar: bool = True,
        sample_rate: float | None = None,  # None: enough for the profile's beams (default_sample_rate)
        pump: SimPump | None = None,
    ) -> None:
        self.pump = pump or SimPump.for_world(world, profile, seed=seed, start_pose=start_pose)
        base_link = Path(link_dir) / "base" if link_dir is not None else None
        lidar_link = Path(link_dir) / "rplidar" if link_dir is not None else None
        self.base = BaseEmulator(self.pump, PtyPort(base_link, name="base"))
        self.lidar = (
            RPLidarEmulator(
                self.pump, PtyPort(lidar_link, name="rplidar"), sample_rate=sample_rate, seed=seed
            )
            if lidar
            else None
        )

    @property
    def base_path(self) -> str:
        return self.base.path

    @property
    def lidar_path(self) -> str | None:
        return self.lidar.path if self.lidar is not None else None

    def url(self) -> str:
        """The ``--robot`` URL that connects ``SerialDriver`` to this pair."""
        q = f"?lidar={self.lidar_path}" if self.lidar_path else ""
        return f"serial://{self.base_path}{q}"

    def start(self) -> EmulatorPair:
        self.pump.start()
        self.base.start()
        if self.lidar is not None:
            self.lidar.start()
        return self

    def close(self) -> None:
        if self.lidar is not None:
            self.lidar.close()
        self.base.close()
        self.pump.close()

    def __enter__(self) -> EmulatorPair:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
