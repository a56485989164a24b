"""Ghost free space (issue 16): after a full teleop loop of each stock world, how many cells of the
map SLAM built are free where the world has a wall or lies outside its outer walls, and how far the
saved map's extent is from the world's.

The built map is compared in the world frame through the robot's true pose when mapping started
(the SLAM map frame starts there). A built cell is *free* as map_saver writes it (value <= 25, Nav2's
``free_thresh`` 0.25). It is a *ghost* when its centre falls in an occupied world cell or outside the
world (off the world's grid or in a region its outer walls enclose from outside); ``deeper than
half a cell`` counts only those whose centre is more than 0.025 m from the building's free space,
which separates rays that crossed a wall from free cells next to a wall that the map places a
centimetre or two off (registration error of the SLAM map).
The extent error is the largest of the four sides' differences between the bounding box of the
saved map's observed cells (in the world frame) and the world's occupied cells' bounding box.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from bench.core import Benchmark, Figure
from bench.mapping import MappingDrive, build, teleop_loop
from nav.types import GridGeometry, OccupancyGrid, Pose2D

if TYPE_CHECKING:  # only for hints: the SLAM modules load their compiled kernels
    from nav.slam.system import SlamOptions

FREE_MAX = 25
"""Built-map values counted as free (map_saver's default ``free_thresh`` 0.25)."""

# Full loops through every room the lidar (6 m) needs to see the whole building; the routes keep
# clear of chair legs and desks (maps/stock/generate.py).
APARTMENT_FULL_LOOP = [
    (2.9, 4.3), (5.3, 4.3), (5.3, 2.5), (7.5, 2.5), (8.0, 4.2), (8.0, 6.2), (6.3, 6.2), (8.0, 5.8),
    (8.0, 4.2), (7.0, 2.5), (5.3, 2.5), (5.3, 4.3), (2.5, 4.3), (2.5, 6.0), (3.5, 6.6), (2.5, 5.8),
    (2.5, 4.3), (3.0, 3.6),
]  # fmt: skip
OFFICE_FULL_LOOP = [
    (2.5, 10.0), (2.5, 8.0), (3.8, 6.0), (3.8, 3.0), (3.8, 6.0), (2.5, 8.0), (2.5, 10.0), (1.7, 10.0),
    (1.7, 13.0), (3.8, 14.0), (3.8, 16.5), (3.8, 14.0), (1.7, 13.0), (1.7, 10.0), (14.0, 10.0),
    (27.5, 10.2), (27.5, 9.8), (14.0, 9.8), (2.5, 9.8),
]  # fmt: skip
GREENHOUSE_FULL_LOOP = [(1.2, 4.4), (18.8, 4.4), (18.8, 10.2), (1.2, 10.2), (1.2, 6.2)]
FULL_LOOPS: dict[str, tuple[Pose2D, Sequence[tuple[float, float]]]] = {
    "apartment": (Pose2D(3.0, 3.5, 0.0), APARTMENT_FULL_LOOP),
    "office": (Pose2D(2.0, 10.0, 0.0), OFFICE_FULL_LOOP),
    "greenhouse": (Pose2D(1.2, 6.0, 0.0), GREENHOUSE_FULL_LOOP),
}


@dataclass(frozen=True)
class GhostReport:
    """Free cells of a built map against the world's truth."""

    free_cells: int
    in_walls: int
    """Free built cells whose centre is in an occupied world cell."""
    outside: int
    """Free built cells whose centre is outside the world's outer walls."""
    deeper_than_half_cell: int
    """Of ``in_walls + outside``, those whose centre is more than half a cell (0.025 m) from the
    building's free space: beyond what a centimetre of map registration error explains."""
    extent_error_m: float
    """Largest side difference between the bounding boxes (world frame) of the built map's observed
    cells and of the world's occupied cells."""
    built_size_m: tuple[float, float]
    world_size_m: tuple[float, float]

    @property
    def ghosts(self) -> int:
        return self.in_walls + self.outside


def _world_free_and_exterior(occupied: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(free interior, exterior) masks: non-occupied cells connected to the grid border are
    outside the outer walls, the others are the building's free space."""
    labels, _ = ndimage.label(~occupied)
    border = np.unique(np.concatenate((labels[0], labels[-1], labels[:, 0], labels[:, -1])))
    exterior = np.isin(labels, border[border > 0])
    return ~occupied & ~exterior, exterior


def _depth(pts: np.ndarray, interior: np.ndarray, geometry: GridGeometry, reach: int = 3) -> np.ndarray:
    """Per world point: distance (m) to the nearest cell of the building's free space (its square,
    not its centre), looked for within ``reach`` cells; farther counts as ``inf``."""
    res = geometry.resolution
    o = geometry.origin
    local = (pts - (o.x, o.y)) / res  # axis-aligned world grids (every stock and map_server world)
    base = np.floor(local).astype(np.int64)
    off = np.arange(-reach, reach + 1)
    dr, dc = (a.ravel() for a in np.meshgrid(off, off, indexing="ij"))
    rr, cc = base[:, 1:2] + dr, base[:, 0:1] + dc
    ok = (rr >= 0) & (rr < interior.shape[0]) & (cc >= 0) & (cc < interior.shape[1])
    ok &= interior[np.clip(rr, 0, interior.shape[0] - 1), np.clip(cc, 0, interior.shape[1] - 1)]
    gx = np.maximum(np.maximum(cc - local[:, 0:1], local[:, 0:1] - (cc + 1)), 0.0)
    gy = np.maximum(np.maximum(rr - local[:, 1:2], local[:, 1:2] - (rr + 1)), 0.0)
    d = np.where(ok, np.hypot(gx, gy), np.inf)
    return d.min(axis=1) * res if d.size else np.zeros(len(pts))


def _observed_extent(built: OccupancyGrid, map_in_world: Pose2D) -> tuple[np.ndarray, np.ndarray]:
    """World-frame bounding box of the built map's observed cells (their corners). Not the grid's
    corners: the map frame starts at the robot's start pose, so a start heading oblique to the
    walls rotates the whole grid, and its corners' box is metres wider than what was mapped (a
    generated office started at -83 deg: 27.5 x 19.4 m of corners around a 24.35 x 13.6 m building
    mapped within a few centimetres)."""
    g = built.geometry
    rows, cols = np.nonzero(built.data >= 0)
    cells = np.column_stack((cols, rows)).astype(float)
    corners = (cells[:, None, :] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])[None]).reshape(-1, 2)
    corners = map_in_world.transform_points(g.origin.transform_points(corners * g.resolution))
    return corners.min(axis=0), corners.max(axis=0)


def ghost_report(
    built: OccupancyGrid, world_occupied: np.ndarray, world_geometry: GridGeometry, map_in_world: Pose2D
) -> GhostReport:
    """Compare ``built`` (in the SLAM map frame, whose pose in the world is ``map_in_world``)
    with the world's occupancy (``world_occupied`` over ``world_geometry``)."""
    g, wg = built.geometry, world_geometry
    interior, exterior = _world_free_and_exterior(world_occupied)
    rows, cols = np.nonzero((built.data >= 0) & (built.data <= FREE_MAX))
    pts = map_in_world.transform_points(g.cell_to_world(rows, cols))
    wr, wc = wg.world_to_cell(pts)
    inside = wg.in_bounds(wr, wc)
    r, c = np.clip(wr, 0, wg.height - 1), np.clip(wc, 0, wg.width - 1)
    in_walls = inside & world_occupied[r, c]
    outside = ~inside | (inside & exterior[r, c])
    ghost = in_walls | outside
    far = np.zeros_like(ghost)
    far[ghost] = _depth(pts[ghost], interior, wg) > 0.5 * wg.resolution
    b_lo, b_hi = _observed_extent(built, map_in_world)
    orow, ocol = np.nonzero(world_occupied)
    wo = wg.origin
    w_lo = np.array([wo.x + ocol.min() * wg.resolution, wo.y + orow.min() * wg.resolution])
    w_hi = np.array([wo.x + (ocol.max() + 1) * wg.resolution, wo.y + (orow.max() + 1) * wg.resolution])
    err = float(max(np.abs(b_lo - w_lo).max(), np.abs(b_hi - w_hi).max()))
    return GhostReport(
        free_cells=int(rows.size),
        in_walls=int(np.count_nonzero(in_walls)),
        outside=int(np.count_nonzero(outside)),
        deeper_than_half_cell=int(np.count_nonzero(ghost & far)),
        extent_error_m=err,
        built_size_m=(float(b_hi[0] - b_lo[0]), float(b_hi[1] - b_lo[1])),
        world_size_m=(float(w_hi[0] - w_lo[0]), float(w_hi[1] - w_lo[1])),
    )


def map_after_loop(
    world_name: str,
    start: Pose2D,
    loop: Sequence[tuple[float, float]],
    seed: int = 0,
    slam_options: SlamOptions | None = None,
) -> tuple[MappingDrive, OccupancyGrid]:
    """Map ``world_name`` along a teleop loop; the drive (closed) and the saved map."""
    drive = build(world_name, start, seed=seed, slam_options=slam_options)
    try:
        drive.mapping.start()
        teleop_loop(drive, loop, timeout=1800.0)
        drive.mapping.stop()
        return drive, drive.mapping.current_map()
    finally:
        drive.session.close()


def measure(
    world_name: str, seed: int = 0, slam_options: SlamOptions | None = None
) -> tuple[GhostReport, float]:
    """The ghost report after the world's full loop and the SLAM pose error (m) at its end: a map
    that is off by that much places free cells in walls however its rays were cast."""
    start, loop = FULL_LOOPS[world_name]
    drive, grid = map_after_loop(world_name, start, loop, seed, slam_options)
    truth = drive.driver.truth_pose.relative_to(drive.start_truth)
    report = ghost_report(grid, drive.world.static_occupied, drive.world.geometry, drive.start_truth)
    return report, drive.session.pose.distance_to(truth)


def _figures(world_name: str) -> list[Figure]:
    r, end_error = measure(world_name)
    w, h = r.built_size_m
    return [
        Figure(f"{world_name}: SLAM pose error at the end of the loop", end_error, "m"),
        Figure(f"{world_name}: free cells in walls or outside", float(r.ghosts), "cells", "0", r.ghosts == 0),
        Figure(f"{world_name}: of which in walls", float(r.in_walls), "cells"),
        Figure(f"{world_name}: of which outside the outer walls", float(r.outside), "cells"),
        Figure(
            f"{world_name}: of which deeper than half a cell",
            float(r.deeper_than_half_cell),
            "cells",
            "0",
            r.deeper_than_half_cell == 0,
        ),
        Figure(f"{world_name}: free cells in the map", float(r.free_cells), "cells"),
        Figure(
            f"{world_name}: map extent vs world extent",
            r.extent_error_m,
            "m",
            "<= 1 m",
            r.extent_error_m <= 1.0,
        ),
        Figure(f"{world_name}: saved map width (world {r.world_size_m[0]:.1f} m)", w, "m"),
        Figure(f"{world_name}: saved map height (world {r.world_size_m[1]:.1f} m)", h, "m"),
    ]


def _all() -> list[Figure]:
    out: list[Figure] = []
    for name in FULL_LOOPS:
        out.extend(_figures(name))
    return out


BENCHMARKS = [Benchmark(name="mapping.ghost", run=_all, group="slow")]
