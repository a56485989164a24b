"""Footprint costs along many trajectories without a per-pose rasterisation.

Nav2's ``ObstacleFootprintCritic`` rasterises the footprint's edges for every pose. Here the filled
footprint is rasterised once per heading bin into a list of cell offsets (the union over the bin's
heading range, so it is conservative in heading), and a pose's footprint cost is the maximum over
those offsets around the pose's cell (poses snap to their cell: error <= half a cell, the planner's
own discretisation). The offsets are kept as row runs and each run's maximum is two lookups in a
row-maximum sparse table of the window (built once per cycle), so the cost per pose grows with the
footprint's height in cells, not its area: a 1 m round robot at 5 cm cells is 41 runs instead of
1300 cells (it was one ``maximum_filter`` over the window, 30x a 0.1 m robot's cycle). For the
"does it touch a lethal cell" test, a mask of the cells within the circumscribed radius of a
lethal cell (the distance-transform test ``edt <= reach``, stamped by a compiled loop: cheaper
than the transform for one small window per cycle) first clears every pose farther from any
obstacle, so only the few poses near obstacles are queried, up to their first
lethal run. A round robot needs one bin, and its near poses are tested at their exact position
against the lethal cells' centres. ``CostWindow._gather`` (every footprint cell) is the reference
the tests hold the run queries to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit
from scipy import ndimage

from nav.control.footprint_kernels import (
    _crop,
    _disc,
    _lethal_poses,
    _lethal_round_dt,
    _lethal_sq_distance,
    _near_lethal,
    _ring,
    _row_max_levels,
    _span_max,
    _xy_bounds,
)
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, Pose2D, wrap_angle


def _inside_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for (N, 2) points (vectorized over points, loop over edges)."""
    x, y = pts[:, 0], pts[:, 1]
    inside = np.zeros(pts.shape[0], dtype=bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < x_at)
    return inside


def rasterize(polygon: np.ndarray, resolution: float, angles: np.ndarray) -> np.ndarray:
    """(P, 2) integer (row, col) offsets, relative to the pose's cell, of the cells the polygon
    covers at any of ``angles``: cell centres inside it, plus cells its densely sampled edges cross."""
    radius = float(np.max(np.hypot(polygon[:, 0], polygon[:, 1])))
    r = math.ceil(radius / resolution) + 1
    idx = np.arange(-r, r + 1)
    rows, cols = np.meshgrid(idx, idx, indexing="ij")
    centres = np.column_stack((cols.ravel() * resolution, rows.ravel() * resolution))
    mask = np.zeros((2 * r + 1, 2 * r + 1), dtype=bool)
    ends = np.roll(polygon, -1, axis=0)
    n = max(math.ceil(float(np.max(np.hypot(*(ends - polygon).T))) / (resolution / 4.0)), 1)
    f = np.linspace(0.0, 1.0, n + 1)[None, :, None]
    boundary = (polygon[:, None, :] * (1 - f) + ends[:, None, :] * f).reshape(-1, 2)
    for a in angles:
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c, -s], [s, c]])
        mask |= _inside_polygon(centres, polygon @ rot.T).reshape(mask.shape)
        b = boundary @ rot.T
        mask[np.rint(b[:, 1] / resolution).astype(int) + r, np.rint(b[:, 0] / resolution).astype(int) + r] = (
            True
        )
    rr, cc = np.nonzero(mask)
    return np.column_stack((rr - r, cc - r))


@njit(cache=True, nogil=True)
def _max_under(
    costs: np.ndarray, rows: np.ndarray, cols: np.ndarray, bins: np.ndarray, offsets: np.ndarray, stop: int
) -> np.ndarray:
    """Max of ``costs`` over each pose's binned footprint offsets; a pose's scan ends early once
    it reaches ``stop`` (255: never for uint8 costs below it). One pass, no (N, P) temporaries."""
    n, p = rows.shape[0], offsets.shape[1]
    out = np.zeros(n, dtype=np.uint8)
    for i in range(n):
        r, c, off = rows[i], cols[i], offsets[bins[i]]
        best = costs[r + off[0, 0], c + off[0, 1]]
        for j in range(1, p):
            v = costs[r + off[j, 0], c + off[j, 1]]
            if v > best:
                best = v
                if best >= stop:
                    break
        out[i] = best
    return out


@dataclass(frozen=True)
class FootprintModel:
    """The footprint rasterised for ``bins`` headings at one costmap resolution."""

    resolution: float
    offsets: np.ndarray  # (B, P, 2) (row, col) offsets per heading bin, padded by repeating (0, 0)
    circumscribed: float  # m
    round: bool = False  # a circle: collision tests use the distance transform alone

    @property
    def bins(self) -> int:
        return int(self.offsets.shape[0])

    @cached_property
    def spans(self) -> tuple[np.ndarray, np.ndarray, int]:
        """The footprint of each heading bin as row runs: ((B, S, 3) runs (row offset, first and
        last col offset), padded; (B,) runs per bin; sparse-table levels the longest run needs).
        A pose's maximum cost is then one two-lookup query per run: a cost that grows with the
        footprint's height in cells, not its area."""
        runs: list[np.ndarray] = []
        for off in self.offsets:
            cells = np.unique(off, axis=0)  # sorted by row, then column; drops the padding repeats
            new_run = np.ones(len(cells), dtype=bool)
            new_run[1:] = (np.diff(cells[:, 0]) != 0) | (np.diff(cells[:, 1]) != 1)
            first = np.flatnonzero(new_run)
            last = np.append(first[1:], len(cells)) - 1
            runs.append(np.column_stack((cells[first, 0], cells[first, 1], cells[last, 1])))
        counts = np.array([len(r) for r in runs], dtype=np.int64)
        out = np.zeros((len(runs), int(counts.max()), 3), dtype=np.int64)
        for b, r in enumerate(runs):
            out[b, : len(r)] = r
        longest = int((out[..., 2] - out[..., 1]).max()) + 1
        return out, counts, longest.bit_length()

    @staticmethod
    def build(polygon: np.ndarray, resolution: float, bins: int, round_robot: bool) -> FootprintModel:
        bins = 1 if round_robot else max(int(bins), 1)
        width = 2.0 * math.pi / bins
        per_bin = []
        for b in range(bins):
            angles = b * width + np.linspace(-0.5 * width, 0.5 * width, 5) if bins > 1 else np.zeros(1)
            per_bin.append(rasterize(polygon, resolution, angles))
        p = max(len(o) for o in per_bin)
        offsets = np.zeros((bins, p, 2), dtype=np.int64)
        for b, o in enumerate(per_bin):
            offsets[b, : len(o)] = o
        radius = float(np.max(np.hypot(polygon[:, 0], polygon[:, 1])))
        return FootprintModel(resolution, offsets, radius, round_robot)


@dataclass(frozen=True)
class CostWindow:
    """A crop of the costmap covering every trajectory plus a margin (>= the footprint's radius),
    with NO_INFORMATION mapped per ``unknown_is_lethal`` and everything off the costmap lethal."""

    costs: np.ndarray  # (H, W) uint8
    geometry: GridGeometry  # geometry of the crop (origin shifted, same resolution and rotation)
    _near: dict[float, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    _levels: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    @cached_property
    def _origin(self) -> np.ndarray | None:
        """(x0, y0, theta0, 1 / resolution) for the compiled kernels; None for a rotated grid
        (those take the general numpy path)."""
        o = self.geometry.origin
        if o.theta != 0.0:
            return None
        return np.array([o.x, o.y, o.theta, 1.0 / self.geometry.resolution])

    @staticmethod
    def around(costmap: Costmap, xy: np.ndarray, margin: float, unknown_is_lethal: bool) -> CostWindow:
        """Crop ``costmap`` to the bounding box of points ``xy`` (..., 2+) grown by ``margin`` metres."""
        g = costmap.geometry
        x0, x1, y0, y1 = _xy_bounds(xy.reshape(-1, xy.shape[-1]))
        if g.origin.theta == 0.0:  # floor is monotonic: the box's cells are its corners' cells
            o, res = g.origin, g.resolution
            rows = (math.floor((y0 - o.y) / res), math.floor((y1 - o.y) / res))
            cols = (math.floor((x0 - o.x) / res), math.floor((x1 - o.x) / res))
        else:
            corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
            rows, cols = g.world_to_cell(corners)  # bounding box of the points, in cells
        m = math.ceil(margin / g.resolution) + 2
        r0, r1 = int(min(rows)) - m, int(max(rows)) + m + 1
        c0, c1 = int(min(cols)) - m, int(max(cols)) + m + 1
        out = _crop(costmap.costs, r0, r1, c0, c1, LETHAL_OBSTACLE if unknown_is_lethal else 0)
        origin = g.origin.compose(Pose2D(c0 * g.resolution, r0 * g.resolution, 0.0))
        return CostWindow(out, GridGeometry(g.resolution, c1 - c0, r1 - r0, origin))

    def cells(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row/col in this window of (..., 2+) poses (clipped: only guards rounding at the border)."""
        g = self.geometry
        h, w = self.costs.shape
        if g.origin.theta == 0.0:  # the usual axis-aligned costmap: no rotation, no reshaping
            inv = 1.0 / g.resolution
            cols = np.floor((poses[..., 0] - g.origin.x) * inv).astype(np.intp)
            rows = np.floor((poses[..., 1] - g.origin.y) * inv).astype(np.intp)
        else:
            rows, cols = g.world_to_cell(poses[..., :2].reshape(-1, 2))
            rows, cols = rows.reshape(poses.shape[:-1]), cols.reshape(poses.shape[:-1])
        np.clip(rows, 0, h - 1, out=rows)
        np.clip(cols, 0, w - 1, out=cols)
        return rows, cols

    def centre_costs(self, poses: np.ndarray) -> np.ndarray:
        """Cost of the cell under each pose's centre, shape ``poses.shape[:-1]``."""
        rows, cols = self.cells(poses)
        return self.costs[rows, cols]

    def _bins(self, theta: np.ndarray, model: FootprintModel) -> np.ndarray:
        if model.bins == 1:
            return np.zeros(theta.shape, dtype=np.int64)
        b = np.rint((theta - self.geometry.origin.theta) * (model.bins / (2.0 * math.pi))).astype(np.int64)
        return b % model.bins

    def _gather(
        self, rows: np.ndarray, cols: np.ndarray, theta: np.ndarray, model: FootprintModel
    ) -> np.ndarray:
        """(N,) max cost under the footprint at flat (N,) cells and headings."""
        # no clipping needed: ``around`` pads the crop by more than the footprint's reach
        return _max_under(self.costs, rows, cols, self._bins(theta, model), model.offsets, 255)

    def footprint_costs(self, poses: np.ndarray, model: FootprintModel) -> np.ndarray:
        """Max cost under the footprint at each pose, shape ``poses.shape[:-1]``: the footprint's
        row runs (``FootprintModel.spans``) queried in a row-maximum sparse table of the window,
        so a 1 m robot costs ten times a 0.1 m one per pose, not a hundred (``_gather``, every
        footprint cell, is the reference)."""
        spans, counts, levels = model.spans
        rows, cols = self.cells(poses)
        bins = self._bins(poses[..., 2].ravel(), model)
        got = _span_max(self.row_max_levels(levels), rows.ravel(), cols.ravel(), bins, spans, counts)
        return got.reshape(poses.shape[:-1])

    def row_max_levels(self, levels: int) -> np.ndarray:
        """(levels, H, W) row-maximum sparse table of the costs (``_row_max_levels``), cached."""
        table = self._levels.get(levels)
        if table is None:
            table = self._levels[levels] = _row_max_levels(self.costs, levels)
        return table

    def lethal_distance(self) -> np.ndarray:
        """(H, W) Euclidean distance (m) from each cell centre to the nearest lethal cell centre."""
        return self._lethal_dist

    @cached_property
    def _lethal_dist(self) -> np.ndarray:
        if not self._has_lethal:  # scipy's answer for a mask without a lethal cell, kept as it was
            return ndimage.distance_transform_edt(self.costs < LETHAL_OBSTACLE) * self.geometry.resolution
        return np.sqrt(_lethal_sq_distance(self.costs)) * self.geometry.resolution

    @cached_property
    def _has_lethal(self) -> bool:
        return bool((self.costs >= LETHAL_OBSTACLE).any())

    def near_lethal(self, reach: float) -> np.ndarray:
        """(H, W) whether a lethal cell centre lies within ``reach`` m of each cell centre: the
        same answer as ``lethal_distance() <= reach``, from a compiled disc stamp (no transform).
        Cached per reach: a cycle asks for the same one several times."""
        near = self._near.get(reach)
        if near is None:
            near = self._near[reach] = _near_lethal(self.costs, _disc(self.geometry.resolution, reach))
        return near

    def footprint_lethal(self, poses: np.ndarray, model: FootprintModel) -> np.ndarray:
        """Whether the footprint touches a lethal cell at each pose, shape ``poses.shape[:-1]``.

        Poses farther than the circumscribed radius + 0.75 cell from every lethal cell (cell
        centres: the ``near`` mask) are clear without further work. Round robots: the rest are
        tested at their exact position, a lethal cell being a point obstacle at its centre that
        collides strictly inside the radius (TEB's ``centre_collisions``); snapping the pose to
        its cell instead is off by up to 0.71 cell, and in a gap one cell wider than the robot it
        flags every pose of the passable row (the robot stops in the gap, and the spin recovery
        then grinds the post's corner). Polygons: the rest are gathered, up to their first
        lethal cell."""
        res = self.geometry.resolution
        if model.round:  # exact pose against the lethal cells' centres (see _lethal_round_dt)
            p3, origin = _poses_3d(poses), self._origin
            if origin is None:  # rotated grid: the poses in the grid's frame, where it is axis-aligned
                xy = self.geometry.origin.inverse().transform_points(p3[..., :2].reshape(-1, 2))
                p3 = np.concatenate((xy.reshape(*p3.shape[:2], 2), p3[..., 2:3]), axis=-1)
                origin = np.array([0.0, 0.0, 0.0, 1.0 / res])
            if not self._has_lethal:
                return np.zeros(poses.shape[:-1], dtype=bool)
            ring, ring_r = _ring(res, model.circumscribed + 0.7072 * res)
            dist = self._lethal_dist
            got = _lethal_round_dt(self.costs, dist, p3, origin, ring, ring_r, res, model.circumscribed)
            return got.reshape(poses.shape[:-1])
        reach = model.circumscribed + 0.75 * res
        near = self.near_lethal(reach)
        if self._origin is not None:
            spans, counts, levels = model.spans
            table = self.row_max_levels(levels)
            got = _lethal_poses(table, near, _poses_3d(poses), self._origin, spans, counts)
            return got.reshape(poses.shape[:-1])
        rows, cols = self.cells(poses)
        hit = near[rows, cols]
        rows, cols, hit = rows.ravel(), cols.ravel(), hit.ravel()
        idx = np.flatnonzero(hit)
        out = np.zeros(rows.shape[0], dtype=bool)
        if idx.size:
            b = self._bins(poses[..., 2].ravel()[idx], model)
            # stop at the first lethal cell: "touches" needs no maximum
            got = _max_under(self.costs, rows[idx], cols[idx], b, model.offsets, LETHAL_OBSTACLE)
            out[idx] = got >= LETHAL_OBSTACLE
        return out.reshape(poses.shape[:-1])

    def clearance(self, poses: np.ndarray) -> np.ndarray:
        """Distance (m) from each pose's cell to the nearest lethal cell, shape ``poses.shape[:-1]``."""
        rows, cols = self.cells(poses)
        return self.lethal_distance()[rows, cols]


def _poses_3d(poses: np.ndarray) -> np.ndarray:
    """(K, T, 3+) float64 view of (..., 3+) poses (no copy for the usual 1-3 dimensions)."""
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim == 3:
        return p
    return p.reshape(-1 if p.ndim > 1 else 1, *p.shape[-2:]) if p.ndim > 2 else p.reshape(1, -1, p.shape[-1])


def swept_poses(poses: np.ndarray, reach: float, step: float) -> np.ndarray:
    """The (M, 3) poses a footprint passes through going along the (N, 3) poses: each segment is
    cut so that no footprint point within ``reach`` of base_link moves more than ``step`` between
    samples (position linearly, heading along the shorter way round), first pose included.

    Checking only the end poses of a turn misses a rectangle's corners sweeping through a post
    between them (a 0.51 x 0.43 m base turning 0.18 rad per 0.1 s moves a corner 6 cm, more than a
    5 cm cell); teb_local_planner's ``isTrajectoryFeasible`` interpolates for the same reason."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    if len(p) < 2:
        return p.copy()
    d = np.diff(p, axis=0)
    d[:, 2] = wrap_angle(d[:, 2])
    travel = np.hypot(d[:, 0], d[:, 1]) + np.abs(d[:, 2]) * reach
    n = np.maximum(np.ceil(travel / step).astype(np.int64), 1)
    seg = np.repeat(np.arange(len(d)), n)
    frac = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n) + 1) / np.repeat(n, n)
    out = p[seg] + frac[:, None] * d[seg]
    return np.vstack((p[:1], out))


def swept_turn(pose: np.ndarray, angle: float, reach: float, step: float) -> np.ndarray:
    """(M, 3) poses of an in-place turn by ``angle`` (rad, signed, any size) from ``pose``, spaced
    as :func:`swept_poses` (the start pose first)."""
    p = np.asarray(pose, dtype=float).reshape(3)
    n = max(math.ceil(abs(angle) * reach / step), 1)
    out = np.repeat(p[None, :], n + 1, axis=0)
    out[:, 2] = p[2] + np.linspace(0.0, angle, n + 1)
    return out


__all__ = ["CostWindow", "FootprintModel", "rasterize", "swept_poses", "swept_turn"]
