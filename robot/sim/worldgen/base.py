"""What every world family produces: a ``GeneratedWorld`` (the map, obstacles only the simulator
has, the robot it was built for) with its start/goal sampler and walkers' paths.

The guarantees are checked on the simulated world (map plus unmapped obstacles), not assumed:

* *passable*: a cell is passable when its centre is at least the robot's circumscribed radius plus
  one cell from every occupied cell, so the footprint fits there at any heading;
* a start and a goal are drawn only where the clearance is ``pose_clearance`` more than that (room to
  turn) and only inside one 8-connected component of passable cells, so a route the footprint can
  drive always joins them;
* a walker's path is a loop of straight legs whose every point keeps the person's disc
  ``person_margin`` clear of the walls, away from the start and the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import label
from scipy.spatial import cKDTree

from maps.stock.generate import Canvas
from nav.types import GridGeometry, OccupancyGrid, Pose2D
from robot.profiles import load_profile
from robot.sim.people import PERSON_RADIUS
from robot.sim.world import World

EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


class WorldgenError(ValueError):
    """A family or its parameters are unknown, or a drawn world offers no valid start/goal pair."""


@dataclass(frozen=True)
class Zone:
    """A disc start or goal poses are drawn from (a forest's clear areas); None: anywhere."""

    x: float
    y: float
    radius: float


@dataclass
class GeneratedWorld:
    """One seeded member of a family. ``grid`` is the map the robot is given; ``unmapped`` are
    polygons the simulator adds that the map lacks (greenhouse mounds), met only by the sensors."""

    family: str
    seed: int
    grid: OccupancyGrid
    profile: str
    unmapped: tuple[np.ndarray, ...] = ()
    params: dict[str, float] = field(default_factory=dict)
    """The drawn parameters (sizes, counts, widths) for reports and tests."""
    items: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    """Centres of small things by kind (``leg``, ``cylinder``, ``post``), for tests and the docs."""
    lanes: tuple[np.ndarray, ...] = ()
    """(2, 2) segments people walk along (a greenhouse's aisles, headland to headland); the first
    walkers take one each when it keeps clear of the start and goal."""
    start_zone: Zone | None = None
    goal_zone: Zone | None = None
    pose_clearance: float = 0.2
    """Metres of room beyond the circumscribed radius around a start or goal (to turn in place)."""

    def __post_init__(self) -> None:
        world = self.world()  # the simulator's static obstacles: the map plus the unmapped polygons
        self.occupied = world.static_occupied
        self.clearance = world.clearance_map
        self.robot_radius = load_profile(self.profile).circumscribed_radius
        self.passable = self.clearance >= self.robot_radius + self.geometry.resolution
        labels, count = label(self.passable, structure=EIGHT_CONNECTED)
        if count == 0:
            raise WorldgenError(f"{self.family} seed {self.seed}: no place the robot fits")
        self.components = labels

    @property
    def geometry(self) -> GridGeometry:
        return self.grid.geometry

    @property
    def size(self) -> tuple[float, float]:
        g = self.geometry
        return g.width * g.resolution, g.height * g.resolution

    def world(self, start: Pose2D | None = None) -> World:
        """A fresh simulated world: a copy of the map plus the unmapped obstacles."""
        world = World(
            OccupancyGrid(self.geometry, self.grid.data.copy()),
            name=f"{self.family}-{self.seed}",
            start_pose=start or Pose2D(),
        )
        for poly in self.unmapped:
            world.add_polygon(poly, kind="mound")
        return world

    def _cells(self, zone: Zone | None, component: int | None) -> np.ndarray:
        """(N, 2) world points of cells a start or goal may take."""
        ok = self.clearance >= self.robot_radius + self.pose_clearance
        if component is not None:
            ok &= self.components == component
        rows, cols = np.nonzero(ok)
        pts = self.geometry.cell_to_world(rows, cols)
        if zone is not None:
            pts = pts[np.hypot(pts[:, 0] - zone.x, pts[:, 1] - zone.y) <= zone.radius]
        return pts

    def component_of(self, x: float, y: float) -> int:
        """The passable component label at a world point (0: not passable)."""
        rows, cols = self.geometry.world_to_cell(np.array([[x, y]]))
        if not self.geometry.in_bounds(rows, cols)[0]:
            return 0
        return int(self.components[rows[0], cols[0]])

    def sample_start_goal(
        self, rng: np.random.Generator, min_distance: float = 3.0, max_distance: float = 10.0
    ) -> tuple[Pose2D, Pose2D]:
        """A start and a goal in one passable component, each ``pose_clearance`` clear, their straight
        distance in [min_distance, max_distance] (best effort: the largest below it when the world is
        smaller); headings uniform."""
        starts = self._cells(self.start_zone, None)
        if starts.shape[0] == 0:
            raise WorldgenError(f"{self.family} seed {self.seed}: no start with clearance")
        for _ in range(64):
            s = starts[int(rng.integers(starts.shape[0]))]
            goals = self._cells(self.goal_zone, self.component_of(float(s[0]), float(s[1])))
            if goals.shape[0] == 0:
                continue
            d = np.hypot(goals[:, 0] - s[0], goals[:, 1] - s[1])
            ok = np.flatnonzero((d >= min_distance) & (d <= max_distance))
            if ok.size == 0:
                continue
            g = goals[int(ok[rng.integers(ok.size)])]
            heading = rng.uniform(-math.pi, math.pi, 2)
            return Pose2D(float(s[0]), float(s[1]), float(heading[0])), Pose2D(
                float(g[0]), float(g[1]), float(heading[1])
            )
        raise WorldgenError(
            f"{self.family} seed {self.seed}: no start/goal pair {min_distance}-{max_distance} m apart"
        )

    def segment_clear(self, a: np.ndarray, b: np.ndarray, need: float) -> bool:
        """Whether every point of segment a-b (sampled every half cell) has ``need`` m clearance."""
        res = self.geometry.resolution
        n = max(2, math.ceil(float(np.hypot(*(b - a))) / (0.5 * res)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        rows, cols = self.geometry.world_to_cell(pts)
        inside = self.geometry.in_bounds(rows, cols)
        if not inside.all():
            return False
        return bool((self.clearance[rows, cols] >= need).all())

    def walker_paths(
        self,
        rng: np.random.Generator,
        n: int,
        avoid: tuple[Pose2D, ...] = (),
        avoid_distance: float = 1.5,
        person_margin: float = 0.1,
        leg: tuple[float, float] = (2.0, 6.0),
    ) -> list[np.ndarray]:
        """``n`` walkers' loops, each two or three waypoints joined by straight legs of ``leg`` metres
        with the disc ``person_margin`` clear of walls all the way; no waypoint within
        ``avoid_distance`` of the ``avoid`` poses (the robot's start and goal). Fewer than ``n`` when
        the world has no room for more."""
        res = self.geometry.resolution
        need = PERSON_RADIUS + person_margin + res * math.sqrt(2.0)
        rows, cols = np.nonzero(self.clearance >= need)
        pts = self.geometry.cell_to_world(rows, cols)
        for p in avoid:
            pts = pts[np.hypot(pts[:, 0] - p.x, pts[:, 1] - p.y) >= avoid_distance]
        paths: list[np.ndarray] = []
        for k in rng.permutation(len(self.lanes)):
            lane = self.lanes[int(k)]
            if len(paths) == n:
                return paths
            far = all(min(np.hypot(*(lane - [p.x, p.y]).T)) >= avoid_distance for p in avoid)
            if far and self.segment_clear(lane[0], lane[1], need):
                paths.append(lane.copy())
        if pts.shape[0] == 0:
            return paths
        for _ in range(n * 40):
            if len(paths) == n:
                break
            way = [pts[int(rng.integers(pts.shape[0]))]]
            for _ in range(int(rng.integers(1, 3))):
                d = np.hypot(pts[:, 0] - way[-1][0], pts[:, 1] - way[-1][1])
                cand = np.flatnonzero((d >= leg[0]) & (d <= leg[1]))
                if cand.size == 0:
                    break
                picks = cand[rng.integers(cand.size, size=min(16, cand.size))]
                nxt = next((pts[k] for k in picks if self.segment_clear(way[-1], pts[k], need)), None)
                if nxt is None:
                    break
                way.append(nxt)
            if len(way) >= 2 and self.segment_clear(way[-1], way[0], need):
                paths.append(np.array(way))
        return paths


def disc_mask(geometry: GridGeometry, centres: np.ndarray, radius: float) -> np.ndarray:
    """Cells whose centre lies within ``radius`` of any of the (N, 2) ``centres`` (one k-d tree
    query over all cell centres)."""
    mask = np.zeros((geometry.height, geometry.width), dtype=bool)
    if len(centres) == 0:
        return mask
    rr, cc = np.mgrid[0 : geometry.height, 0 : geometry.width]
    pts = geometry.cell_to_world(rr.ravel(), cc.ravel())
    d, _ = cKDTree(np.asarray(centres, dtype=float)).query(pts, distance_upper_bound=radius + 1e-9)
    mask.ravel()[np.isfinite(d)] = True
    return mask


def place_chair(c: Canvas, x: float, y: float, legs: list[tuple[float, float]]) -> None:
    """``Canvas.chair`` at (x, y), its four legs' centres (0.2 m off the centre) added to ``legs``."""
    c.chair(x, y)
    legs.extend((x + dx, y + dy) for dx in (-0.2, 0.2) for dy in (-0.2, 0.2))
