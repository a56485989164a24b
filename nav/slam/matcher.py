"""Scan-to-map matching: correlative search then least-squares refinement.

- :func:`correlative_search`: real-time correlative scan matching (Olson 2009) over an
  (x, y, theta) window around a prior, vectorized over all candidate poses and points at once.
  Coarse-to-fine over max-pooled fields (Hess et al. 2016's branch-and-bound bounds, evaluated as a
  beam: the best ``beam`` candidates of each level are split into their 4 children), so a wide
  loop-closure window costs little more than a small front-end window.
- :func:`refine_pose`: Gauss-Newton on ``sum (1 - F(T p_i))^2 / N`` plus translation and rotation
  priors (Cartographer's CeresScanMatcher2D: occupied_space_weight, translation_weight,
  rotation_weight) over the smooth likelihood field.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from nav.slam import kernels
from nav.slam.beam_search import beam_search, keep_best_reference, top_level_blocks
from nav.slam.branch_and_bound import branch_and_bound_search
from nav.slam.field import LikelihoodField
from nav.types import Pose2D, wrap_angle


class ScanMatchError(RuntimeError):
    """The scan could not be matched (no points, or an empty map)."""


@dataclass(frozen=True)
class SearchWindow:
    """Search window of :func:`correlative_search` (Cartographer RealTimeCorrelativeScanMatcher names)."""

    linear_search_window: float = 0.1
    """Half-width of the translation window (m)."""
    angular_search_window: float = math.radians(10.0)
    """Half-width of the rotation window (rad)."""
    angular_step: float = math.radians(0.5)
    """Angle step (rad); Olson's rule is about resolution / max range."""
    levels: int = 0
    """Coarse-to-fine levels (0 = exhaustive at full resolution)."""
    beam: int = 48
    """Candidates kept per level when ``levels > 0``."""
    max_points: int = 100
    """The search scores at most this many points (evenly thinned); refinement uses all."""
    top_level_points: int | None = None
    """With ``levels > 0`` (the beam): the top level ranks its blocks by at most this many of those
    points (evenly thinned; None: all of them); the levels below score them all."""
    branch_and_bound: bool = False
    """With ``levels > 0`` and no runner-up asked: depth-first branch-and-bound over the ``levels``
    pooled fields (:mod:`nav.slam.branch_and_bound`), which returns the exhaustive search's
    result, instead of the beam (which keeps ``beam`` candidates a level and may miss it)."""


@dataclass(frozen=True)
class RefineOptions:
    """Options of :func:`refine_pose` (Cartographer ceres_scan_matcher defaults in spirit)."""

    occupied_space_weight: float = 1.0
    translation_weight: float = 10.0
    rotation_weight: float = 40.0
    max_iterations: int = 20
    tolerance: float = 1e-5


_NO_BOUND = np.zeros((0, 0), dtype=np.float32)  # exhaustive_search without angle bounds
_NO_INCUMBENT = np.zeros(0, dtype=np.int64)  # branch_and_bound_search from scratch


@functools.lru_cache(maxsize=64)
def _thinned(n: int, m: int) -> np.ndarray:
    """Indices of ``m`` of ``n`` points, evenly spread (cached: the same few scan sizes recur)."""
    idx = np.linspace(0, n - 1, m).astype(np.int64)
    idx.setflags(write=False)
    return idx


@functools.lru_cache(maxsize=16)
def _angle_offsets(step: float, na: int) -> np.ndarray:
    """``step * (-na .. na)``: a window's angles about its prior (cached, read-only; the same
    products as computing them per search, so the same angles)."""
    offsets = step * np.arange(-na, na + 1)
    offsets.setflags(write=False)
    return offsets


def _rotations(pts: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """(A, N, 2) points rotated by each angle."""
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    x, y = pts[None, :, 0], pts[None, :, 1]
    return np.stack((c * x - s * y, s * x + c * y), axis=-1)


@functools.lru_cache(maxsize=16)
def _top_candidates(angles: int, lo: int, nb: int) -> np.ndarray:
    """Every ``(angle index, by, bx)`` of a coarse-to-fine search's top level, blocks ``lo`` ..
    ``lo + nb - 1`` (cached, read-only: each window's is built once)."""
    a_idx, by, bx = np.meshgrid(np.arange(angles), lo + np.arange(nb), lo + np.arange(nb), indexing="ij")
    cand = np.column_stack((a_idx.ravel(), by.ravel(), bx.ravel()))
    cand.setflags(write=False)
    return cand


def _top_level_points(
    rows0: np.ndarray, cols0: np.ndarray, limit: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """The (A, N) cells of at most ``limit`` of the points (evenly thinned; None: all)."""
    n = rows0.shape[1]
    if limit is None or n <= limit:
        return rows0, cols0
    keep = _thinned(n, limit)
    return np.ascontiguousarray(rows0[:, keep]), np.ascontiguousarray(cols0[:, keep])


def _lattice(
    field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """A search's points (at most ``window.max_points``, evenly thinned), its angles, the number
    of angle steps each side of the prior and the window's half-width in cells."""
    if pts.shape[0] == 0:
        raise ScanMatchError("no points to match")
    if pts.shape[0] > window.max_points:
        pts = np.take(pts, _thinned(pts.shape[0], window.max_points), axis=0)  # = pts[idx], cheaper
    na = math.ceil(window.angular_search_window / window.angular_step)
    thetas = prior.theta + _angle_offsets(window.angular_step, na)
    return pts, thetas, na, math.ceil(window.linear_search_window / field.resolution)


def _cell_args(
    field: LikelihoodField, pts: np.ndarray, prior: Pose2D, thetas: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, float, float, float]:
    """The arguments :func:`nav.slam.kernels.rotated_cells` (and the searches built on it) take:
    the points, the angles' cosines and sines (numpy's, as the reference uses), the prior's
    position, the field's origin and resolution."""
    return (
        np.ascontiguousarray(pts, dtype=np.float64),
        np.cos(thetas),
        np.sin(thetas),
        prior.x,
        prior.y,
        float(field.origin[0]),
        float(field.origin[1]),
        field.resolution,
    )


def score_candidates_reference(
    field: LikelihoodField, level: int, rows0: np.ndarray, cols0: np.ndarray, cand: np.ndarray, step: int
) -> np.ndarray:
    """Pure-numpy reference of :func:`nav.slam.kernels.score_candidates` (tests compare the two)."""
    r = rows0[cand[:, 0]] + (cand[:, 1] * step)[:, None]
    c = cols0[cand[:, 0]] + (cand[:, 2] * step)[:, None]
    return field.lookup(level, r, c).sum(axis=1) / rows0.shape[1]


def correlative_search(
    field: LikelihoodField,
    pts: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    incumbent: tuple[Pose2D, float] | None = None,
) -> tuple[Pose2D, float]:
    """Best pose (on the search lattice) of points ``pts`` (N, 2, robot frame) in ``field``'s frame
    and its score (mean field value, 0..1). ``incumbent``: a pose of this search's lattice and its
    score from the search of a window nested in this one (:func:`nested`), where a branch-and-bound
    search starts (same result, fewer candidates visited); ignored by other searches."""
    pose, score, _ = _correlative(field, pts, prior, window, math.inf, True, incumbent)
    return pose, score


def correlative_search_runner_up(
    field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow, separation: float
) -> tuple[Pose2D, float, float]:
    """:func:`correlative_search`, plus the best score of the final candidates more than
    ``separation`` (m) away from the best one (0 when there is none): a runner-up almost as good
    as the best says the match is ambiguous (a corridor that looks the same a few metres along)."""
    return _correlative(field, pts, prior, window, separation, compiled=True)


def correlative_search_reference(
    field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow, separation: float
) -> tuple[Pose2D, float, float]:
    """Pure-numpy reference of :func:`correlative_search_runner_up` (the tests compare the two: both
    sum the field's float32 values in float32 in numpy's pairwise order, so scores, ties and the
    chosen pose are bit-identical)."""
    return _correlative(field, pts, prior, window, separation, compiled=False)


def _correlative(
    field: LikelihoodField,
    pts: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    separation: float,
    compiled: bool,
    incumbent: tuple[Pose2D, float] | None = None,
) -> tuple[Pose2D, float, float]:
    """The correlative search, scored by the numba kernels (``compiled``) or by numpy.
    ``incumbent``: see :func:`correlative_search`."""
    pts, thetas, na, wc = _lattice(field, pts, prior, window)
    res = field.resolution
    if compiled:  # (A, N) cells of the points at each angle and zero offset
        cell_args = _cell_args(field, pts, prior, thetas)
        if window.levels == 0 and separation == math.inf:  # the front end's search: one call
            a, dy, dx, best = kernels.exhaustive_search_of_points(
                field.field, field.window_max(wc), *cell_args, wc
            )
            pose = Pose2D(prior.x + dx * res, prior.y + dy * res, float(wrap_angle(thetas[a])))
            return pose, best, 0.0
        rows0, cols0 = kernels.rotated_cells(*cell_args)
    else:
        rot = _rotations(pts, thetas) + np.array([prior.x, prior.y])  # (A, N, 2)
        cell = np.floor((rot - field.origin) / res).astype(np.int64)
        rows0, cols0 = cell[..., 1], cell[..., 0]
    if compiled and window.levels == 0:  # with a runner-up, which needs every score: no bounds
        a, dy, dx, best, runner_up = kernels.exhaustive_search(
            field.field, _NO_BOUND, rows0, cols0, wc, res, separation
        )
        pose = Pose2D(prior.x + dx * res, prior.y + dy * res, float(wrap_angle(thetas[a])))
        return pose, float(best), float(runner_up)
    exact = window.branch_and_bound and separation == math.inf
    if compiled and exact and window.levels > 0:
        field.ensure_levels(window.levels)
        seed, seed_score = _NO_INCUMBENT, -1.0
        if incumbent is not None:
            pose, seed_score = incumbent
            seed = np.array(
                (
                    na + round(float(wrap_angle(pose.theta - prior.theta)) / window.angular_step),
                    round((pose.y - prior.y) / res),
                    round((pose.x - prior.x) / res),
                ),
                dtype=np.int64,
            )
        a, dy, dx, best = branch_and_bound_search(
            tuple(field.pooled[: window.levels + 1]), rows0, cols0, wc, seed, seed_score
        )
        pose = Pose2D(prior.x + dx * res, prior.y + dy * res, float(wrap_angle(thetas[a])))
        return pose, best, 0.0
    if compiled:
        return _beam(field, cell_args, rows0, cols0, thetas, prior, window, na, wc, separation)
    # numpy: the beam, or with ``exact`` the exhaustive search (branch-and-bound's reference)
    top = 0 if exact else window.levels
    field.ensure_levels(top)
    s = 1 << top
    blocks = np.arange(math.floor(-wc / s), math.floor(wc / s) + 1)
    cand = _top_candidates(len(thetas), int(blocks[0]), len(blocks))  # (C, 3) at level `top`
    top_rows, top_cols = _top_level_points(rows0, cols0, window.top_level_points if top else None)
    for level in range(top, -1, -1):
        s = 1 << level
        if level < top:  # split every kept candidate into its 4 children
            kids = np.repeat(cand, 4, axis=0)
            kids[:, 1] = 2 * kids[:, 1] + np.tile([0, 0, 1, 1], len(cand))
            kids[:, 2] = 2 * kids[:, 2] + np.tile([0, 1, 0, 1], len(cand))
            lo_y, lo_x = kids[:, 1] * s, kids[:, 2] * s
            inside = (lo_y + s - 1 >= -wc) & (lo_y <= wc) & (lo_x + s - 1 >= -wc) & (lo_x <= wc)
            cand = kids[inside]  # a block meeting the window has at least one child that does
        rows, cols = (top_rows, top_cols) if level == top else (rows0, cols0)
        score = score_candidates_reference(field, level, rows, cols, cand, s)
        if level > 0:
            keep = keep_best_reference(score, window.beam)
            cand = cand[keep]
    # tie-break towards the prior (smallest offset) for determinism
    dist = np.abs(cand[:, 1]) + np.abs(cand[:, 2]) + np.abs(cand[:, 0] - na)
    best = np.lexsort((dist, -score))[0]
    a, dy, dx = cand[best]
    apart = np.hypot(cand[:, 1] - dy, cand[:, 2] - dx) * res > separation
    runner_up = float(score[apart].max()) if apart.any() else 0.0
    pose = Pose2D(prior.x + dx * res, prior.y + dy * res, float(wrap_angle(thetas[a])))
    return pose, float(score[best]), runner_up


def _beam(
    field: LikelihoodField,
    cell_args: tuple,
    rows0: np.ndarray,
    cols0: np.ndarray,
    thetas: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    na: int,
    wc: int,
    separation: float,
) -> tuple[Pose2D, float, float]:
    """The compiled coarse-to-fine beam (:func:`nav.slam.beam_search.beam_search`) on the field's
    pooled levels. ``cell_args``: :func:`_cell_args` of the search's points (the top level's
    thinned ones are rotated on their own, the same cells as ``rows0`` / ``cols0``'s columns, ~5x
    cheaper than gathering those)."""
    top = window.levels
    field.ensure_levels(top)
    pts = cell_args[0]
    limit = window.top_level_points
    if limit is None or pts.shape[0] <= limit:
        top_rows, top_cols = rows0, cols0
    else:
        top_pts = np.take(pts, _thinned(pts.shape[0], limit), axis=0)
        top_rows, top_cols = kernels.rotated_cells(top_pts, *cell_args[1:])
    res = field.resolution
    pad = top_level_blocks(wc, top)[1]
    a, dy, dx, best, runner_up = beam_search(
        tuple(field.pooled[:top]), field.phase(top, pad), pad, rows0, cols0, top_rows, top_cols,
        wc, window.beam, na, separation, res,
    )  # fmt: skip
    pose = Pose2D(prior.x + dx * res, prior.y + dy * res, float(wrap_angle(thetas[a])))
    return pose, best, runner_up


def refine_pose(
    field: LikelihoodField,
    pts: np.ndarray,
    initial: Pose2D,
    prior: Pose2D,
    options: RefineOptions = RefineOptions(),
) -> tuple[Pose2D, float]:
    """Gauss-Newton refinement of ``initial``; returns the pose and its mean field score
    (compiled: :func:`nav.slam.kernels.gauss_newton`; :func:`refine_pose_reference` in numpy)."""
    if pts.shape[0] == 0:
        raise ScanMatchError("no points to match")
    x, score = kernels.gauss_newton(
        field.field,
        float(field.origin[0]),
        float(field.origin[1]),
        field.resolution,
        np.ascontiguousarray(pts, dtype=np.float64),
        initial.as_array(),
        prior.as_array(),
        options.occupied_space_weight,
        options.translation_weight,
        options.rotation_weight,
        options.max_iterations,
        options.tolerance,
    )
    return Pose2D(float(x[0]), float(x[1]), float(x[2])), float(score)


def refine_pose_reference(
    field: LikelihoodField,
    pts: np.ndarray,
    initial: Pose2D,
    prior: Pose2D,
    options: RefineOptions = RefineOptions(),
) -> tuple[Pose2D, float]:
    """Pure-numpy reference of :func:`refine_pose` (tests compare the two)."""
    if pts.shape[0] == 0:
        raise ScanMatchError("no points to match")
    x = initial.as_array().astype(float)
    p0 = prior.as_array()
    n = pts.shape[0]
    wo = math.sqrt(options.occupied_space_weight / n)
    wt, wr = options.translation_weight, options.rotation_weight
    px, py = pts[:, 0], pts[:, 1]
    for _ in range(options.max_iterations):
        c, s = math.cos(x[2]), math.sin(x[2])
        world = np.column_stack((c * px - s * py + x[0], s * px + c * py + x[1]))
        f, g = field.interpolate_grad(world)
        # residual r_i = wo (1 - F); dr/dx = -wo dF/dxy * dxy/dpose
        dth = np.column_stack((-s * px - c * py, c * px - s * py))
        j = np.empty((n + 3, 3))
        j[:n, 0] = -wo * g[:, 0]
        j[:n, 1] = -wo * g[:, 1]
        j[:n, 2] = -wo * np.einsum("ij,ij->i", g, dth)
        j[n:] = np.diag([wt, wt, wr])
        r = np.concatenate(
            (
                wo * (1.0 - f),
                [wt * (x[0] - p0[0]), wt * (x[1] - p0[1])],
                [wr * float(wrap_angle(x[2] - p0[2]))],
            )
        )
        h = j.T @ j + 1e-9 * np.eye(3)
        step = -np.linalg.solve(h, j.T @ r)
        x += step
        if np.abs(step).max() < options.tolerance:
            break
    pose = Pose2D(float(x[0]), float(x[1]), float(wrap_angle(x[2])))
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    world = np.column_stack((c * px - s * py + pose.x, s * px + c * py + pose.y))
    return pose, float(field.interpolate(world).mean())


def surface_lines(pts: np.ndarray, half_window: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Per point of a scan in beam order: the direction (rad, in the points' frame) of the line
    through it and its ``half_window`` neighbours on each side, and whether those points are
    collinear (a wall, not a corner or a jump between two surfaces; False at the scan's ends).
    Compiled (:func:`nav.slam.kernels.surface_lines`, bit-identical to the numpy version
    :func:`surface_lines_reference`)."""
    n = pts.shape[0]
    if n < 2 * half_window + 1:
        return np.zeros(n), np.zeros(n, dtype=bool)
    return kernels.surface_lines(np.ascontiguousarray(pts, dtype=np.float64), half_window)


def surface_lines_reference(pts: np.ndarray, half_window: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Pure-numpy reference of :func:`surface_lines` (the tests compare the two)."""
    n = pts.shape[0]
    if n < 2 * half_window + 1:
        return np.zeros(n), np.zeros(n, dtype=bool)
    return _lines_from_moments(*window_moments_reference(pts, half_window), half_window)


def window_moments_reference(pts: np.ndarray, half_window: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pure-numpy reference of :func:`nav.slam.kernels.window_moments`."""
    n = pts.shape[0]
    idx = np.arange(n)[:, None] + np.arange(-half_window, half_window + 1)[None, :]
    idx = np.clip(idx, 0, n - 1)
    win = pts[idx]  # (N, W, 2)
    d = win - win.mean(axis=1, keepdims=True)
    cxx, cyy = (d[..., 0] ** 2).mean(axis=1), (d[..., 1] ** 2).mean(axis=1)
    cxy = (d[..., 0] * d[..., 1]).mean(axis=1)
    return cxx, cyy, cxy


def _lines_from_moments(
    cxx: np.ndarray, cyy: np.ndarray, cxy: np.ndarray, half_window: int
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`surface_lines` from the windows' second moments."""
    n = cxx.shape[0]
    along = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    spread = np.hypot(0.5 * (cxx - cyy), cxy)
    lam_hi, lam_lo = 0.5 * (cxx + cyy) + spread, 0.5 * (cxx + cyy) - spread
    line = (lam_lo <= 0.05 * lam_hi) & (lam_hi > 0)
    line[:half_window] = line[n - half_window :] = False
    return along, line


def translation_information(pts: np.ndarray, theta: float, half_window: int = 3) -> np.ndarray:
    """(2, 2) mean of ``n n^T`` over the scan's surface normals, rotated by ``theta`` (the match's
    heading): how well the scan's geometry pins the position in each direction (the point-to-line
    Hessian of ICP, as used to detect degeneracy by Zhang et al. 2016). Along a corridor or an aisle
    whose ends are out of range every normal is across it, so the information along it is ~0.

    ``pts`` (N, 2) are in beam order; each point's normal is that of its :func:`surface_lines`
    line, where there is one. The scan's geometry is used, not the map's field:
    a field built from noisy scans ripples along a straight wall, which looks like information
    along it that is not there."""
    along, line = surface_lines(pts, half_window)
    if not line.any():
        return np.zeros((2, 2))
    nx, ny = kernels.surface_normals(along, line, theta)  # the lines' directions, rotated
    return np.array([[nx @ nx, nx @ ny], [nx @ ny, ny @ ny]]) / pts.shape[0]


def translation_information_reference(pts: np.ndarray, theta: float, half_window: int = 3) -> np.ndarray:
    """Pure-numpy reference of :func:`translation_information` (the tests compare the two)."""
    n = pts.shape[0]
    along, line = surface_lines_reference(pts, half_window)
    if not line.any():
        return np.zeros((2, 2))
    along = along[line] + theta  # the line's direction, rotated
    nx, ny = -np.sin(along), np.cos(along)
    return np.array([[nx @ nx, nx @ ny], [nx @ ny, ny @ ny]]) / n


def fuse_with_prediction(match: Pose2D, prediction: Pose2D, info: np.ndarray, threshold: float) -> Pose2D:
    """The match's position, moved towards the odometry ``prediction`` along directions the scan
    does not pin down (a degenerate direction: along a corridor, an aisle between long rows).

    Zhang et al. 2016's solution remapping, made smooth: each eigen-direction ``v`` of ``info``
    (:func:`translation_information`) keeps the fraction ``r^2 / (r^2 + threshold^2)`` of the
    match's offset from the prediction, ``r`` its eigenvalue over the largest one. In a room or a
    corridor with a visible end (``r`` >= 0.1 at ``threshold`` 0.03) the match stands (>= 92 %);
    along a featureless aisle (``r`` ~ 0.003, the normals' noise) the prediction stands, as in
    Cartographer's scan matcher, whose translation prior targets the prediction. Heading is the
    match's."""
    if threshold <= 0.0:
        return match
    lam, vec = np.linalg.eigh(0.5 * (info + info.T))
    lmax = float(lam.max())
    if lmax <= 0.0:
        return Pose2D(prediction.x, prediction.y, match.theta)
    r = np.clip(lam, 0.0, None) / lmax
    keep = r**2 / (r**2 + threshold**2)
    off = np.array([match.x - prediction.x, match.y - prediction.y])
    moved = vec @ (keep * (vec.T @ off))
    return Pose2D(prediction.x + float(moved[0]), prediction.y + float(moved[1]), match.theta)


def match_scan(
    field: LikelihoodField,
    pts: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    refine: RefineOptions = RefineOptions(),
) -> tuple[Pose2D, float]:
    """Correlative search around ``prior`` then least-squares refinement (the refinement is
    regularized towards the correlative result, as Cartographer does)."""
    return _search_and_refine(field, pts, prior, window, refine)[2:]


def _search_and_refine(
    field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow, refine: RefineOptions
) -> tuple[Pose2D, float, Pose2D, float]:
    """:func:`correlative_search` then :func:`refine_pose` from (and towards) its pose: the
    search's pose and score, then the refined ones. An exhaustive window (no levels) is one
    compiled call (:func:`nav.slam.kernels.exhaustive_match`, the same kernels)."""
    if window.levels != 0:
        coarse, coarse_score = correlative_search(field, pts, prior, window)
        pose, score = refine_pose(field, pts, coarse, coarse, refine)
        return coarse, coarse_score, pose, score
    search_pts, thetas, _, wc = _lattice(field, pts, prior, window)
    c, best, x, score = kernels.exhaustive_match(
        field.field,
        field.window_max(wc),
        *_cell_args(field, search_pts, prior, thetas),
        wc,
        thetas,
        np.ascontiguousarray(pts, dtype=np.float64),
        refine.occupied_space_weight,
        refine.translation_weight,
        refine.rotation_weight,
        refine.max_iterations,
        refine.tolerance,
    )
    coarse = Pose2D(float(c[0]), float(c[1]), float(c[2]))
    return coarse, best, Pose2D(float(x[0]), float(x[1]), float(x[2])), score


def match_scan_with_fallback(
    field: LikelihoodField,
    pts: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    wide_window: SearchWindow,
    minimum_score: float,
    refine: RefineOptions = RefineOptions(),
) -> tuple[Pose2D, float]:
    """:func:`match_scan` in ``window``; a match scoring below ``minimum_score`` is searched again
    in ``wide_window`` (the prior may be outside the narrow one: slip, a fast turn) and the better
    of the two kept (the SLAM front end's ``wide_search_minimum_score``). A branch-and-bound wide
    search starts from the narrow search's best when the narrow window is nested in it. A wide
    search that lands where the narrow one did is not refined again: the refinement would start
    from the same pose towards the same prior, so end where the first one did (the 7 wide searches
    of the 50 Intel relation pairs all did)."""
    coarse, coarse_score, pose, score = _search_and_refine(field, pts, prior, window, refine)
    if score < minimum_score:
        return wide_fallback(
            field, pts, prior, window, wide_window, coarse, coarse_score, pose, score, refine
        )
    return pose, score


def wide_fallback(
    field: LikelihoodField,
    pts: np.ndarray,
    prior: Pose2D,
    window: SearchWindow,
    wide_window: SearchWindow,
    coarse: Pose2D,
    coarse_score: float,
    pose: Pose2D,
    score: float,
    refine: RefineOptions = RefineOptions(),
) -> tuple[Pose2D, float]:
    """The second half of :func:`match_scan_with_fallback`: the search in ``wide_window`` of a
    match in ``window`` (its search's pose and score ``coarse`` / ``coarse_score``, refined to
    ``pose`` / ``score``) and the better of the two refined matches."""
    seed = (coarse, coarse_score) if nested(window, wide_window) else None
    wide_coarse, _ = correlative_search(field, pts, prior, wide_window, seed)
    if wide_coarse != coarse:
        wide_pose, wide_score = refine_pose(field, pts, wide_coarse, wide_coarse, refine)
        if wide_score > score:
            return wide_pose, wide_score
    return pose, score


def nested(inner: SearchWindow, outer: SearchWindow) -> bool:
    """Whether every candidate of ``inner`` is one of ``outer`` scored the same (same angle step
    and points, smaller windows, the same prior and field)."""
    return (
        inner.angular_step == outer.angular_step
        and inner.max_points == outer.max_points
        and inner.linear_search_window <= outer.linear_search_window
        and inner.angular_search_window <= outer.angular_search_window
    )
