"""People in the simulator: 0.3 m discs that walk scripted loops, wander at random or step in front
of the robot (source A's moving-obstacle trial: a person steps in about 0.3 m ahead of the robot).

Why discs cast analytically instead of cells in the grid: the static ray caster keeps its padded
table and distance transform (built once per world); people are few, so each lidar beam is also
intersected with every disc in closed form (B x P ray/circle tests, one numpy expression) and the
range is the minimum of both. Collision and IR checks test sample points against the discs the same
way. ``Crowd.mask`` rasterizes the discs for consumers that want a grid (``World.occupied``).

Motion is vectorized over people: every person walks straight toward its current target at its
speed; only when one arrives does its behaviour (a small Python object) choose the next target, so
the per-substep cost is a handful of numpy operations whatever the number of people. A person never
walks into the robot: a step that would overlap the robot's circumscribed circle is not taken (the
person waits), so every contact between them is the robot's doing and is reported as its collision.
A walker kept waiting by the robot for ``GIVE_WAY_S`` turns back the way it came (a loop walker
reverses along its loop, a wanderer picks a new goal), as people do in an aisle a robot blocks:
waiting forever for a robot that waits for them deadlocked both (issue 16, a greenhouse aisle).
People do not avoid each other (they may pass through one another).
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from nav.types import GridGeometry, Pose2D

if TYPE_CHECKING:
    from robot.sim.world import World

PERSON_RADIUS = 0.15
"""Metres: a person seen at lidar height (legs / hips) as a 0.3 m disc."""
MIN_SPEED, MAX_SPEED = 0.5, 1.2
"""m/s: walking speeds people are given (slow stroll to brisk walk)."""
GIVE_WAY_S = 3.0
"""s a walker waits for the robot to clear its way before it turns back."""


class PeopleError(ValueError):
    """A person could not be added (bad speed, radius, waypoints or unknown id)."""


class Behaviour(Protocol):
    """Chooses a person's next target when it arrives (and may override it while walking)."""

    kind: str

    def next_target(self, crowd: Crowd, i: int) -> np.ndarray | None:
        """The next point to walk to, or None to stand still where it is."""
        ...

    def update(self, crowd: Crowd, i: int, robot: Pose2D, now: float) -> None:
        """Called every step before walking (for behaviours that react to the robot)."""
        ...


class Loop:
    """Walk a scripted closed loop of waypoints forever (a person crossing a corridor and back)."""

    kind = "loop"

    def __init__(self, waypoints: np.ndarray) -> None:
        self.waypoints = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        self._k = 0
        self._step = 1  # walking the loop forwards (1) or backwards (-1)

    def next_target(self, crowd: Crowd, i: int) -> np.ndarray | None:
        if len(self.waypoints) < 2:
            return None  # a single waypoint: stand there
        self._k = (self._k + self._step) % len(self.waypoints)
        return self.waypoints[self._k]

    def turn_back(self, crowd: Crowd, i: int) -> np.ndarray | None:
        """Walk the loop the other way, starting with the waypoint just left."""
        if len(self.waypoints) < 2:
            return None
        self._k = (self._k - self._step) % len(self.waypoints)
        self._step = -self._step
        return self.waypoints[self._k]

    def update(self, crowd: Crowd, i: int, robot: Pose2D, now: float) -> None:
        return None


class RandomWalk:
    """Wander: on arrival pick a random point within ``reach`` metres that is free (clearance >= the
    disc radius plus ``margin``) and in line of sight; 16 candidates are tested in one ray cast."""

    kind = "random"

    def __init__(self, rng: np.random.Generator, reach: float = 3.0, margin: float = 0.1) -> None:
        self.rng = rng
        self.reach = reach
        self.margin = margin

    def next_target(self, crowd: Crowd, i: int) -> np.ndarray | None:
        world = crowd.world
        p = crowd.xy[i]
        if world is None:
            return p + self.rng.uniform(-self.reach, self.reach, 2)
        n, res = 16, world.geometry.resolution
        ang = self.rng.uniform(-math.pi, math.pi, n)
        dist = self.rng.uniform(0.3 * self.reach, self.reach, n)
        # samples every half cell along each candidate segment (n x m points, one table lookup):
        # the whole disc must keep ``margin`` from the walls all the way, not just its centre
        frac = np.linspace(0.0, 1.0, max(2, math.ceil(self.reach / (0.5 * res)) + 1))
        along = (dist[:, None] * frac[None, :])[..., None]
        pts = p + np.stack((np.cos(ang), np.sin(ang)), axis=-1)[:, None, :] * along
        rows, cols = world.geometry.world_to_cell(pts.reshape(-1, 2))
        inside = world.geometry.in_bounds(rows, cols)
        clear = np.zeros(rows.shape)
        clear[inside] = world.clearance_map[rows[inside], cols[inside]]
        need = crowd.radius[i] + self.margin + res * math.sqrt(2.0)  # centre-to-centre transform
        ok = (clear.reshape(n, -1)[:, 1:] >= need).all(axis=1)
        cand = pts[:, -1, :]
        if not ok.any():
            return None  # boxed in: wait and try again next arrival
        return cand[int(np.argmax(ok))]

    def turn_back(self, crowd: Crowd, i: int) -> np.ndarray | None:
        """Blocked by the robot: wander somewhere else (a new random goal)."""
        return self.next_target(crowd, i)

    def update(self, crowd: Crowd, i: int, robot: Pose2D, now: float) -> None:
        return None


class StepIn:
    """Source A's moving-obstacle trial: wait at ``standby`` until the robot comes within
    ``trigger_distance``, then step to a point ``ahead`` metres in front of the robot's front edge
    (on its heading at that moment), stand there ``dwell`` seconds and walk back. Re-arms when the
    robot is farther than ``trigger_distance`` + 1 m from the standby point."""

    kind = "step_in"

    def __init__(
        self,
        standby: np.ndarray,
        trigger_distance: float = 1.5,
        ahead: float = 0.3,
        dwell: float = 3.0,
        front: float = 0.12,
    ) -> None:
        self.standby = np.asarray(standby, dtype=float).reshape(2)
        self.trigger_distance = trigger_distance
        self.ahead = ahead
        self.dwell = dwell
        self.front = front  # robot's front extent from base_link (m); set by the crowd
        self.state = "armed"  # armed -> stepping -> standing -> returning -> (disarmed) -> armed
        self._until = 0.0

    def next_target(self, crowd: Crowd, i: int) -> np.ndarray | None:
        if self.state == "stepping":
            self.state = "standing"
            self._until = crowd.time + self.dwell
        elif self.state == "returning":
            self.state = "disarmed"
        return None

    def update(self, crowd: Crowd, i: int, robot: Pose2D, now: float) -> None:
        d = math.hypot(robot.x - self.standby[0], robot.y - self.standby[1])
        if self.state == "armed" and d <= self.trigger_distance:
            r = crowd.radius[i]
            c, s = math.cos(robot.theta), math.sin(robot.theta)
            reach = self.front + self.ahead + r
            spot = np.array([robot.x + c * reach, robot.y + s * reach])
            # lead the robot: where that spot will be when the person gets there
            eta = float(np.hypot(*(spot - crowd.xy[i]))) / max(crowd.speed[i], 1e-6)
            crowd.target[i] = spot + crowd.robot_velocity * eta
            crowd.walking[i] = True
            self.state = "stepping"
        elif self.state == "standing" and now >= self._until:
            crowd.target[i] = self.standby
            crowd.walking[i] = True
            self.state = "returning"
        elif self.state == "disarmed" and d > self.trigger_distance + 1.0:
            self.state = "armed"


@dataclass(frozen=True)
class PersonInfo:
    """A person as the 3D view and the API see it."""

    id: int
    x: float
    y: float
    heading: float
    radius: float
    speed: float
    behaviour: str


def _locked(method: Callable) -> Callable:
    """Run a ``Crowd`` method under its lock: people are added or removed from API threads while
    the control loop steps and senses them, and the parallel arrays must change together."""

    @functools.wraps(method)
    def wrapper(self: Crowd, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)

    return wrapper


class Crowd:
    """All people of one world, as parallel arrays (positions, targets, speeds, radii). Thread-safe:
    every public method holds the crowd's lock."""

    def __init__(self, world: World | None = None) -> None:
        self.world = world
        self.xy = np.zeros((0, 2))
        self.target = np.zeros((0, 2))
        self.speed = np.zeros(0)
        self.radius = np.zeros(0)
        self.heading = np.zeros(0)
        self.walking = np.zeros(0, dtype=bool)
        self.waited = np.zeros(0)  # s each walker has been kept waiting by the robot
        self.ids: list[int] = []
        self.behaviours: list[Behaviour] = []
        self.time = 0.0
        self.robot_radius = 0.0  # circumscribed radius of the robot people keep out of
        self.robot_front = 0.12
        self.robot_velocity = np.zeros(2)  # m/s in the world frame, from successive robot poses
        self._robot_xy: tuple[float, float] | None = None
        self.version = 0  # bumped whenever anyone moves (for cached rasters)
        self._next_id = 1
        self._reactive: list[int] = []
        self._lock = threading.RLock()
        self._discs: list[tuple[float, float, float]] = []  # (x, y, radius) for ``near``
        self._discs_version = -1

    def __len__(self) -> int:
        return len(self.ids)

    def _reindex(self) -> None:
        self._reactive = [i for i, b in enumerate(self.behaviours) if b.kind == "step_in"]
        self.version += 1

    # ------------------------------------------------------------------------------- editing
    @_locked
    def add(
        self,
        x: float,
        y: float,
        behaviour: Behaviour | None = None,
        speed: float = 0.8,
        radius: float = PERSON_RADIUS,
    ) -> int:
        """Add a person at (x, y) (a standing person when ``behaviour`` is None); returns its id."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise PeopleError(f"person position must be finite, got ({x!r}, {y!r})")
        if not (MIN_SPEED - 1e-9 <= speed <= MAX_SPEED + 1e-9):
            raise PeopleError(f"person speed must be in [{MIN_SPEED}, {MAX_SPEED}] m/s, got {speed!r}")
        if not (0.05 <= radius <= 0.5):
            raise PeopleError(f"person radius must be in [0.05, 0.5] m, got {radius!r}")
        behaviour = behaviour or Loop(np.array([[x, y]]))
        if isinstance(behaviour, StepIn):
            behaviour.front = self.robot_front
        pid = self._next_id
        self._next_id += 1
        self.ids.append(pid)
        self.behaviours.append(behaviour)
        self.xy = np.vstack((self.xy, [x, y]))
        self.target = np.vstack((self.target, [x, y]))
        self.speed = np.append(self.speed, speed)
        self.radius = np.append(self.radius, radius)
        self.heading = np.append(self.heading, 0.0)
        self.walking = np.append(self.walking, False)
        self.waited = np.append(self.waited, 0.0)
        self._arrive(len(self.ids) - 1)
        self._reindex()
        return pid

    def add_loop(self, waypoints: np.ndarray | list, speed: float = 0.8) -> int:
        """A person walking a closed loop through ``waypoints`` ((K, 2), starting at the first)."""
        pts = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        if len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise PeopleError("a walking loop needs at least one finite waypoint")
        return self.add(pts[0, 0], pts[0, 1], Loop(pts), speed)

    def add_random(self, x: float, y: float, rng: np.random.Generator, speed: float = 0.8) -> int:
        return self.add(x, y, RandomWalk(rng), speed)

    def add_step_in(
        self, x: float, y: float, trigger_distance: float = 1.5, dwell: float = 3.0, speed: float = 1.0
    ) -> int:
        return self.add(x, y, StepIn(np.array([x, y]), trigger_distance, dwell=dwell), speed)

    def populate(
        self,
        n: int,
        rng: np.random.Generator,
        avoid: tuple[float, float] | None = None,
        min_gap: float = 1.5,
        clearance: float = 0.5,
    ) -> list[int]:
        """Add ``n`` random walkers (speeds 0.5-1.2 m/s) at random free places with at least
        ``clearance`` metres to any wall and ``min_gap`` metres from ``avoid`` (the robot's start);
        for ``sim-nav --people N``. Raises ``PeopleError`` when the world has no such place."""
        if self.world is None:
            raise PeopleError("populate needs a world to find free space in")
        if n < 0:
            raise PeopleError(f"number of people must be >= 0, got {n}")
        g = self.world.geometry
        rows, cols = np.nonzero(self.world.clearance_map >= clearance)
        pts = g.cell_to_world(rows, cols)
        if avoid is not None:
            pts = pts[np.hypot(pts[:, 0] - avoid[0], pts[:, 1] - avoid[1]) >= min_gap]
        if n and pts.shape[0] == 0:
            raise PeopleError(f"no free place with {clearance} m clearance for people")
        picks = pts[rng.integers(0, pts.shape[0], n)] if n else np.zeros((0, 2))
        speeds = rng.uniform(MIN_SPEED, MAX_SPEED, n)
        return [
            self.add_random(float(x), float(y), rng, float(v))
            for (x, y), v in zip(picks, speeds, strict=True)
        ]

    @_locked
    def remove(self, pid: int) -> None:
        try:
            i = self.ids.index(pid)
        except ValueError:
            raise PeopleError(f"no person with id {pid}") from None
        keep = np.arange(len(self.ids)) != i
        del self.ids[i]
        del self.behaviours[i]
        for name in ("xy", "target", "speed", "radius", "heading", "walking", "waited"):
            setattr(self, name, getattr(self, name)[keep])
        self._reindex()

    @_locked
    def clear(self) -> None:
        for pid in list(self.ids):
            self.remove(pid)

    @_locked
    def list(self) -> list[PersonInfo]:
        return [
            PersonInfo(
                pid,
                float(self.xy[i, 0]),
                float(self.xy[i, 1]),
                float(self.heading[i]),
                float(self.radius[i]),
                float(self.speed[i]),
                self.behaviours[i].kind,
            )
            for i, pid in enumerate(self.ids)
        ]

    @_locked
    def poses(self) -> np.ndarray:
        """(P, 3) x, y, heading of every person (for the 3D view)."""
        return np.column_stack((self.xy, self.heading))

    @_locked
    def move(self, pid: int, x: float, y: float) -> None:
        """Put a person somewhere at once (it then walks on toward its target)."""
        i = self.ids.index(pid)
        self.xy[i] = (x, y)
        self.version += 1

    # ------------------------------------------------------------------------------- motion
    def _arrive(self, i: int) -> None:
        nxt = self.behaviours[i].next_target(self, i)
        if nxt is None:
            self.walking[i] = False
        else:
            self.target[i] = nxt
            self.walking[i] = True

    @_locked
    def step(self, dt: float, robot: Pose2D) -> None:
        """Advance everyone by ``dt`` seconds toward their targets; people wait rather than walk into
        the robot (its circumscribed circle at ``robot``)."""
        self.time += dt
        if self._robot_xy is not None and dt > 0:
            self.robot_velocity = np.array([robot.x - self._robot_xy[0], robot.y - self._robot_xy[1]]) / dt
        self._robot_xy = (robot.x, robot.y)
        if not self.ids:
            return
        for i in self._reactive:  # behaviours that watch the robot (step-in people)
            self.behaviours[i].update(self, i, robot, self.time)
        if not self.walking.any():
            return
        delta = self.target - self.xy
        dist = np.hypot(delta[:, 0], delta[:, 1])
        stride = np.where(self.walking, self.speed * dt, 0.0)
        frac = np.minimum(1.0, stride / np.maximum(dist, 1e-12))
        new = self.xy + delta * frac[:, None]
        gap = np.hypot(new[:, 0] - robot.x, new[:, 1] - robot.y) - self.radius - self.robot_radius
        now_gap = np.hypot(self.xy[:, 0] - robot.x, self.xy[:, 1] - robot.y) - self.radius - self.robot_radius
        blocked = (gap < 0.0) & (gap < now_gap)  # never step (further) into the robot
        moving = self.walking & ~blocked & (dist > 0)
        self.heading = np.where(moving, np.arctan2(delta[:, 1], delta[:, 0]), self.heading)
        self.xy = np.where(moving[:, None], new, self.xy)
        self.version += 1
        arrived = np.flatnonzero(self.walking & ~blocked & (frac >= 1.0))
        for i in arrived:
            self._arrive(int(i))
        self.waited = np.where(self.walking & blocked, self.waited + dt, 0.0)
        for i in np.flatnonzero(self.waited >= GIVE_WAY_S):
            self._give_way(int(i))

    def _give_way(self, i: int) -> None:
        """Walker ``i`` has waited ``GIVE_WAY_S`` for the robot: it turns back (its behaviour's
        ``turn_back``; a behaviour without one, e.g. a step-in person, keeps waiting)."""
        self.waited[i] = 0.0
        turn_back = getattr(self.behaviours[i], "turn_back", None)
        if turn_back is None:
            return
        nxt = turn_back(self, i)
        if nxt is not None:
            self.target[i] = nxt

    # ------------------------------------------------------------------------------- sensing
    @_locked
    def near(self, x: float, y: float, distance: float) -> bool:
        """Whether any disc comes within ``distance`` of (x, y) (the cheap pre-check)."""
        # scalar math over a cached list: called every physics substep, and for the handful of
        # people a world holds this is several times cheaper than building numpy temporaries
        if self._discs_version != self.version:
            self._discs = [
                (p[0], p[1], r) for p, r in zip(self.xy.tolist(), self.radius.tolist(), strict=True)
            ]
            self._discs_version = self.version
        return any(math.hypot(px - x, py - y) - r <= distance for px, py, r in self._discs)

    @_locked
    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Per (N, 2) world point: whether it lies inside any person's disc."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not self.ids:
            return np.zeros(xy.shape[0], dtype=bool)
        d2 = ((xy[:, None, :] - self.xy[None, :, :]) ** 2).sum(axis=2)
        return (d2 <= (self.radius**2)[None, :]).any(axis=1)

    @_locked
    def hit_by(self, xy: np.ndarray) -> int | None:
        """Id of a person containing any of the (N, 2) points, or None."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not self.ids:
            return None
        d2 = ((xy[:, None, :] - self.xy[None, :, :]) ** 2).sum(axis=2)
        inside = (d2 <= (self.radius**2)[None, :]).any(axis=0)
        return self.ids[int(np.argmax(inside))] if inside.any() else None

    @_locked
    def ranges(self, origin: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
        """Distance along each world-frame angle from ``origin`` (2,) to the nearest disc (inf if
        none within ``max_range``): the ray/circle intersection t = b - sqrt(b^2 - |oc|^2 + r^2),
        b = d . oc, for all beams x people at once. An origin inside a disc reads 0."""
        angles = np.asarray(angles, dtype=float)
        out = np.full(angles.shape, np.inf)
        if not self.ids:
            return out
        oc = self.xy - np.asarray(origin, dtype=float).reshape(1, 2)  # (P, 2)
        dist = np.hypot(oc[:, 0], oc[:, 1])
        near = dist - self.radius <= max_range
        if not near.any():
            return out
        oc, r = oc[near], self.radius[near]
        b = np.cos(angles)[:, None] * oc[None, :, 0] + np.sin(angles)[:, None] * oc[None, :, 1]
        disc = b * b - (oc**2).sum(axis=1)[None, :] + (r * r)[None, :]
        with np.errstate(invalid="ignore"):
            t = b - np.sqrt(disc)
        inside = (dist[near] <= r)[None, :]
        t = np.where(inside, 0.0, np.where((disc >= 0.0) & (t >= 0.0), t, np.inf))
        out = t.min(axis=1)
        out[out > max_range] = np.inf
        return out

    @_locked
    def mask(self, geometry: GridGeometry) -> np.ndarray:
        """(H, W) bool: cells whose centre lies inside a disc (only each disc's bounding box is
        touched)."""
        m = np.zeros((geometry.height, geometry.width), dtype=bool)
        res = geometry.resolution
        for (x, y), r in zip(self.xy, self.radius, strict=True):  # per person, not per cell
            rows, cols = geometry.world_to_cell(np.array([[x - r, y - r], [x + r, y + r]]))
            r0, r1 = max(int(rows.min()), 0), min(int(rows.max()) + 1, geometry.height)
            c0, c1 = max(int(cols.min()), 0), min(int(cols.max()) + 1, geometry.width)
            if r0 >= r1 or c0 >= c1:
                continue
            rr, cc = np.mgrid[r0:r1, c0:c1]
            pts = geometry.cell_to_world(rr.ravel(), cc.ravel())
            inside = np.hypot(pts[:, 0] - x, pts[:, 1] - y) <= r + 1e-9 * res
            m[rr.ravel()[inside], cc.ravel()[inside]] = True
        return m
