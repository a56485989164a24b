"""Layered costmap, as Nav2's ``Costmap2DROS`` + ``LayeredCostmap``: static, obstacle and inflation
layers combined into one master grid of uint8 costs.

Combination follows Nav2: the static layer overwrites the master, the obstacle layer merges with
``updateWithMax`` (its NO_INFORMATION cells are skipped; a known cell replaces an unknown master
cell), then the inflation layer spreads costs around lethal cells. Two flavours:

- global: the size and geometry of the map, static + obstacle + inflation;
- local: a rolling window (Nav2 default 3 x 3 m) that follows the robot, obstacle + inflation and
  optionally the static map sampled into the window.

Updates are cheap: ``update`` only records the changed bounds; ``costmap()`` recomputes the master
lazily and, like Nav2's ``updateBounds``, only over the changed region grown by two inflation radii
(cells within one radius may change, and they depend on sources within another radius).

Thread use: one owner (the control loop) calls ``update``/``clear``; ``costmap()`` returns an
independent snapshot that a planner worker may keep.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from nav.costmap.footprint import cells_in_polygon, circle_footprint, footprint_cost, footprint_radii
from nav.costmap.inflation import InflationOptions, cell_inflation_radius, inflate
from nav.costmap.obstacle_layer import Bounds, ObstacleLayer, ObstacleLayerOptions, _union
from nav.costmap.static_layer import StaticLayerOptions, sample_costs, static_costs
from nav.types import (
    FREE_SPACE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    Costmap,
    GridGeometry,
    LaserScan,
    OccupancyGrid,
    Pose2D,
)


class CostmapError(ValueError):
    """Invalid costmap configuration (e.g. a rolling window without a size)."""


@dataclass(frozen=True)
class CostmapOptions:
    """Nav2 ``Costmap2DROS`` parameters plus the options of each layer."""

    resolution: float = 0.05
    """Cell size (m) of a rolling window; a global costmap takes the map's. Nav2 default 0.05."""
    width: float = 3.0
    """Rolling-window width (m). Nav2 local costmap default 3."""
    height: float = 3.0
    """Rolling-window height (m). Nav2 local costmap default 3."""
    rolling_window: bool = False
    """Whether the grid follows the robot (local costmap). Nav2 default false."""
    track_unknown_space: bool = True
    """Keep unknown cells as NO_INFORMATION (255) instead of free. Nav2's global costmap sets true,
    its local costmap leaves the default false."""
    observation_max_age: float = math.inf
    """With ``track_unknown_space``: a free obstacle-layer cell not observed again for this long
    (s, on the clock of ``update``'s ``stamp``) returns to unknown, so a controller that treats
    unknown as lethal only drives where the sensors looked recently (navdeck, issue 18; inf: never)."""
    robot_radius: float = 0.1
    """Radius (m) of a circular robot, used when ``footprint`` is empty. Nav2 default 0.1."""
    footprint: tuple[tuple[float, float], ...] = ()
    """Footprint polygon in base_link (m); empty means circular with ``robot_radius``."""
    use_static_layer: bool = True
    use_obstacle_layer: bool = True
    use_inflation_layer: bool = True
    static_layer: StaticLayerOptions = field(default_factory=StaticLayerOptions)
    obstacle_layer: ObstacleLayerOptions = field(default_factory=ObstacleLayerOptions)
    inflation_layer: InflationOptions = field(default_factory=InflationOptions)

    def footprint_polygon(self) -> np.ndarray | None:
        """The footprint as (K, 2), or None for a circular robot."""
        return np.asarray(self.footprint, dtype=float) if self.footprint else None

    def outline(self) -> np.ndarray:
        """The footprint polygon, or a 16-gon of ``robot_radius`` for a circular robot (K, 2)."""
        poly = self.footprint_polygon()
        return circle_footprint(self.robot_radius) if poly is None else poly

    @property
    def inscribed_radius(self) -> float:
        poly = self.footprint_polygon()
        return self.robot_radius if poly is None else footprint_radii(poly)[0]

    @property
    def circumscribed_radius(self) -> float:
        poly = self.footprint_polygon()
        return self.robot_radius if poly is None else footprint_radii(poly)[1]


def local_costmap_options(**overrides: object) -> CostmapOptions:
    """Nav2's local costmap defaults: 3 x 3 m rolling window, no static layer, unknown as free
    (``track_unknown_space=True`` in ``overrides`` keeps unseen cells unknown)."""
    base: dict[str, object] = {
        "rolling_window": True,
        "use_static_layer": False,
        "track_unknown_space": False,
    }
    base.update(overrides)
    return CostmapOptions(**base)  # type: ignore[arg-type]


@njit(cache=True, nogil=True)
def _combine(base: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Nav2's ``updateWithMax`` of the obstacle layer onto a copy of ``base``: a known obstacle
    cost replaces an unknown or lower master cost. One pass instead of five masked numpy ops."""
    out = np.empty(base.shape, dtype=np.uint8)
    for i in range(base.shape[0]):
        for j in range(base.shape[1]):
            b, o = base[i, j], obs[i, j]
            out[i, j] = o if o != NO_INFORMATION and (b == NO_INFORMATION or b < o) else b
    return out


class Costmap2D:
    """A layered costmap over a fixed or rolling grid. See the module docstring."""

    def __init__(
        self,
        geometry: GridGeometry,
        options: CostmapOptions | None = None,
        static_map: OccupancyGrid | None = None,
    ) -> None:
        self.options = o = options or CostmapOptions()
        if geometry.width <= 0 or geometry.height <= 0 or geometry.resolution <= 0:
            raise CostmapError(f"invalid costmap geometry {geometry}")
        self.geometry = geometry
        self._static_full: np.ndarray | None = None
        self._static_geometry: GridGeometry | None = None
        # keepout filter mask (bool, its own geometry: the map's), applied under inflation
        self._keepout: np.ndarray | None = None
        self._keepout_geometry: GridGeometry | None = None
        if o.use_static_layer and static_map is not None:
            self._static_full = static_costs(
                static_map, o.static_layer, track_unknown_space=o.track_unknown_space
            )
            self._static_geometry = static_map.geometry
        self._obstacles = (
            ObstacleLayer(
                geometry,
                o.obstacle_layer,
                track_unknown_space=o.track_unknown_space,
                keep_stamps=o.track_unknown_space and math.isfinite(o.observation_max_age),
            )
            if o.use_obstacle_layer
            else None
        )
        self._inflation_cells = cell_inflation_radius(geometry.resolution, o.inflation_layer)
        self._inscribed = o.inscribed_radius  # a polygon computation: once, not every refresh
        self._base = self._static_window()
        self._master = np.empty_like(self._base)
        self._dirty: Bounds | None = (0, geometry.height, 0, geometry.width)

    # ----------------------------------------------------------------- construction
    @classmethod
    def from_map(cls, static_map: OccupancyGrid, options: CostmapOptions | None = None) -> Costmap2D:
        """A global costmap with the map's geometry."""
        o = options or CostmapOptions()
        if o.rolling_window:
            raise CostmapError("a global costmap built from a map cannot be a rolling window")
        return cls(static_map.geometry, o, static_map)

    @classmethod
    def rolling(
        cls,
        options: CostmapOptions | None = None,
        center: Pose2D | None = None,
        static_map: OccupancyGrid | None = None,
    ) -> Costmap2D:
        """A local rolling-window costmap centred on ``center`` (default the origin)."""
        o = options or local_costmap_options()
        if not o.rolling_window:
            raise CostmapError("rolling() needs options with rolling_window=True")
        w = round(o.width / o.resolution)
        h = round(o.height / o.resolution)
        if w <= 0 or h <= 0:
            raise CostmapError(f"rolling window {o.width} x {o.height} m is empty")
        geo = GridGeometry(o.resolution, w, h, cls._window_origin(o, w, h, center or Pose2D()))
        return cls(geo, o, static_map)

    @staticmethod
    def _window_origin(o: CostmapOptions, w: int, h: int, center: Pose2D) -> Pose2D:
        # Snap to whole cells (of the world grid) so shifting keeps cells aligned, as Nav2's updateMap.
        res = o.resolution
        ox = math.floor((center.x - 0.5 * w * res) / res) * res
        oy = math.floor((center.y - 0.5 * h * res) / res) * res
        return Pose2D(ox, oy, 0.0)

    def _static_window(self) -> np.ndarray:
        base = self._static_only()
        keep = self._keepout_window()
        return base if keep is None else np.where(keep, np.uint8(LETHAL_OBSTACLE), base)

    def _static_only(self) -> np.ndarray:
        geo = self.geometry
        if self._static_full is None or self._static_geometry is None:
            fill = NO_INFORMATION if self.options.track_unknown_space else FREE_SPACE
            return np.full((geo.height, geo.width), fill, dtype=np.uint8)
        if self._static_geometry == geo:
            return self._static_full
        return sample_costs(self._static_full, self._static_geometry, geo)

    def _keepout_window(self) -> np.ndarray | None:
        if self._keepout is None or self._keepout_geometry is None:
            return None
        if self._keepout_geometry == self.geometry:
            return self._keepout
        return sample_costs(self._keepout.view(np.uint8), self._keepout_geometry, self.geometry) == 1

    def update_static(self, grid: OccupancyGrid, bounds: tuple[int, int, int, int] | None = None) -> None:
        """A new version of the static map with the same geometry (an edit): only the cells in
        ``bounds`` (r0, r1, c0, c1; default all) are re-interpreted, and only around them re-inflated."""
        if self._static_full is None or self._static_geometry != grid.geometry:
            raise CostmapError("update_static needs a static layer built from a map of the same geometry")
        g = grid.geometry
        r0, r1, c0, c1 = bounds or (0, g.height, 0, g.width)
        block = OccupancyGrid(GridGeometry(g.resolution, c1 - c0, r1 - r0, g.origin), grid.data[r0:r1, c0:c1])
        self._static_full = self._static_full.copy()  # snapshots taken before keep the old map
        self._static_full[r0:r1, c0:c1] = static_costs(
            block, self.options.static_layer, track_unknown_space=self.options.track_unknown_space
        )
        self._base = self._static_window()
        if self._static_geometry == self.geometry:
            self._dirty = _union(self._dirty, (r0, r1, c0, c1))
        else:  # a rolling window: its sampled copy was rebuilt, refresh it all
            self._dirty = (0, self.geometry.height, 0, self.geometry.width)

    def set_keepout(self, mask: np.ndarray | None, geometry: GridGeometry | None = None) -> None:
        """Keepout filter (Nav2 ``KeepoutFilter``): cells where the (H, W) bool ``mask`` (over
        ``geometry``, default this costmap's) is true are lethal; None removes it. Unlike Nav2, which
        writes the mask after inflation (only the robot's centre is kept out), it is applied under
        inflation like a wall, so the whole footprint stays out. Only the changed region is
        re-inflated."""
        geo = geometry or self.geometry
        if mask is not None and mask.shape != (geo.height, geo.width):
            raise CostmapError(
                f"keepout mask {mask.shape} does not match its geometry {geo.height}x{geo.width}"
            )
        old = self._keepout_window()
        self._keepout = None if mask is None else np.ascontiguousarray(mask, dtype=bool)
        self._keepout_geometry = None if mask is None else geo
        new = self._keepout_window()
        self._base = self._static_window()
        if old is None and new is None:
            return
        changed = new if old is None else old if new is None else old ^ new
        rows = np.flatnonzero(changed.any(axis=1))
        if rows.size == 0:
            return
        cols = np.flatnonzero(changed[rows[0] : rows[-1] + 1].any(axis=0))
        self._dirty = _union(self._dirty, (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1))

    # ----------------------------------------------------------------- updates
    def update(
        self,
        robot_pose: Pose2D,
        scan_points_world: np.ndarray | None = None,
        sensor_origin: np.ndarray | tuple[float, float] | None = None,
        *,
        no_return_points_world: np.ndarray | None = None,
        stamp: float | None = None,
    ) -> None:
        """One cycle: move the window (rolling), clear and mark the scan, then clear the footprint.

        ``scan_points_world``: (N, 2) lidar returns in the costmap's frame; ``sensor_origin``: the
        laser position (default the robot position); ``no_return_points_world``: optional far ends
        of beams without a return, used only for clearing; ``stamp``: the scan's time (s), which
        ages observations when ``observation_max_age`` is finite.
        """
        o = self.options
        if o.rolling_window:
            self._move_window(robot_pose)
        if self._obstacles is None:
            return
        if stamp is not None:
            self._obstacles.now = stamp
            if math.isfinite(o.observation_max_age):
                self._dirty = _union(self._dirty, self._obstacles.expire(o.observation_max_age))
        if scan_points_world is not None or no_return_points_world is not None:
            origin = (
                np.array([robot_pose.x, robot_pose.y]) if sensor_origin is None else np.asarray(sensor_origin)
            )
            pts = np.zeros((0, 2)) if scan_points_world is None else scan_points_world
            self._dirty = _union(self._dirty, self._obstacles.update(pts, origin, no_return_points_world))
        if o.obstacle_layer.footprint_clearing_enabled:
            # After marking, as Nav2's ObstacleLayer::updateCosts: returns off the robot's own body
            # (or noise inside it) never become obstacles.
            rows, cols = cells_in_polygon(self.geometry, robot_pose.transform_points(o.outline()))
            self._dirty = _union(self._dirty, self._obstacles.clear_cells(rows, cols))

    def update_from_scan(
        self,
        robot_pose: Pose2D,
        scan: LaserScan,
        laser_offset: Pose2D | None = None,
        stamp: float | None = None,
    ) -> None:
        """``update`` from a ``LaserScan``: valid returns mark and clear; beams with no return
        (``+inf``, REP-117) clear up to ``raytrace_max_range`` without marking, like Nav2 with
        ``inf_is_valid``; NaN and out-of-range readings are dropped. ``laser_offset`` is the laser's
        pose in base_link (default: at the robot's origin)."""
        laser = robot_pose.compose(laser_offset) if laser_offset is not None else robot_pose
        r = scan.ranges
        a = scan.angles
        valid = scan.valid_mask()
        no_return = np.isposinf(r)
        reach = self.options.obstacle_layer.raytrace_max_range
        hits = np.column_stack((r[valid] * np.cos(a[valid]), r[valid] * np.sin(a[valid])))
        far = np.column_stack((reach * np.cos(a[no_return]), reach * np.sin(a[no_return])))
        self.update(
            robot_pose,
            laser.transform_points(hits),
            np.array([laser.x, laser.y]),
            no_return_points_world=laser.transform_points(far) if far.shape[0] else None,
            stamp=stamp,
        )

    def _move_window(self, robot_pose: Pose2D) -> None:
        geo = self.geometry
        origin = self._window_origin(self.options, geo.width, geo.height, robot_pose)
        if abs(origin.x - geo.origin.x) < 1e-9 and abs(origin.y - geo.origin.y) < 1e-9:
            return
        new_geo = GridGeometry(geo.resolution, geo.width, geo.height, origin)
        if self._obstacles is not None:
            self._obstacles.set_geometry(new_geo)
        self.geometry = new_geo
        self._base = self._static_window()
        self._dirty = (0, geo.height, 0, geo.width)

    def keep_observations(self, old: Costmap2D) -> None:
        """Take over ``old``'s obstacle layer (its marks, cleared cells and their stamps), moved to
        this window: a costmap rebuilt over a grown map keeps what the sensors saw, as Nav2's obstacle
        layer does when the static layer gets a new map. Without it, an obstacle the map does not
        hold (a chair leg seen by the lidar, not yet occupied in SLAM's map) is gone until a scan
        sees it again, and one hidden from the next scans (occluded, beyond the marking range) is
        gone until it is, while the controller drives on a costmap without it."""
        mine, theirs = self._obstacles, old._obstacles
        if mine is None or theirs is None:
            return
        if (
            abs(theirs.geometry.resolution - self.geometry.resolution) > 1e-12
            or theirs.costs.shape != mine.costs.shape
            or theirs.default_value != mine.default_value
            or bool(theirs.seen.shape[0]) != bool(mine.seen.shape[0])
        ):
            raise CostmapError("keep_observations needs a costmap of the same resolution, size and layers")
        taken = copy.deepcopy(theirs)  # the old costmap's snapshots stay as they were
        taken.set_geometry(self.geometry)
        self._obstacles = taken
        self._dirty = (0, self.geometry.height, 0, self.geometry.width)

    def clear(self) -> None:
        """Reset the obstacle layer (Nav2 ``clearEntireCostmap`` / the ClearCostmap behaviour)."""
        if self._obstacles is not None:
            self._obstacles.reset()
        self._dirty = (0, self.geometry.height, 0, self.geometry.width)

    # ----------------------------------------------------------------- outputs
    def _refresh(self) -> None:
        if self._dirty is None:
            return
        geo = self.geometry
        r = self._inflation_cells if self.options.use_inflation_layer else 0
        r0, r1, c0, c1 = self._dirty
        # Cells within r of a change may change; they depend on sources within 2r of it.
        ir0, ir1, ic0, ic1 = max(r0 - r, 0), min(r1 + r, geo.height), max(c0 - r, 0), min(c1 + r, geo.width)
        er0, er1, ec0, ec1 = (
            max(r0 - 2 * r, 0),
            min(r1 + 2 * r, geo.height),
            max(c0 - 2 * r, 0),
            min(c1 + 2 * r, geo.width),
        )
        base = self._base[er0:er1, ec0:ec1]
        if self._obstacles is not None:
            combined = _combine(base, self._obstacles.costs[er0:er1, ec0:ec1])
        else:
            combined = base.copy()
        if self.options.use_inflation_layer:
            combined = inflate(combined, geo.resolution, self._inscribed, self.options.inflation_layer)
        self._master[ir0:ir1, ic0:ic1] = combined[ir0 - er0 : ir1 - er0, ic0 - ec0 : ic1 - ec0]
        self._dirty = None

    def costmap(self) -> Costmap:
        """An independent snapshot of the master grid as ``nav.types.Costmap``."""
        self._refresh()
        return Costmap(self.geometry, self._master.copy())

    def map_only(self) -> Costmap:
        """The master grid without the sensors' marks: the map (and keepout zones) inflated. What
        the costmap would be with every sensed obstacle gone (a person who walks away)."""
        base = self._base
        if self.options.use_inflation_layer:
            base = inflate(base, self.geometry.resolution, self._inscribed, self.options.inflation_layer)
        return Costmap(self.geometry, base.copy())

    def cost_at(self, xy: np.ndarray) -> np.ndarray:
        """Master costs at (N, 2) world points (255 off the grid)."""
        self._refresh()
        return Costmap(self.geometry, self._master).cost_at(xy)

    def footprint_cost(self, poses: np.ndarray, footprint: np.ndarray | None = None) -> np.ndarray:
        """Highest master cost of the footprint at each of (M, 3) poses as (M,) uint8; ``footprint``
        defaults to the configured one (centre cell for a circular robot). See
        ``nav.costmap.footprint.footprint_cost``."""
        self._refresh()
        fp = self.options.footprint_polygon() if footprint is None else footprint
        return footprint_cost(Costmap(self.geometry, self._master), poses, fp)

    def in_mapped_obstacle(self, pose: Pose2D) -> bool:
        """Does the footprint at ``pose`` cover a lethal cell of the static map alone (no sensor
        marks, no inflation)? A robot cannot stand there: its pose estimate is wrong."""
        if self._static_full is None or self._static_geometry is None:
            return False
        static = Costmap(self._static_geometry, self._static_full)
        cost = footprint_cost(static, np.array([[pose.x, pose.y, pose.theta]]), self.options.outline())
        return bool(cost[0] == LETHAL_OBSTACLE)  # 255 (unknown, off the map) is not a wall

    @property
    def obstacle_costs(self) -> np.ndarray | None:
        """The obstacle layer's own grid (read-only view), for display and tests."""
        if self._obstacles is None:
            return None
        v = self._obstacles.costs.view()
        v.flags.writeable = False
        return v


LayeredCostmap = Costmap2D
"""Nav2's name for the layer container; one class here."""
