"""``SimPump``: one simulated robot shared by the emulated base and the emulated lidar.

``SimDriver.read`` returns what is new since the last call, so two emulators must not each call it.
The pump owns the simulator: one thread steps it in real time at ``rate_hz`` and fans the frames
out to subscribers (the base firmware gets ticks/gyro/IR/battery, the lidar gets scans); commands
from the emulated firmware reach the simulator through the pump's lock. This is how the base and
lidar emulators share one world in one process (``EmulatorPair``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace

from nav.types import Pose2D, Twist2D
from robot.base import SensorFrame
from robot.clock import RealClock
from robot.profiles import RobotProfile
from robot.sim import SimDriver, World


class SimPump:
    """Steps a ``SimDriver`` on wall time and hands each ``SensorFrame`` to every subscriber."""

    def __init__(self, sim, rate_hz: float = 200.0) -> None:
        self.sim = sim
        self.period = 1.0 / rate_hz
        self._lock = threading.Lock()
        self._subs: list[Callable[[SensorFrame], None]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @classmethod
    def for_world(
        cls,
        world_name: str,
        profile: RobotProfile,
        seed: int = 0,
        start_pose: Pose2D | None = None,
        rate_hz: float = 200.0,
    ) -> SimPump:
        """A pump over a fresh ``SimDriver`` in a stock world (``box`` = a 6 x 4 m empty room)."""
        world = World.box(6.0, 4.0) if world_name == "box" else World.stock(world_name)
        return cls(SimDriver(world, profile, RealClock(), seed=seed, start_pose=start_pose), rate_hz)

    @property
    def profile(self) -> RobotProfile:
        return self.sim.profile

    def subscribe(self, fn: Callable[[SensorFrame], None]) -> None:
        self._subs = [*self._subs, fn]

    def command(self, cmd: Twist2D) -> None:
        with self._lock:
            self.sim.command(cmd)

    def estop(self) -> None:
        with self._lock:
            self.sim.estop()

    def reset(self) -> None:
        with self._lock:
            self.sim.reset()

    def set_ir_stop(self, enabled: bool) -> None:
        """The firmware's IR interrupt is modelled in the simulator's physics substeps (it cuts the
        motors between control ticks, as an interrupt does); this switches it."""
        with self._lock:
            self.sim.options = replace(self.sim.options, ir_stop=enabled)

    @property
    def truth_pose(self) -> Pose2D:
        with self._lock:
            return self.sim.truth_pose

    def step(self) -> SensorFrame:
        """Advance the simulator to now and publish the frame (the thread calls this)."""
        with self._lock:
            frame = self.sim.read()
        for fn in self._subs:
            fn(frame)
        return frame

    def start(self) -> SimPump:
        """Take one step synchronously (the simulator's first ray cast builds its caches, which can
        take a second), then step in the background."""
        if self._thread is None:
            with self._lock:
                self.sim.read()
            self._thread = threading.Thread(target=self._run, name="sim-pump", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.step()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        with self._lock:
            self.sim.close()
