"""Rigid-body physics of the simulated base: acceleration-limited motors, wheel slip, encoders and a
footprint that cannot pass through obstacles or people.

Each fixed substep (``SimOptions.physics_rate_hz``) the motor twist moves toward the command within
the profile's ``acc_lim_*`` / ``decel_lim_*``; the wheels turn by the inverse kinematics of that
twist (what the encoders count); the body moves by the same twist perturbed by multiplicative slip
noise (and, for skid steer, an effective track wider than the wheel track: skid-steer bases turn
less than their encoders claim). The new pose is accepted if every sample point of the
footprint lies in a free cell. Otherwise a collision (contact) is reported and the body still takes
the first of these motions that does not deepen the contact: the whole substep, its rotation alone,
its translation alone (a base pushed against a post slides along it or turns away). "Deepen" is
judged contact by contact (``robot/sim/contact.py``): each occupied cell's exact overlap with the
footprint polygon and each person's disc's reach into it must stay within what it is now or
``SimOptions.contact_skin``, whichever is more. So a robot in contact can back out, turn away or
slide along what it touches, also with a chair leg on each side; one already overlapping something
(a person stepped into it, a teleport, an obstacle added under it) can leave it; pushing on never
gets further in. When no motion qualifies the body stays and the motors stall (velocity zero,
wheels do not turn). The contact itself is still detected at the footprint's sample points (fast
enough for every substep), so a cell's corner may poke up to half the edge spacing in between them
unreported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav.types import Pose2D, Twist2D
from robot.kinematics import integrate_twist
from robot.profiles import RobotProfile
from robot.sim.contact import ContactProbe, convex_outline
from robot.sim.world import World, points_in_polygon

_MAX_SUBSTEP_MOTION = 0.05
"""m; a bound on how far a footprint point moves in one physics substep (2 m/s x 10 ms with room to
spare): the static cells a contact probe gathers reach this far beyond the footprint."""


@dataclass(frozen=True)
class SimOptions:
    """Options of the simulator (physics, sensor noise switches, battery)."""

    physics_rate_hz: float = 100.0
    """Hz; fixed physics substep rate. Default 100 (the base's 10 ms motor task in source A)."""
    slip_noise_std: float = 0.02
    """Relative std of the per-substep multiplicative noise on the body's v and w. Default 0.02."""
    skid_track_factor: float = 1.0
    """Effective / nominal track width for skid steer (> 1: turns less than the encoders claim).
    Default 1.0 (no systematic scrub)."""
    lidar_noise: bool = True
    """Apply the profile's lidar range noise and dropouts. Default True."""
    gyro_noise: bool = True
    """Apply the profile's gyro bias and white noise. Default True."""
    ir_rate_hz: float = 20.0
    """Hz; how often the IR sensors are evaluated. Default 20."""
    people_rate_hz: float = 25.0
    """Hz; how often people are moved (at most 5 cm per step at 1.2 m/s, the map's cell size;
    stepping them every physics substep would cost more than the robot's own physics). Default 25."""
    ir_stop: bool = True
    """The base stops forward motion when an IR sensor triggers (source A's interrupt). Default True."""
    battery_life_s: float = 3 * 3600.0
    """Seconds from full to empty at full speed; half the drain rate when idle. Default 3 h."""
    footprint_spacing: float = 0.02
    """Metres between sample points on the footprint's edge for collision checks (finer than the
    map so an edge sweeping into a cell is caught). Default 0.02."""
    footprint_interior_spacing: float = 0.05
    """Metres between interior sample points (no coarser than the map resolution, so a cell lying
    wholly inside the footprint, e.g. after a teleport, is caught too). Default 0.05."""
    contact_skin: float = 0.002
    """Metres of penetration into any one obstacle cell or person a body in contact may take (a
    bumper's compliance): the slack that lets a body slide along what it touches despite noise and
    the grid's steps. Default 0.002."""

    def __post_init__(self) -> None:
        positive = (
            "physics_rate_hz",
            "ir_rate_hz",
            "people_rate_hz",
            "battery_life_s",
            "footprint_spacing",
            "footprint_interior_spacing",
            "skid_track_factor",
        )
        if not (math.isfinite(self.contact_skin) and self.contact_skin >= 0):
            raise ValueError(f"SimOptions.contact_skin must be >= 0, got {self.contact_skin!r}")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"SimOptions.{name} must be a positive number, got {value!r}")
        if not (math.isfinite(self.slip_noise_std) and self.slip_noise_std >= 0):
            raise ValueError(f"SimOptions.slip_noise_std must be >= 0, got {self.slip_noise_std!r}")


def footprint_samples(
    polygon: np.ndarray, spacing: float, interior_spacing: float | None = None
) -> np.ndarray:
    """Points covering a footprint polygon (its boundary and interior) in base_link, (N, 2)."""
    poly = np.asarray(polygon, dtype=float)
    q = np.roll(poly, -1, axis=0)
    edges = []
    for a, b in zip(poly, q, strict=True):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / spacing))
        t = np.arange(n)[:, None] / n
        edges.append(a + t * (b - a))
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    step = interior_spacing or spacing
    xs = np.arange(lo[0] + step / 2, hi[0], step)
    ys = np.arange(lo[1] + step / 2, hi[1], step)
    gx, gy = np.meshgrid(xs, ys)
    grid = np.column_stack((gx.ravel(), gy.ravel()))
    interior = grid[points_in_polygon(grid, poly)] if grid.size else np.zeros((0, 2))
    return np.vstack([*edges, interior])


class NormalStream:
    """Standard normal samples drawn from a generator in blocks: one numpy call per 4096 samples
    instead of one per physics substep, same determinism for a seed."""

    def __init__(self, rng: np.random.Generator, block: int = 4096) -> None:
        self.rng = rng
        self.block = block
        self._buf: list[float] = []
        self._i = 0

    def next(self) -> float:
        if self._i >= len(self._buf):
            self._buf = self.rng.standard_normal(self.block).tolist()
            self._i = 0
        self._i += 1
        return self._buf[self._i - 1]


def _approach(v: float, target: float, acc: float, dec: float, dt: float) -> float:
    """Move ``v`` toward ``target``: ``acc`` when speeding up, ``dec`` when slowing or reversing."""
    speeding_up = (v >= 0 and target > v) or (v <= 0 and target < v)
    lim = (acc if speeding_up else dec) * dt
    if lim <= 0:
        return target
    return v + max(-lim, min(lim, target - v))


class SimBody:
    """State and stepping of one simulated base."""

    def __init__(
        self, profile: RobotProfile, options: SimOptions, rng: np.random.Generator, pose: Pose2D
    ) -> None:
        self.profile = profile
        self.options = options
        self.rng = rng
        self.noise = NormalStream(rng)
        self.pose = pose
        self.velocity = Twist2D()  # motor twist (body frame)
        self._wheel = [0.0] * profile.wheel_count  # cumulative radians, profile order (see wheel_angle)
        self.samples = footprint_samples(
            profile.footprint_polygon(32), options.footprint_spacing, options.footprint_interior_spacing
        )
        self._reach = float(np.max(np.hypot(self.samples[:, 0], self.samples[:, 1])))
        self.outline = convex_outline(profile.footprint_polygon(32))
        self.last_hit: str | None = None  # what the latest collision was with
        self._rest: tuple[Pose2D, int] | None = None  # (pose, world version) verified free at rest
        self.last_accel = (0.0, 0.0)
        self.true_yaw_rate = 0.0

    def collides(self, world: World, pose: Pose2D) -> bool:
        """Whether the footprint at ``pose`` overlaps an occupied cell or a person (sampled every
        ``footprint_spacing`` on the edge and ``footprint_interior_spacing`` inside). Sets
        ``last_hit`` to ``"obstacle"`` or ``"person:<id>"``."""
        crowd = world.people
        if len(crowd) and crowd.near(pose.x, pose.y, self._reach):
            pid = crowd.hit_by(pose.transform_points(self.samples))
            if pid is not None:
                self.last_hit = f"person:{pid}"
                return True
        if world.clearance_at(pose.x, pose.y) > self._reach:
            return False  # open space: no obstacle within the footprint's circumscribed circle
        if world.raycaster.any_occupied_at_pose(self.samples, pose.x, pose.y, pose.theta):
            self.last_hit = "obstacle"
            return True
        return False

    def penetration(self, world: World, pose: Pose2D) -> tuple[float, float]:
        """(deepest, total) penetration (m) of the footprint at ``pose`` into obstacle cells and
        people (``robot.sim.contact``); (0, 0) when free."""
        static, people = ContactProbe(world, self.outline, pose, self._reach).depths(pose)
        d = np.concatenate((static, people))
        return (float(d.max()), float(d.sum())) if len(d) else (0.0, 0.0)

    def _contact_motion(self, world: World, body: Twist2D, dt: float) -> tuple[Pose2D, Twist2D] | None:
        """After the whole substep ``body`` touched something: the first of (the whole motion, its
        rotation alone, its translation alone) that takes no contact deeper than it is now or than
        the contact skin, whichever is more, as (pose, the part of ``body`` taken); None if every
        one of them would press something further in. Contact by contact: a base touching two chair
        legs may leave one and slide along the other."""
        probe = ContactProbe(world, self.outline, self.pose, self._reach + _MAX_SUBSTEP_MOTION)
        skin = self.options.contact_skin
        limit = [np.maximum(d, skin) + 1e-12 for d in probe.depths(self.pose)]
        parts = (body, Twist2D(0.0, 0.0, body.wz), Twist2D(body.vx, body.vy, 0.0))
        for k, part in enumerate(parts):
            if k and part.is_zero():
                continue
            pose = integrate_twist(self.pose, part, dt)
            if all(np.all(d <= lim) for d, lim in zip(probe.depths(pose), limit, strict=True)):
                return pose, part
        return None

    def step(self, world: World, target: Twist2D, dt: float) -> bool:
        """Advance one substep toward ``target``; returns True on a collision.

        At rest (motors and command exactly zero) at a pose already found free in an unchanged world
        with nobody near, nothing can move or touch: the step is skipped (an idle robot costs a few
        attribute reads per substep). The slip noise is still drawn so that a seed gives the same
        run whether or not the robot paused."""
        lim = self.profile.limits
        v = self.velocity
        if (
            self._rest is not None
            and self._rest[0] is self.pose
            and self._rest[1] == world.version
            and v.vx == 0.0
            and v.vy == 0.0
            and v.wz == 0.0
            and target.vx == 0.0
            and target.vy == 0.0
            and target.wz == 0.0
            and not (len(world.people) and world.people.near(self.pose.x, self.pose.y, self._reach + 0.5))
        ):
            if self.options.slip_noise_std > 0:
                self.noise.next(), self.noise.next(), self.noise.next()
            self.last_accel = (0.0, 0.0)
            self.true_yaw_rate = 0.0
            return False
        omni = self.profile.is_omni
        vx = _approach(v.vx, target.vx, lim.acc_lim_x, abs(lim.decel_lim_x), dt)
        vy = (
            _approach(v.vy, target.vy if omni else 0.0, lim.acc_lim_y, abs(lim.decel_lim_y), dt)
            if omni
            else 0.0
        )
        wz = _approach(v.wz, target.wz, lim.acc_lim_theta, abs(lim.decel_lim_theta), dt)
        motor = Twist2D(vx, vy, wz)
        std = self.options.slip_noise_std
        if std > 0:
            nx, ny, nw = std * self.noise.next(), std * self.noise.next(), std * self.noise.next()
        else:
            nx = ny = nw = 0.0
        turn = 1.0 if omni else 1.0 / self.options.skid_track_factor
        body = Twist2D(vx * (1 + nx), vy * (1 + ny), wz * turn * (1 + nw))
        candidate = integrate_twist(self.pose, body, dt)
        contact = self.collides(world, candidate)
        if contact:
            taken = self._contact_motion(world, body, dt)
            if taken is None:
                self.velocity = Twist2D()
                self.last_accel = (-v.vx / dt, -v.vy / dt)
                self.true_yaw_rate = 0.0
                self._rest = None
                return True
            candidate, body = taken
            # the motors keep turning only for the part of the motion the contact lets through
            if body.vx == 0.0 and body.vy == 0.0:
                vx = vy = 0.0
            if body.wz == 0.0:
                wz = 0.0
            motor = Twist2D(vx, vy, wz)
        # plain floats: four numpy ops per substep cost more than the arithmetic (same IEEE results)
        k = dt / self.profile.wheel_radius
        self._wheel = [a + v * k for a, v in zip(self._wheel, self._rim_speeds(motor), strict=True)]
        self.last_accel = ((vx - v.vx) / dt, (vy - v.vy) / dt)
        self.velocity = motor
        self.pose = candidate
        self.true_yaw_rate = body.wz
        at_rest = vx == 0.0 and vy == 0.0 and wz == 0.0 and v.vx == 0.0 and v.vy == 0.0 and v.wz == 0.0
        self._rest = (candidate, world.version) if at_rest and not contact else None
        return contact

    @property
    def wheel_angle(self) -> np.ndarray:
        """Cumulative wheel angles (radians), profile order."""
        return np.array(self._wheel)

    def _rim_speeds(self, t: Twist2D) -> list[float]:
        """Wheel rim speeds of the motor twist in profile order (scalar math: runs every substep)."""
        p = self.profile
        if p.is_omni:
            r = p.omni_radius * t.wz
            return [t.vy + r, -t.vx + r, -t.vy + r, t.vx + r]
        vl, vr = t.vx - t.wz * p.track_width / 2.0, t.vx + t.wz * p.track_width / 2.0
        return [vl, vl, vr, vr] if p.wheel_count == 4 else [vl, vr]

    def ticks(self) -> np.ndarray:
        """Cumulative encoder counts (int64), profile wheel order."""
        return np.floor(self.wheel_angle / (2 * math.pi) * self.profile.ticks_per_rev).astype(np.int64)
