"""Submaps: small log-odds grids built from a few consecutive scans in their own frame.

Hess et al. 2016 sec. IV: scans are matched against the current submap instead of the whole map,
so local errors stay local; the back end later moves whole submaps. A submap's grid is expressed in
the submap frame, whose pose in the front end's local frame is ``local_pose`` (the pose of the first
node inserted). Two submaps are active at a time, overlapping by half, so matching always has a
well-filled submap.
"""

from __future__ import annotations

import numpy as np

from nav.grid import LogOddsGrid, LogOddsOptions
from nav.slam.field import LikelihoodField
from nav.types import Pose2D


class Submap:
    """One submap: grid in its own frame, the nodes inserted, and a cached likelihood field."""

    max_stale_cells: int = 200
    """Rebuild the field once this many cells have turned from occupied to free."""

    def __init__(
        self,
        index: int,
        local_pose: Pose2D,
        grid_options: LogOddsOptions,
        sigma: float,
        track_view: bool = False,
    ) -> None:
        self.index = index
        self.local_pose = local_pose
        # track_view: the grid also keeps per cell which firm evidence came last (LogOddsGrid.view)
        self.grid = LogOddsGrid(grid_options, track_view=track_view)
        self.nodes: list[int] = []
        self.finished = False
        self._sigma = sigma
        self._field: LikelihoodField | None = None
        self._stale_free = 0

    def insert(
        self,
        node: int,
        node_local: Pose2D,
        sensor: Pose2D,
        points: np.ndarray,
        misses: np.ndarray,
        shorten: np.ndarray | None = None,
        view_shorten: np.ndarray | None = None,
    ) -> np.ndarray:
        """Insert a scan taken at front-end pose ``node_local``; ``sensor`` is the laser in base_link
        and ``points`` / ``misses`` are in the laser frame; ``shorten``: per point, how far short of
        it its ray stops clearing (``LogOddsGrid.insert_rays``), ``view_shorten`` likewise for the
        grid's ``view`` states only. Returns ``misses`` shortened to where
        they stopped at a surface this submap holds (``LogOddsGrid.insert_rays``), so the next
        submap, still nearly empty, does not clear past walls this one knows."""
        in_submap = node_local.relative_to(self.local_pose).compose(sensor)
        change = self.grid.insert_scan(in_submap, points, misses, shorten, view_shorten)
        self.nodes.append(node)
        if self._field is not None:
            self._stale_free += change.became_free
            # Cells that stopped being occupied can only be lowered by a full rebuild; a few stale
            # (too high) cells barely move a match, so rebuild only when enough have accumulated.
            if change.resized or self._stale_free > self.max_stale_cells:
                self._field = None
            else:
                self._field.splat(change.became_occupied)
        if change.miss_reach is None or not len(misses):
            return misses
        return misses * change.miss_reach[:, None]

    def observed(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the cells under the (N, 2) submap-frame points were observed (hit or passed
        through by a ray) by a scan inserted so far."""
        rows, cols = self.grid.cells(xy)
        h, w = self.grid.shape
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        out = np.zeros(len(xy), dtype=bool)
        out[inside] = self.grid.seen[rows[inside], cols[inside]]
        return out

    def field(self, levels: int = 0) -> LikelihoodField:
        """Likelihood field of the current grid (kept up to date incrementally where possible)."""
        if self._field is None:
            self._field = LikelihoodField.from_grid(self.grid, self._sigma, levels)
            self._stale_free = 0
        else:
            self._field.ensure_levels(levels)
        return self._field

    def release_field(self) -> None:
        """Drop the cached field (finished submaps keep only what loop closure needs)."""
        self._field = None
