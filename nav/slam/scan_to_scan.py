"""Scan-to-scan matching: one scan against one reference scan, from an odometry prior (what
OpenKarto's ScanMatcher does for a pair of scans; ``navdeck bench peers`` compares the two).

The SLAM front end's match on the reference's likelihood field: the field of the reference's
returns (:meth:`nav.slam.field.LikelihoodField.from_points`), the current scan's points the
reference did not observe left out (chosen at the prior, :mod:`nav.slam.coverage`, as the front end
leaves out points its submap has not observed), the narrow exhaustive search and Gauss-Newton
refinement, and below ``wide_search_minimum_score`` the wide re-search
(:func:`nav.slam.matcher.match_scan_with_fallback`).

Everything up to the refined narrow match is one compiled call (:func:`narrow_match`) of the same
kernels the separate steps call, so the result is theirs bit for bit (the tests compare the two):
as separate calls, their Python (a dozen small numpy operations, five dispatches, the field object)
was ~15 % of a match. The wide re-search is a second one (:func:`wide_match`), which builds the
pooled levels it needs from the reference's cells rather than from the field (two passes over the
grid a level).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.typed import List

from nav.slam import kernels
from nav.slam.beam_search import beam_search, top_level_blocks
from nav.slam.field import POINTS_FIELD_MARGIN, LikelihoodField, _halved_window_kernels, _window_kernel
from nav.slam.matcher import ScanMatchError, _angle_offsets, wide_fallback
from nav.slam.system import SlamOptions
from nav.types import LaserScan, Pose2D


class ScanToScanMatcher:
    """Matches scans against reference scans (:meth:`match`) as the SLAM front end matches a scan
    against its submap: ``options``' resolution, likelihood field, windows, wide re-search threshold
    and refinement weights; returns beyond ``range_limit`` (default ``max_laser_range``) observed
    nothing, and a point within a cell of a return was observed."""

    def __init__(self, options: SlamOptions | None = None, range_limit: float | None = None) -> None:
        o = options or SlamOptions()
        self.resolution, self.sigma = o.resolution, o.likelihood_sigma
        self.range_limit = o.max_laser_range if range_limit is None else range_limit
        self.window, self.wide_window = o.front_end_windows()
        if self.window.levels != 0:
            raise ValueError("a scan-to-scan match searches its narrow window exhaustively (search_levels 0)")
        self.minimum_score = o.wide_search_minimum_score
        self.refine = o.refine_options()
        self._na = math.ceil(self.window.angular_search_window / self.window.angular_step)
        self._wc = math.ceil(self.window.linear_search_window / self.resolution)
        self._kernel = _window_kernel(self.sigma, self.resolution, 0)
        self._halved = _halved_window_kernels(self.sigma, self.resolution, self._wc)
        ww = self.wide_window
        self._wide_na = math.ceil(ww.angular_search_window / ww.angular_step)
        self._wide_wc = math.ceil(ww.linear_search_window / self.resolution)

    def match(
        self, reference: LaserScan, reference_points: np.ndarray, points: np.ndarray, prior: Pose2D
    ) -> tuple[Pose2D, float]:
        """The pose of ``points`` (N, 2, their scan's frame) in the frame of ``reference`` (whose
        returns are ``reference_points``) and its score (mean field value, 0..1); ``prior``: the
        odometry's guess of that pose."""
        if reference_points.shape[0] == 0:
            raise ValueError("no points to build a likelihood field from")
        if points.shape[0] == 0:
            raise ScanMatchError("no points to match")
        w, r = self.window, self.refine
        thetas = prior.theta + _angle_offsets(w.angular_step, self._na)
        grid, ox, oy, kept, cx, cy, ct, best, x, y, theta, score = narrow_match(
            np.ascontiguousarray(reference_points, dtype=np.float64),
            self.resolution,
            POINTS_FIELD_MARGIN,
            self._kernel,
            self._halved,
            np.ascontiguousarray(reference.ranges, dtype=np.float64),
            float(reference.range_min),
            self.range_limit,
            float(reference.angle_min),
            float(reference.angle_increment),
            np.ascontiguousarray(points, dtype=np.float64),
            np.array([prior.x, prior.y, math.cos(prior.theta), math.sin(prior.theta)]),
            w.max_points,
            np.cos(thetas),  # numpy's, as the separate steps use
            np.sin(thetas),
            prior.x,
            prior.y,
            self._wc,
            thetas,
            r.occupied_space_weight,
            r.translation_weight,
            r.rotation_weight,
            r.max_iterations,
            r.tolerance,
        )
        pose = Pose2D(x, y, theta)
        if score >= self.minimum_score:
            return pose, score
        ww = self.wide_window
        if ww.branch_and_bound or ww.levels == 0:  # the beam is compiled in one call, these are not
            f = LikelihoodField(grid, np.array([ox, oy]), self.resolution)
            f.sigma = self.sigma
            return wide_fallback(f, kept, prior, w, ww, Pose2D(cx, cy, ct), best, pose, score, r)
        thetas = prior.theta + _angle_offsets(ww.angular_step, self._wide_na)
        out, wide_score = wide_match(
            grid, ox, oy, self.resolution,
            np.ascontiguousarray(reference_points, dtype=np.float64), self._kernel,
            kept, np.cos(thetas), np.sin(thetas), thetas, prior.x, prior.y,
            self._wide_wc, ww.levels, ww.beam, ww.max_points,
            -1 if ww.top_level_points is None else ww.top_level_points,
            np.array([cx, cy, ct]), np.array([x, y, theta]), score,
            r.occupied_space_weight, r.translation_weight, r.rotation_weight, r.max_iterations, r.tolerance,
        )  # fmt: skip
        return Pose2D(float(out[0]), float(out[1]), float(out[2])), wide_score


@njit(cache=True, nogil=True)
def _thinned(n: int, m: int) -> np.ndarray:
    """``np.linspace(0, n - 1, m).astype(np.int64)`` (``matcher._thinned``), the same float64
    operations: ``i * ((n - 1) / (m - 1))``, the last exactly ``n - 1``, truncated."""
    out = np.zeros(m, dtype=np.int64)
    if m == 1:  # linspace's single sample is its start
        return out
    step = float(n - 1) / float(m - 1)
    for i in range(m - 1):
        out[i] = int(float(i) * step)
    out[m - 1] = n - 1
    return out


@njit(cache=True, nogil=True)
def narrow_match(
    reference_points: np.ndarray,
    resolution: float,
    margin: float,
    kernel: np.ndarray,
    halved_kernels: np.ndarray,
    ranges: np.ndarray,
    range_min: float,
    range_limit: float,
    angle_min: float,
    angle_increment: float,
    points: np.ndarray,
    prior_pose: np.ndarray,
    max_points: int,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    px: float,
    py: float,
    wc: int,
    thetas: np.ndarray,
    occupied_weight: float,
    wt: float,
    wr: float,
    max_iterations: int,
    tolerance: float,
) -> tuple:
    """The reference's field (``LikelihoodField.from_points``: grid, origin x and y), the points
    the reference observed (``coverage.observed_by_scan`` at ``prior_pose`` (x, y, cos, sin), then
    ``coverage.observed_subset``), then ``matcher._search_and_refine`` of those in the exhaustive
    window, bounded by the field's ``window_max(wc)``: the search's pose (x, y, theta) and score,
    the refined pose and its score. Two arrays come back, not more: each one handed to Python is
    ~1 us of boxing."""
    grid, ox, oy, rows, cols = kernels.points_field(reference_points, resolution, margin, kernel)
    h, w = grid.shape
    bound = np.zeros(((h + 2 * wc + 1) // 2, (w + 2 * wc + 1) // 2), dtype=np.float32)
    kernels.splat_halved(bound, rows + wc, cols + wc, halved_kernels)
    observed = kernels.observed_by_scan(
        ranges, range_min, range_limit, angle_min, angle_increment, points, prior_pose, resolution
    )
    n = points.shape[0]
    kept = 0
    for i in range(n):
        kept += observed[i]
    if 3 <= kept < n:  # too few observed: all are matched
        pts = np.empty((kept, 2))
        k = 0
        for i in range(n):
            if observed[i]:
                pts[k] = points[i]
                k += 1
    else:
        pts = points
    search = pts
    if pts.shape[0] > max_points:
        idx = _thinned(pts.shape[0], max_points)
        search = np.empty((max_points, 2))
        for i in range(max_points):
            search[i] = pts[idx[i]]
    coarse, best, x, score = kernels.exhaustive_match(
        grid, bound, search, cos_t, sin_t, px, py, ox, oy, resolution, wc, thetas, pts,
        occupied_weight, wt, wr, max_iterations, tolerance,
    )  # fmt: skip
    return grid, ox, oy, pts, coarse[0], coarse[1], coarse[2], best, x[0], x[1], x[2], score


@njit(cache=True, nogil=True)
def wide_match(
    grid: np.ndarray,
    ox: float,
    oy: float,
    resolution: float,
    reference_points: np.ndarray,
    kernel: np.ndarray,
    kept: np.ndarray,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    thetas: np.ndarray,
    px: float,
    py: float,
    wc: int,
    levels: int,
    beam: int,
    max_points: int,
    top_level_points: int,
    coarse: np.ndarray,
    pose: np.ndarray,
    score: float,
    occupied_weight: float,
    wt: float,
    wr: float,
    max_iterations: int,
    tolerance: float,
) -> tuple[np.ndarray, float]:
    """``matcher.wide_fallback`` of a narrow match (its search's pose ``coarse`` and refined
    ``pose`` / ``score``; ``kept``: the points it matched) with the wide window's beam, in one call:
    the search's points (``max_points`` of ``kept``, thinned) at the window's angles (``thetas``,
    their cosines and sines given), the top level's (``top_level_points`` of those; -1: all), the
    pooled levels (:func:`nav.slam.kernels.points_pooled` and :func:`~nav.slam.kernels.points_phase`
    from the reference's cells, exactly ``LikelihoodField``'s when no splat was clipped at the
    grid's edge, else ``max_pool`` and ``phase_split`` as the field does), the beam search, and the
    refinement of its pose when it is not the narrow search's. Returns the better refined pose and
    its score."""
    n = kept.shape[0]
    pts = kept
    if n > max_points:
        idx = _thinned(n, max_points)
        pts = np.empty((max_points, 2))
        for i in range(max_points):
            pts[i] = kept[idx[i]]
    rows0, cols0 = kernels.rotated_cells(pts, cos_t, sin_t, px, py, ox, oy, resolution)
    top_rows, top_cols = rows0, cols0
    if 0 <= top_level_points < pts.shape[0]:  # those points' columns of the cells
        idx = _thinned(pts.shape[0], top_level_points)
        top_rows = np.empty((rows0.shape[0], top_level_points), dtype=np.int64)
        top_cols = np.empty((rows0.shape[0], top_level_points), dtype=np.int64)
        for a in range(rows0.shape[0]):
            for i in range(top_level_points):
                top_rows[a, i] = rows0[a, idx[i]]
                top_cols[a, i] = cols0[a, idx[i]]
    h, w = grid.shape
    rows, cols = kernels.points_cells(reference_points, ox, oy, resolution)
    pooled = List()
    pooled.append(grid)
    pad = top_level_blocks(wc, levels)[1]
    if kernels.points_fit(rows, cols, kernel.shape[0] // 2, h, w):
        for level in range(1, levels):
            pooled.append(kernels.points_pooled(rows, cols, kernel, 1 << level, h, w))
        phase = kernels.points_phase(rows, cols, kernel, 1 << levels, h, w, pad)
    else:  # a splat clipped at the edge: pool the field itself
        g = grid
        for level in range(1, levels + 1):
            g = kernels.max_pool(g, 1 << (level - 1))
            if level < levels:
                pooled.append(g)
        phase = kernels.phase_split(g, 1 << levels, pad)
    centre = (thetas.shape[0] - 1) // 2
    a, dy, dx, _, _ = beam_search(
        pooled, phase, pad, rows0, cols0, top_rows, top_cols, wc, beam, centre, math.inf, resolution
    )
    wide = np.array([px + dx * resolution, py + dy * resolution, kernels._wrap(thetas[a])])
    if wide[0] != coarse[0] or wide[1] != coarse[1] or wide[2] != coarse[2]:
        x, wide_score = kernels.gauss_newton(
            grid, ox, oy, resolution, kept, wide, wide, occupied_weight, wt, wr, max_iterations, tolerance
        )
        if wide_score > score:
            return x, wide_score
    return pose, score
