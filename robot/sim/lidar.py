"""Simulated 2D lidar: exact ray casts on the world grid and the people's discs, Gaussian range
noise and dropouts.

Ranges are in the ``laser`` frame (counter-clockwise from the mount's x axis, REP-103) and follow
REP-117: ``+inf`` for no return (nothing within ``range_max`` or a dropout), ``-inf`` for a return
closer than ``range_min`` (the sensor cannot measure it).
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import LaserScan, Pose2D
from robot.profiles import LidarSpec
from robot.sim.world import World


class SimLidar:
    """Produces ``LaserScan``s for a ``LidarSpec`` mounted on the robot."""

    def __init__(self, spec: LidarSpec, rng: np.random.Generator, noise: bool = True) -> None:
        self.spec = spec
        self.rng = rng
        self.noise = noise
        self.mount = Pose2D(spec.mount_x, spec.mount_y, spec.mount_yaw)
        self.beam_angles = spec.angle_min + spec.angle_increment * np.arange(spec.beams)
        self._cache: tuple[Pose2D, int, int, np.ndarray] | None = None  # pose, world and people versions

    def true_ranges(self, world: World, base_pose: Pose2D) -> np.ndarray:
        """Noise-free ranges (metres, inf = nothing within range_max) from ``base_pose`` (map frame).
        A robot at rest in an unchanged world (same pose, same static world, nobody moved) gets the
        previous cast again: an idle simulator costs almost nothing."""
        c = self._cache
        if c is not None and c[0] == base_pose and c[1] == world.version and c[2] == world.people.version:
            return c[3].copy()
        laser = base_pose.compose(self.mount)
        world_angles = laser.theta + self.beam_angles
        origin = np.array([laser.x, laser.y])
        r = world.raycaster.cast(origin, world_angles, self.spec.range_max)[0]
        if len(world.people) and world.people.near(laser.x, laser.y, self.spec.range_max):
            r = np.minimum(r, world.people.ranges(origin, world_angles, self.spec.range_max))
        self._cache = (base_pose, world.version, world.people.version, r.copy())
        return r

    def scan(self, world: World, base_pose: Pose2D, stamp: float) -> LaserScan:
        spec = self.spec
        r = self.true_ranges(world, base_pose)
        if self.noise:
            r = r + self.rng.normal(0.0, spec.range_noise_std, r.shape)
            r[self.rng.random(r.shape) < spec.dropout_prob] = np.inf
        r[r > spec.range_max] = np.inf
        r[r < spec.range_min] = -np.inf
        return LaserScan(
            stamp=stamp,
            angle_min=spec.angle_min,
            angle_increment=spec.angle_increment,
            ranges=r,
            range_min=spec.range_min,
            range_max=spec.range_max,
        )

    @property
    def period(self) -> float:
        return 1.0 / self.spec.rate_hz if self.spec.rate_hz > 0 else math.inf
