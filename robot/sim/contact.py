"""Exact penetration of the simulated footprint into what it touches, one depth per contact.

The simulator's contact rule (``robot/sim/physics.py``) compares these depths before and after a
motion. They are exact for a convex footprint (a non-convex one is taken by its convex hull): for
each occupied map cell, the minimum translation that separates the footprint polygon from the
cell's square (the separating-axis theorem over the polygon's edge normals and the grid's two
axes); for each person, how far their disc reaches into the polygon. A depth sampled at points
of the footprint (each point's distance to the nearest free cell) is not: a cell's corner poking
in between two edge samples is invisible to it, and a sample inside a cell's corner reads
min(dx, dy), which grows while the body slides along the cell's face, so a base touching a chair
leg's cell with its edge could neither turn away nor slide along it (issue 16, "never trapped").
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from nav.types import Pose2D
from robot.sim.world import World

_GRID_AXES = np.array([[1.0, 0.0], [0.0, 1.0]])


def outward_normals(polygon: np.ndarray) -> np.ndarray:
    """Unit outward normals (E, 2) of a simple polygon's edges, either winding."""
    p = np.asarray(polygon, dtype=float)
    e = np.roll(p, -1, axis=0) - p
    area2 = float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
    n = np.column_stack((e[:, 1], -e[:, 0])) if area2 > 0 else np.column_stack((-e[:, 1], e[:, 0]))
    return n / np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-18)[:, None]


def convex_outline(polygon: np.ndarray) -> np.ndarray:
    """The polygon's convex hull (V, 2), counter-clockwise: the shape the contact depths use (a
    non-convex footprint is taken by its hull, which can only overstate a contact)."""
    p = np.asarray(polygon, dtype=float)
    return p[ConvexHull(p).vertices]


def cell_depths(polygon: np.ndarray, cells: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    """Penetration (C,) of a convex ``polygon`` (V, 2) into unit squares [c, c+1) x [r, r+1) given
    as (C, 2) (column, row) corners, all in cell units: the smallest overlap of their projections
    over the polygon's edge normals (``outward_normals``, computed when not given) and the x and y
    axes (0 where some axis separates them)."""
    if len(cells) == 0:
        return np.zeros(0)
    n = outward_normals(polygon) if normals is None else normals
    axes = np.vstack((n, _GRID_AXES))  # (A, 2)
    proj = polygon @ axes.T  # (V, A)
    pmin, pmax = proj.min(axis=0), proj.max(axis=0)
    centre = (cells + 0.5) @ axes.T  # (C, A)
    half = 0.5 * (np.abs(axes[:, 0]) + np.abs(axes[:, 1]))
    overlap = np.minimum(pmax - (centre - half), (centre + half) - pmin)
    return np.maximum(overlap.min(axis=1), 0.0)


def disc_depths(polygon: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Penetration (P,) of discs into a convex ``polygon`` (V, 2): radius minus the signed distance
    from the centre to the polygon (negative inside), at least 0."""
    if len(centres) == 0:
        return np.zeros(0)
    a = np.asarray(polygon, dtype=float)
    e = np.roll(a, -1, axis=0) - a
    d = centres[:, None, :] - a[None]  # (P, E, 2)
    signed = (d * outward_normals(a)[None]).sum(axis=2).max(axis=1)  # > 0 outside (convex)
    t = np.clip((d * e[None]).sum(axis=2) / np.maximum((e * e).sum(axis=1), 1e-18)[None], 0.0, 1.0)
    gap = np.hypot(*(d - t[..., None] * e[None]).transpose(2, 0, 1)).min(axis=1)
    dist = np.where(signed > 0, gap, signed)
    return np.maximum(radii - dist, 0.0)


class ContactProbe:
    """Depths of one footprint at candidate poses, against the static cells near a pose and the
    people, in a fixed order so that two poses' depths compare contact by contact."""

    def __init__(self, world: World, polygon: np.ndarray, centre: Pose2D, reach: float) -> None:
        g = world.geometry
        self.world = world
        self.polygon = np.asarray(polygon, dtype=float)  # convex (``convex_outline``)
        self._to_grid = g.origin.inverse()
        self._res = g.resolution
        self._grid_yaw = g.origin.theta
        self._normals = outward_normals(self.polygon)
        c = self._to_grid.transform_points(np.array([[centre.x, centre.y]]))[0] / g.resolution
        k = reach / g.resolution + 1.0
        r0, c0 = max(int(np.floor(c[1] - k)), 0), max(int(np.floor(c[0] - k)), 0)
        r1, c1 = min(int(np.ceil(c[1] + k)) + 1, g.height), min(int(np.ceil(c[0] + k)) + 1, g.width)
        if r1 > r0 and c1 > c0:
            rows, cols = np.nonzero(world.static_occupied[r0:r1, c0:c1])
            self.cells = np.column_stack((cols + c0, rows + r0)).astype(float)
        else:
            self.cells = np.zeros((0, 2))

    def depths(self, pose: Pose2D) -> tuple[np.ndarray, np.ndarray]:
        """(static cells' depths, people's depths) in metres of the footprint at ``pose``."""
        world_poly = pose.transform_points(self.polygon)
        static = np.zeros(0)
        if len(self.cells):
            grid_poly = self._to_grid.transform_points(world_poly) / self._res
            c, s = np.cos(pose.theta - self._grid_yaw), np.sin(pose.theta - self._grid_yaw)
            normals = self._normals @ np.array([[c, s], [-s, c]])  # rotated into the grid frame
            static = cell_depths(grid_poly, self.cells, normals) * self._res
        crowd = self.world.people
        people = disc_depths(world_poly, crowd.xy, crowd.radius) if len(crowd) else np.zeros(0)
        return static, people
