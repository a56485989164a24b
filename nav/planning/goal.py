"""Goal helpers: find a traversable pose near a requested one (what the API suggests when a clicked
goal lies in an obstacle or its inflation)."""

from __future__ import annotations

import numpy as np

from nav.planning.base import _nearest_in_radius, traversable_mask
from nav.types import Costmap, Pose2D


def nearest_free_pose(
    costmap: Costmap, pose: Pose2D, max_radius: float, *, allow_unknown: bool = False
) -> Pose2D | None:
    """The centre of the traversable cell (cost < 253, unknown only if ``allow_unknown``) nearest to
    ``pose`` within ``max_radius`` metres, keeping ``pose.theta``; ``pose`` itself if its cell is
    already traversable; ``None`` if there is none (or the pose is off the map by more than
    ``max_radius``)."""
    geo = costmap.geometry
    rows, cols = geo.world_to_cell(np.array([pose.x, pose.y]))
    r, c = int(rows[0]), int(cols[0])
    mask = traversable_mask(costmap.costs, allow_unknown)
    if geo.in_bounds(rows, cols)[0] and mask[r, c]:
        return pose
    found = _nearest_in_radius(mask, (r, c), max_radius / geo.resolution)
    if found is None:
        return None
    xy = geo.cell_to_world(np.array([found[0]]), np.array([found[1]]))[0]
    return Pose2D(float(xy[0]), float(xy[1]), pose.theta)
