"""Simulated infrared obstacle sensors (source A: E3F-DS30Y2, 30 cm, front of the base).

Each sensor looks along a small fan of rays across its field of view; it reports the nearest
return and triggers when that is within its range, like the digital output that stops the motors
in the base. The rays are sampled every ``IR_STEP`` metres (finer than any map resolution we use)
rather than ray cast exactly: an IR sensor is a coarse proximity switch, and one table lookup for
all samples keeps the 20 Hz check cheap inside the physics loop. People (discs) are tested on the
same sample points.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import Pose2D
from robot.base import IrReading
from robot.profiles import IrSensor
from robot.sim.world import World

RAYS_PER_SENSOR = 5
IR_STEP = 0.01  # metres between samples along each IR ray


class SimIr:
    """All IR sensors of a profile, evaluated at once."""

    def __init__(self, sensors: tuple[IrSensor, ...]) -> None:
        self.sensors = sensors
        n = len(sensors)
        self._range = np.array([s.range for s in sensors], dtype=float)
        xy = np.array([[s.x, s.y] for s in sensors], dtype=float).reshape(n, 2)
        spread = np.linspace(-0.5, 0.5, RAYS_PER_SENSOR)
        steps = int(np.ceil(self._range.max() / IR_STEP)) if n else 0
        # distances along each ray; samples beyond a sensor's range are masked out when reading
        self._dist = (np.arange(steps) + 1) * IR_STEP
        yaw = np.array([[s.yaw + f * s.fov for f in spread] for s in sensors], dtype=float).reshape(
            n, RAYS_PER_SENSOR
        )
        d = self._dist[None, None, :]
        self._points = np.stack(
            (
                xy[:, 0, None, None] + np.cos(yaw)[..., None] * d,
                xy[:, 1, None, None] + np.sin(yaw)[..., None] * d,
            ),
            axis=-1,
        ).reshape(-1, 2)  # (n * rays * steps, 2) in base_link
        self._shape = (n, RAYS_PER_SENSOR, steps)
        self._in_range = self._dist[None, None, :] <= self._range[:, None, None] + 1e-12
        # farthest point any IR beam can reach from base_link
        self._reach = float(np.max(np.hypot(xy[:, 0], xy[:, 1]) + self._range)) if n else 0.0
        self._mounts = [(float(x), float(y), float(r)) for (x, y), r in zip(xy, self._range, strict=True)]

    def read(self, world: World, base_pose: Pose2D, stamp: float) -> IrReading:
        n = len(self.sensors)
        people = len(world.people) > 0 and world.people.near(base_pose.x, base_pose.y, self._reach)
        if not n or (
            not people
            and (world.clearance_at(base_pose.x, base_pose.y) > self._reach or self._clear(world, base_pose))
        ):
            return IrReading(stamp, np.zeros(n, dtype=bool), np.full(n, np.inf))
        pts = base_pose.transform_points(self._points)
        hit = world.raycaster.occupied_at(pts)
        if people:
            hit |= world.people.contains(pts)
        hit = hit.reshape(self._shape)
        hit &= self._in_range
        first = np.where(hit.any(axis=2), self._dist[hit.argmax(axis=2)], np.inf)  # (n, rays)
        nearest = first.min(axis=1)
        return IrReading(stamp, np.isfinite(nearest), nearest)

    def _clear(self, world: World, base_pose: Pose2D) -> bool:
        """Whether every sensor's samples (all within its range of its mount) are farther from any
        static obstacle than that range: then nothing can be hit (scalar math, the usual case in a
        corridor, where the whole-robot reach test fails but each forward sensor sees nothing)."""
        c, s = math.cos(base_pose.theta), math.sin(base_pose.theta)
        for x, y, r in self._mounts:
            wx, wy = base_pose.x + c * x - s * y, base_pose.y + s * x + c * y
            if world.clearance_at(wx, wy) <= r:
                return False
        return True
