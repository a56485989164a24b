"""Global map rendering by re-placing submaps at their optimized poses (Hess et al. 2016 sec. IV).

Each submap's log-odds are resampled into the global grid by *inverse* nearest-neighbour mapping
(every global cell in the submap's footprint looks up the submap cell under its centre), so rotated
submaps leave no aliasing holes. Log-odds add up (independent evidence) and are clamped. One
compiled pass per submap (:func:`nav.slam.kernels.place_submap`; :func:`_surface_wins` and
:func:`_lookup` are its numpy references): cost scales with map area, not with the number of scans.
"""

from __future__ import annotations

import math

import numpy as np

from nav.grid import VIEW_CLEARED, VIEW_HIT, VIEW_UNSURE, LogOddsGrid, LogOddsOptions
from nav.slam.kernels import place_submap
from nav.types import Pose2D

SubmapLayer = tuple[Pose2D, np.ndarray, np.ndarray, np.ndarray]
"""(submap pose in the map frame, grid origin in the submap frame, log-odds, seen mask)."""


def view_logodds(lo: np.ndarray, view: np.ndarray | None, l_occ: float, edge: bool = True) -> np.ndarray:
    """A submap's log-odds as the rendered map shows them (a copy), from its grid's ``view`` states
    (``LogOddsGrid.view``; ``lo`` unchanged where None): a cell whose last firm evidence was a return
    is at least ``l_occ`` (occupied), one that no ray crossed far from its own surface is at least 0
    (not free). Rays that meet a face at a few degrees run within half a cell of it for metres,
    through the cells that straddle it, and outvote the few returns that land in each: the face was
    drawn free though the cells are mostly wall (issue 16, no ghost free space). Only the display:
    the matched grids keep the plain evidence.

    ``edge``: a firmly cleared cell on the edge of what rays firmly cleared, facing space that is
    neither (:func:`unsure_edge`), is at least 0 as well."""
    if view is None:
        return lo.copy()
    floor = np.where(view == VIEW_HIT, np.float32(l_occ), np.float32(0.0))
    free = view == VIEW_CLEARED
    if edge:
        free &= ~unsure_edge(view)
    return np.where(free, lo, np.maximum(lo, floor)).astype(np.float32)


_SIDES = ((0, 1), (0, -1), (1, 0), (-1, 0))


def unsure_edge(view: np.ndarray) -> np.ndarray:
    """Cells a ray firmly cleared (:data:`VIEW_CLEARED`) whose next cell in some lattice direction
    no ray firmly cleared and no return marked (:data:`VIEW_UNSURE`: never observed, or crossed
    only within a margin of the rays' own surface) and whose cell after that is not firmly cleared
    either: the edge of the cleared space against an unobserved wall interior, a shadow, a face only
    grazing rays reached (cells off the grid count as unsure).

    Such a cell was cleared by the outermost rays of a fan, the ones that passed a door jamb's or a
    post's corner or ran down a face no return landed on, which cross only part of it: the unseen
    side may begin inside the cell, and a few centimetres of pose error (the office's corridor
    4-5 cm, the greenhouse's far corner 5 cm) put it there. A cell facing a return (a face seen by
    its own rays) is not an edge: those rays stopped at that surface, whose cell holds it. A single
    unobserved cell between beams far from the lidar is not one either (the cell beyond it is
    cleared)."""
    h, w = view.shape
    pad = np.pad(view, 2, constant_values=VIEW_UNSURE)
    edge = np.zeros(view.shape, dtype=bool)
    for dr, dc in _SIDES:
        nxt = pad[2 + dr : 2 + dr + h, 2 + dc : 2 + dc + w] == VIEW_UNSURE
        after = pad[2 + 2 * dr : 2 + 2 * dr + h, 2 + 2 * dc : 2 + 2 * dc + w] != VIEW_CLEARED
        edge |= nxt & after
    return edge & (view == VIEW_CLEARED)


def _corners(pose: Pose2D, origin: np.ndarray, shape: tuple[int, int], res: float) -> np.ndarray:
    h, w = shape
    local = origin + np.array([[0, 0], [w, 0], [0, h], [w, h]], dtype=float) * res
    return pose.transform_points(local)


def _crop_to_seen(layer: SubmapLayer, res: float) -> SubmapLayer:
    """The layer cut to the bounding box of its observed cells: a submap grid grows with a margin
    of never-seen cells, and the map's extent must be the building's, not the margins'."""
    pose, origin, lo, sn = layer
    rows, cols = np.flatnonzero(sn.any(axis=1)), np.flatnonzero(sn.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    return pose, origin + np.array([c0, r0], dtype=float) * res, lo[r0:r1, c0:c1], sn[r0:r1, c0:c1]


SURFACE_SAMPLE = 0.25
"""Where, in cells from a map cell's centre, :func:`_surface_wins` also looks into a submap."""


def _lookup(
    pose: Pose2D,
    origin: np.ndarray,
    lo: np.ndarray,
    sn: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    res: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Log-odds (0 where not observed) and observed mask of the submap cells under map points."""
    cth, sth = math.cos(pose.theta), math.sin(pose.theta)
    dx, dy = gx - pose.x, gy - pose.y
    sc = np.floor((cth * dx + sth * dy - origin[0]) / res).astype(np.int64)
    sr = np.floor((-sth * dx + cth * dy - origin[1]) / res).astype(np.int64)
    ok = (sr >= 0) & (sr < lo.shape[0]) & (sc >= 0) & (sc < lo.shape[1])
    sr, sc = np.where(ok, sr, 0), np.where(ok, sc, 0)
    ok &= sn[sr, sc]
    return np.where(ok, lo[sr, sc], 0.0), ok


def _surface_wins(
    pose: Pose2D,
    origin: np.ndarray,
    lo: np.ndarray,
    sn: np.ndarray,
    xx: np.ndarray,
    yy: np.ndarray,
    res: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A submap's contribution to the map cells centred at (xx, yy): the submap cell under the
    centre, unless the map cell also covers an occupied submap cell (looked up a quarter cell from
    the centre towards each corner), then the most occupied of those. The two lattices are offset
    and rotated, so a map cell often straddles a wall's face: nearest-neighbour resampling made it
    free when its centre fell on the free side, though part of it is the wall (a cell with a
    surface in it is occupied, as a hit wins over a pass-through when a scan is inserted)."""
    val, ok = _lookup(pose, origin, lo, sn, xx, yy, res)
    best = np.full(val.shape, -np.inf, dtype=np.float64)
    q = SURFACE_SAMPLE * res
    for sx, sy in ((-q, -q), (q, -q), (-q, q), (q, q)):
        v, o = _lookup(pose, origin, lo, sn, xx + sx, yy + sy, res)
        best = np.where(o & (v > best), v, best)
    surface = best > 0.0
    return np.where(surface, best, val), ok | surface


def _footprint(layer: SubmapLayer, res: float) -> tuple[np.ndarray, np.ndarray]:
    """First and one-past-last (col, row) of the map-frame lattice cells (cell k spans
    [k res, (k + 1) res)) that a layer's grid can cover."""
    pose, origin, lo, _ = layer
    c = _corners(pose, origin, lo.shape, res)
    return (
        np.floor(c.min(axis=0) / res).astype(np.int64),
        np.ceil(c.max(axis=0) / res).astype(np.int64),
    )


class _Placed:
    """Submaps' evidence summed in order on the map-frame lattice: ``acc`` / ``seen`` / ``top``
    (top: the most occupied single-submap value, kept only for ``surface_wins_across_submaps``)
    cover the cells from (col, row) ``first`` on."""

    def __init__(self, first: np.ndarray, last: np.ndarray, with_top: bool) -> None:
        w, h = np.maximum(last - first, 0)
        self.first = first
        self.acc = np.zeros((h, w), dtype=np.float32)
        self.seen = np.zeros((h, w), dtype=bool)
        self.top = np.zeros((h, w), dtype=np.float32) if with_top else None

    @property
    def last(self) -> np.ndarray:
        return self.first + np.array([self.acc.shape[1], self.acc.shape[0]])

    def grown(self, first: np.ndarray, last: np.ndarray) -> _Placed:
        """A copy covering at least [first, last), the cells outside this one empty."""
        lo, hi = np.minimum(first, self.first), np.maximum(last, self.last)
        out = _Placed(lo, hi, self.top is not None)
        c0, r0 = self.first - lo
        sub = (slice(r0, r0 + self.acc.shape[0]), slice(c0, c0 + self.acc.shape[1]))
        out.acc[sub], out.seen[sub] = self.acc, self.seen
        if out.top is not None:
            out.top[sub] = self.top
        return out

    def add(self, layers: list[SubmapLayer], res: float, surface_wins: bool) -> None:
        """Place cropped layers, in order, inside this sum's cells (callers grow it first).
        Cell centres are computed from the global cell index, so a cell's value does not depend
        on which other submaps set the extent (a cached sum and a full render agree exactly)."""
        for layer in layers:
            pose, origin, lo, sn = layer
            f, l_ = _footprint(layer, res)
            gx = (np.arange(f[0], l_[0]) + 0.5) * res
            gy = (np.arange(f[1], l_[1]) + 0.5) * res
            # compiled (kernels.place_submap); the numpy _surface_wins / _lookup are its references
            val, ok = place_submap(
                pose.as_array(), origin, lo, sn, gx, gy, res, SURFACE_SAMPLE * res, surface_wins
            )
            c0, r0 = f - self.first
            sub = (slice(r0, r0 + val.shape[0]), slice(c0, c0 + val.shape[1]))
            self.acc[sub] += val
            self.seen[sub] |= ok
            if self.top is not None:
                self.top[sub] = np.maximum(self.top[sub], val)

    def grid(self, options: LogOddsOptions) -> LogOddsGrid:
        """The sum as a clamped log-odds grid cut to its observed cells."""
        res = options.resolution
        out = LogOddsGrid(LogOddsOptions(**{**options.__dict__, "grow_margin": res}))
        acc, seen = self.acc, self.seen
        if self.top is not None:  # (top holds max(0, the most occupied submap value))
            acc = np.where(self.top > 0.0, np.maximum(acc, self.top), acc)
        # cut to the observed cells: the corners of rotated submaps span more than they observed
        rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
        if not rows.size:
            return out
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        out.origin = (self.first + np.array([c0, r0])).astype(float) * res
        out.logodds = np.clip(acc[r0:r1, c0:c1], options.l_min, options.l_max).astype(np.float32)
        out.seen = seen[r0:r1, c0:c1].copy()
        return out


def _cropped(layers: list[SubmapLayer], res: float) -> list[SubmapLayer]:
    return [_crop_to_seen(ly, res) for ly in layers if ly[2].size and ly[3].any()]


def _placed(
    base: _Placed | None, layers: list[SubmapLayer], res: float, with_top: bool, surface_wins: bool
) -> _Placed:
    """``base`` (never modified; returned itself when there is nothing to add) with the cropped
    ``layers`` added after it."""
    if not layers:
        return base if base is not None else _Placed(np.zeros(2, np.int64), np.zeros(2, np.int64), with_top)
    feet = [_footprint(ly, res) for ly in layers]
    first = np.min([f for f, _ in feet], axis=0)
    last = np.max([l_ for _, l_ in feet], axis=0)
    out = base.grown(first, last) if base is not None else _Placed(first, last, with_top)
    out.add(layers, res, surface_wins)
    return out


def render_submaps(
    layers: list[SubmapLayer],
    options: LogOddsOptions,
    surface_wins_across_submaps: bool = False,
    surface_wins: bool = True,
) -> LogOddsGrid:
    """Sum the submaps' log-odds into one grid in the map frame, on the map frame's cell lattice
    (cell k spans [k res, (k + 1) res): the same cell stays the same as the map grows).

    ``surface_wins_across_submaps``: a map cell that any submap holds occupied (its
    :func:`_surface_wins` value above 0: a return landed there more than rays passed) is at least
    that occupied, whatever free evidence the other submaps add; off (the sum decides), because a
    person or a moved chair that one submap saw would stay in the map for good.

    ``surface_wins=False``: plain nearest-neighbour resampling, each submap's evidence placed
    without widening its surfaces (what the map-consistency measure reads: it tests the poses, not
    this display rule)."""
    res = options.resolution
    placed = _placed(None, _cropped(layers, res), res, surface_wins_across_submaps, surface_wins)
    return placed.grid(options)


class SubmapRender:
    """:func:`render_submaps` for a live map published again and again (the same grid, exactly).

    Between pose-graph optimizations only the active submaps change: finished submaps keep their
    grids and, until the optimizer moves them, their poses. Their placed sum is kept and only the
    active submaps are placed on top of it; when any kept submap's pose differs, everything is
    placed again. Submaps are summed in index order in both cases, so the float sums are equal."""

    def __init__(self, options: LogOddsOptions, surface_wins_across_submaps: bool = False) -> None:
        self.options = options
        self.across = surface_wins_across_submaps
        self._kept: _Placed | None = None
        self._kept_poses = np.zeros((0, 3))
        self.full_renders = 0
        """Times the kept sum was rebuilt from the first submap (informational)."""

    def kept(self, poses: np.ndarray) -> int:
        """How many leading submaps the kept sum can serve, given all submaps' (n, 3) map poses:
        the caller need not copy those submaps' grids."""
        k = len(self._kept_poses)
        if self._kept is None or k > len(poses) or not np.array_equal(poses[:k], self._kept_poses):
            return 0
        return k

    def render(self, poses: np.ndarray, finished: int, layers: list[SubmapLayer]) -> LogOddsGrid:
        """The map of submaps whose (n, 3) map poses are ``poses``; the first ``finished`` of them
        will not change their grids any more. ``layers``: the submaps from :meth:`kept` (called
        with the same poses) on, with those poses."""
        res = self.options.resolution
        k = self.kept(poses)
        if k == 0 and len(self._kept_poses):
            self.full_renders += 1
        if k == 0:
            self._kept = None
        if k > len(poses) - len(layers):
            raise ValueError("layers must start at the first submap the kept sum does not hold")
        skip = k - (len(poses) - len(layers))
        layers = layers[skip:]
        final = max(finished - k, 0)
        if final or self._kept is None:
            self._kept = _placed(self._kept, _cropped(layers[:final], res), res, self.across, True)
            self._kept_poses = np.array(poses[: k + final], dtype=float).reshape(-1, 3)
        return _placed(self._kept, _cropped(layers[final:], res), res, self.across, True).grid(self.options)
