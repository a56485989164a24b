"""The simulated world: a static occupancy grid (from a map_server PGM + YAML) plus optional polygon
obstacles rasterized into it, and the people walking in it (``robot.sim.people.Crowd``).

The ray caster and the clearance map are built from ``static_occupied`` only (once per world state);
people are cast against analytically and taken as the minimum, so walking people never invalidate the
static tables. ``occupied`` is the static mask OR the people's rasterized discs, for consumers that want
one grid."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from maps.mapio import load_map_yaml, read_map_metadata
from maps.stock import stock_world_path
from nav.raycast import RayCaster
from nav.types import GridGeometry, OccupancyGrid, Pose2D
from robot.sim.people import Crowd
from robot.sim.scenario import load_scenario, sidecar_path


class WorldError(ValueError):
    """A world could not be built (bad map, bad polygon, unknown stock name)."""


def polygon_mask(geometry: GridGeometry, polygon: np.ndarray) -> np.ndarray:
    """Cells whose centre lies inside ``polygon`` ((N, 2) world points), even-odd rule, vectorized
    over the cells of the polygon's bounding box and its edges."""
    poly = np.asarray(polygon, dtype=float).reshape(-1, 2)
    if poly.shape[0] < 3:
        raise WorldError("a polygon obstacle needs at least 3 points")
    mask = np.zeros((geometry.height, geometry.width), dtype=bool)
    rows, cols = geometry.world_to_cell(poly)
    r0, r1 = max(int(rows.min()) - 1, 0), min(int(rows.max()) + 2, geometry.height)
    c0, c1 = max(int(cols.min()) - 1, 0), min(int(cols.max()) + 2, geometry.width)
    if r0 >= r1 or c0 >= c1:
        return mask
    rr, cc = np.mgrid[r0:r1, c0:c1]
    pts = geometry.cell_to_world(rr.ravel(), cc.ravel())
    inside = points_in_polygon(pts, poly)
    mask[rr.ravel()[inside], cc.ravel()[inside]] = True
    return mask


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for (M, 2) points against an (N, 2) polygon."""
    px, py = points[:, 0:1], points[:, 1:2]
    x0, y0 = polygon[:, 0], polygon[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    return np.count_nonzero(straddle & (px < x_cross), axis=1) % 2 == 1


@dataclass
class World:
    """A grid world with people. ``occupied`` (static | people) is what the lidar sees and the body
    collides with; ``static_occupied`` backs the cached ``raycaster`` and ``clearance_map``."""

    grid: OccupancyGrid
    name: str = "world"
    start_pose: Pose2D = field(default_factory=Pose2D)
    occupied_threshold: int = 65
    unknown_is_occupied: bool = False
    static_occupied: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        d = self.grid.data
        occ = d >= self.occupied_threshold
        if self.unknown_is_occupied:
            occ |= d < 0
        self.static_occupied = occ
        self._caster: RayCaster | None = None
        self._clearance: np.ndarray | None = None
        self.people = Crowd(self)
        self.features: list[tuple[str, np.ndarray]] = []  # (kind, polygon) added by a scenario
        self._occ_cache: tuple[int, np.ndarray] | None = None
        self.version = 0  # bumped when the static world changes (add_polygon)

    @property
    def raycaster(self) -> RayCaster:
        """A ``RayCaster`` over ``static_occupied``, rebuilt only when the static world changes
        (people are cast separately: ``people.ranges``)."""
        if self._caster is None:
            self._caster = RayCaster(self.static_occupied, self.geometry, clearance=self.clearance_map)
        return self._caster

    @property
    def clearance_map(self) -> np.ndarray:
        """(H, W) metres from each cell centre to the nearest statically occupied cell centre
        (Euclidean distance transform, computed once per static world state; people excluded)."""
        if self._clearance is None:
            occ = self.static_occupied
            if occ.any():
                self._clearance = distance_transform_edt(~occ) * self.geometry.resolution
            else:
                self._clearance = np.full(occ.shape, np.inf)
        return self._clearance

    def clearance_at(self, x: float, y: float) -> float:
        """A lower bound on the distance (m) from world point (x, y) to any static obstacle; 0 if the
        point is off the grid (unknown surroundings). Scalar math: used to skip exact checks in
        open space every physics substep."""
        g = self.geometry
        o = g.origin
        dx, dy = x - o.x, y - o.y
        if o.theta != 0.0:
            c, s = math.cos(o.theta), math.sin(o.theta)
            dx, dy = c * dx + s * dy, -s * dx + c * dy
        col, row = math.floor(dx / g.resolution), math.floor(dy / g.resolution)
        if not (0 <= row < g.height and 0 <= col < g.width):
            return 0.0
        # the point may sit anywhere in its cell, the obstacle anywhere in its cell
        return max(0.0, float(self.clearance_map[row, col]) - g.resolution * math.sqrt(2.0))

    def any_occupied(self, xy: np.ndarray) -> bool:
        """True if any of the (N, 2) world points lies in an occupied cell or a person (off-grid is
        free). Uses the ray caster's padded table so the hot collision check is a handful of numpy ops."""
        return self.raycaster.any_occupied(xy) or bool(self.people.contains(xy).any())

    @property
    def geometry(self) -> GridGeometry:
        return self.grid.geometry

    @property
    def occupied(self) -> np.ndarray:
        """(H, W) bool obstacle mask: static map + rasterized polygons + people's discs (the
        raster is cached until someone moves)."""
        if not len(self.people):
            return self.static_occupied
        v = self.people.version
        if self._occ_cache is None or self._occ_cache[0] != v:
            self._occ_cache = (v, self.static_occupied | self.people.mask(self.geometry))
        return self._occ_cache[1]

    def add_polygon(self, polygon: np.ndarray | list[tuple[float, float]], kind: str = "obstacle") -> None:
        """Rasterize a polygon obstacle ((N, 2) world points) into the static world. ``kind`` labels
        it for the 3D view (``obstacle``, ``mound``, ``puddle``)."""
        poly = np.asarray(polygon, dtype=float)
        self.static_occupied = self.static_occupied | polygon_mask(self.geometry, poly)
        self.features.append((kind, poly.reshape(-1, 2)))
        self._caster = None
        self._clearance = None
        self._occ_cache = None
        self.version += 1

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """True for (N, 2) world points in free cells; points off the grid count as free."""
        rows, cols = self.geometry.world_to_cell(np.asarray(xy, dtype=float))
        inside = self.geometry.in_bounds(rows, cols)
        out = np.ones(rows.shape, dtype=bool)
        out[inside] = ~self.occupied[rows[inside], cols[inside]]
        return out

    @classmethod
    def from_yaml(cls, path: str | Path, scenario: bool | str | Path = False, **kwargs: object) -> World:
        """Load a map_server YAML; a ``navdeck_start: [x, y, theta]`` key sets the start pose.
        ``scenario``: True loads the sidecar ``<stem>.scenario.toml`` next to the YAML (people,
        mounds, puddles; see ``robot.sim.scenario``), a path loads that file. Off by default so the
        simulated world matches its map unless a scenario is asked for."""
        path = Path(path)
        if scenario:
            spec = load_scenario(sidecar_path(path) if scenario is True else Path(scenario))  # type: ignore[arg-type]
            world = cls.from_yaml(path, **kwargs)
            spec.apply(world)
            return world
        grid = load_map_yaml(path)
        start = read_map_metadata(path).get("navdeck_start")
        start_pose = Pose2D.from_array(start) if isinstance(start, list) and len(start) == 3 else Pose2D()
        kwargs.setdefault("start_pose", start_pose)
        kwargs.setdefault("name", path.stem)
        return cls(grid, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def stock(cls, name: str, scenario: bool = False, **kwargs: object) -> World:
        """One of the stock worlds in ``maps/stock`` (apartment, office, greenhouse); ``scenario``
        adds its people and obstacles from ``maps/stock/<name>.scenario.toml``."""
        return cls.from_yaml(stock_world_path(name), scenario=scenario, **kwargs)

    @classmethod
    def box(cls, width: float, height: float, resolution: float = 0.05, wall: float = 0.1) -> World:
        """An empty rectangular room with walls ``wall`` thick, origin at (0, 0); for tests."""
        w, h = round(width / resolution), round(height / resolution)
        t = max(1, round(wall / resolution))
        data = np.zeros((h, w), dtype=np.int8)
        data[:t, :] = data[-t:, :] = data[:, :t] = data[:, -t:] = 100
        return cls(
            OccupancyGrid(GridGeometry(resolution, w, h), data),
            name="box",
            start_pose=Pose2D(width / 2, height / 2, 0.0),
        )
