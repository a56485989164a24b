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

from nav.grid import VIEW_CLEARED, VIEW_HIT, LogOddsGrid, LogOddsOptions
from nav.slam.kernels import place_submap
from nav.types import Pose2D

SubmapLayer = tuple[Pose2D, np.ndarray, np.ndarray, np.ndarray]
"""(submap pose in the map frame, grid origin in the submap frame, log-odds, seen mask)."""


def view_logodds(lo: np.ndarray, view: np.ndarray | None, l_occ: float) -> np.ndarray:
    """A submap's log-odds as the rendered map shows them (a copy), from its grid's ``view`` states
    (``LogOddsGrid.view``; ``lo`` unchanged where None): a cell whose last firm evidence was a return
    is at least ``l_occ`` (occupied), one that no ray crossed far from its own surface is at least 0
    (not free). Rays that meet a face at a few degrees run within half a cell of it for metres,
    through the cells that straddle it, and outvote the few returns that land in each: the face was
    drawn free though the cells are mostly wall (issue 16, no ghost free space). Only the display:
    the matched grids keep the plain evidence."""
    if view is None:
        return lo.copy()
    floor = np.where(view == VIEW_HIT, np.float32(l_occ), np.float32(0.0))
    return np.where(view == VIEW_CLEARED, lo, np.maximum(lo, floor)).astype(np.float32)


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


def render_submaps(
    layers: list[SubmapLayer],
    options: LogOddsOptions,
    surface_wins_across_submaps: bool = False,
    surface_wins: bool = True,
) -> LogOddsGrid:
    """Sum the submaps' log-odds into one grid in the map frame.

    ``surface_wins_across_submaps``: a map cell that any submap holds occupied (its
    :func:`_surface_wins` value above 0: a return landed there more than rays passed) is at least
    that occupied, whatever free evidence the other submaps add; off (the sum decides), because a
    person or a moved chair that one submap saw would stay in the map for good.

    ``surface_wins=False``: plain nearest-neighbour resampling, each submap's evidence placed
    without widening its surfaces (what the map-consistency measure reads: it tests the poses, not
    this display rule)."""
    res = options.resolution
    # one cell of margin: the map's extent is what was observed (a 1 m margin made every saved map
    # 2 m wider and taller than the building)
    out = LogOddsGrid(LogOddsOptions(**{**options.__dict__, "grow_margin": res}))
    layers = [_crop_to_seen(ly, res) for ly in layers if ly[2].size and ly[3].any()]
    if not layers:
        return out
    allc = np.vstack([_corners(p, o, lo.shape, res) for p, o, lo, _ in layers])
    out.ensure_contains(allc)
    acc = np.zeros(out.shape, dtype=np.float32)
    seen = np.zeros(out.shape, dtype=bool)
    top = np.zeros(out.shape, dtype=np.float32) if surface_wins_across_submaps else None
    for pose, origin, lo, sn in layers:
        c = _corners(pose, origin, lo.shape, res)
        c0 = np.floor((c.min(axis=0) - out.origin) / res).astype(int)
        c1 = np.ceil((c.max(axis=0) - out.origin) / res).astype(int)
        c0 = np.maximum(c0, 0)
        c1 = np.minimum(c1, [out.shape[1], out.shape[0]])
        cols = np.arange(c0[0], c1[0])
        rows = np.arange(c0[1], c1[1])
        gx = out.origin[0] + (cols + 0.5) * res
        gy = out.origin[1] + (rows + 0.5) * res
        # compiled (kernels.place_submap); the numpy _surface_wins / _lookup are its references
        val, ok = place_submap(
            pose.as_array(), origin, lo, sn, gx, gy, res, SURFACE_SAMPLE * res, surface_wins
        )
        sub = (slice(c0[1], c1[1]), slice(c0[0], c1[0]))
        acc[sub] += val
        seen[sub] |= ok
        if top is not None:
            top[sub] = np.maximum(top[sub], val)
    if top is not None:  # (top holds max(0, the most occupied submap value))
        acc = np.where(top > 0.0, np.maximum(acc, top), acc)
    # cut to the observed cells: the corners of rotated submaps span more than they observed
    rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
    if rows.size:
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        acc, seen = acc[r0:r1, c0:c1], seen[r0:r1, c0:c1]
        out.origin = out.origin + np.array([c0, r0], dtype=float) * res
    out.logodds = np.clip(acc, options.l_min, options.l_max).astype(np.float32)
    out.seen = seen
    return out
