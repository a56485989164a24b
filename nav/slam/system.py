"""``GraphSlam``: the SLAM facade used live (control loop + worker thread) and offline (logs).

Front end (``add_scan``, cheap, on the control loop): motion filter on odometry, scan-to-submap
matching (correlative search + Gauss-Newton, Olson 2009 / Hess et al. 2016), insertion into the two
active submaps. Back end (``run_backend``, on a worker): loop-closure search of recent nodes against
finished submaps nearby, sparse pose-graph optimization with a Huber kernel, and re-rendering of the
global map by re-placing the submaps at their optimized poses.

Frames (REP-105): the front end tracks base_link in a drift-prone *local* frame; the back end
estimates *map* poses; ``map_to_odom`` is what a tf broadcaster would publish.
"""

from __future__ import annotations

import math
import threading
from bisect import bisect_left
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from nav.grid import LogOddsOptions
from nav.slam.coverage import observed_subset
from nav.slam.loop_closure import (
    GlobalProposal,
    LoopCandidate,
    find_loop_closure,
    global_search_region,
    observed_fraction,
    proposals_agree,
)
from nav.slam.matcher import (
    RefineOptions,
    ScanMatchError,
    SearchWindow,
    fuse_with_prediction,
    match_scan_with_fallback,
    surface_lines,
    translation_information,
)
from nav.slam.pose_graph import EdgeSet, PoseGraphOptions, edge_errors, optimize_pose_graph
from nav.slam.render import SubmapLayer, SubmapRender, render_submaps, view_logodds
from nav.slam.submap import Submap
from nav.types import LaserScan, OccupancyGrid, Pose2D, wrap_angle

_IDENTITY = Pose2D()


class SlamError(RuntimeError):
    """SLAM cannot continue (e.g. a scan without any usable return)."""


@dataclass(frozen=True)
class SlamOptions:
    """Options of :class:`GraphSlam`. Names follow slam_toolbox / Cartographer where one exists;
    defaults are tuned once for the Freiburg benchmark logs (same values for all three)."""

    resolution: float = 0.05
    """Map and submap cell size (m); slam_toolbox ``resolution`` 0.05."""
    min_laser_range: float = 0.1
    """Returns closer than this are dropped (m); slam_toolbox ``min_laser_range``."""
    max_laser_range: float = 20.0
    """Returns farther than this are used as free-space misses only (m); slam_toolbox 20.0."""
    missing_data_ray_length: float = 5.0
    """Length (m) of the free ray cast for a beam without return (Cartographer default 5), at most
    the scan's ``range_max``: a 4 m lidar's no-return beam would otherwise clear the wall it just
    missed past its range, and mark the cells behind it observed. It never clears past a surface:
    it stops at the first cell a submap already holds as occupied (the fuller active submap first),
    and a return-less beam next to a returning one (a dropout on a wall) stops a cell short of its
    neighbour's return (issue 16, no ghost free space)."""
    grazing_ray_margin: float = 0.0
    """Off by default (0). When > 0 (0.025 m, half a cell, is the measured setting), a return's ray
    does not clear a cell the submap holds occupied where it ran within this distance (m) of the
    surface it hit: over its last ``margin / sin(angle between ray and surface)``, half a cell for a
    head-on return, metres for one that grazed a wall (the surface's direction from the scan's
    neighbouring returns, :func:`grazing_shortening`); cells not (yet) occupied are cleared as
    before. A beam that runs nearly parallel to a face before it meets it passes through the face's
    boundary cells (those straddling the face, on a lattice not aligned with it) where its return
    does not land, and many such beams outvote the few returns that land in each: the face was
    cleared (the greenhouse's plant-row faces seen down the aisles from the headlands; issue 16, no
    ghost free space). Why off: at 0.025 the ghost bench's in-wall cells fell 8 / 62 / 51 -> 2 / 48
    / 30 (apartment / office / greenhouse) but FR079 scored 0.0455 m instead of 0.0440 m (Intel
    0.0340, ACES 0.0373; docs/benchmarks.md, stop 30), and the real logs decide."""
    view_grazing_margin: float = 0.025
    """The same test for the map users get only (render, save, 3D view), 0 = off: each submap keeps
    per cell which firm evidence came last (``LogOddsGrid.view``): a return landing there, or a ray
    crossing it farther than this (m) plus ``range * constraint_rotation_sigma`` (where a heading
    error of one sigma puts the ray's end across its surface) from the surface it hit; crossings
    within it (the stretch of :func:`grazing_shortening`, a return without a fitting line taking its
    angle from its neighbours' segments) do not count. The rendered map shows a cell a return
    marked last as at least occupied, one no firm crossing reached as at least unknown
    (:func:`nav.slam.render.view_logodds`); the grids the front end and loop closure match against
    are the plain log-odds, so trajectories do not change (stop 30's ``grazing_ray_margin`` changed
    them: FR079 got worse)."""
    minimum_travel_distance: float = 0.1
    """Motion filter: a scan becomes a node after this travel (m); slam_toolbox 0.5, Cartographer 0.2."""
    minimum_travel_heading: float = math.radians(5.0)
    """Motion filter: ... or this rotation (rad); slam_toolbox 0.5, Cartographer 1 deg."""
    minimum_time_interval: float = 5.0
    """Motion filter: ... or this much time (s) (Cartographer ``max_time_seconds`` 5)."""
    match_every_scan: bool = False
    """Scan-match every scan, not only motion-filtered nodes (Cartographer's local trajectory builder
    matches all range data; the motion filter only gates insertion). Off by default: it doubles the
    front end's cost; with the lag estimation and the wide re-search the in-between scans placed by
    odometry no longer carry FR079's timing error (docs/slam.md)."""
    submap_num_range_data: int = 40
    """Nodes per submap before a new one starts; each submap holds 2x this (Cartographer 90)."""
    voxel_filter_size: float = 0.05
    """Matching points are thinned to one per cell of this size (m)."""
    max_match_points: int = 200
    """At most this many points are matched per scan."""
    likelihood_sigma: float = 0.05
    """Std-dev (m) of the likelihood field around occupied cells (Thrun et al. ``sigma_hit``)."""
    linear_search_window: float = 0.1
    """Front-end correlative window half-width (m). A fixed 0.2 m window rescued FR079 before the
    wide re-search existed but let ACES jump along corridors (0.044 m -> 0.10 m)."""
    linear_search_window_per_radian: float = 0.0
    """The translation window widens by this much (m) per radian of odometry rotation since the last
    scan (0 = off; 0.5 m/rad kept ACES at 0.044 m but left FR079 at 0.91 m)."""
    angular_search_window: float = math.radians(10.0)
    """Front-end correlative window half-width (rad)."""
    angular_search_step: float = math.radians(0.5)
    """Front-end correlative angle step (rad)."""
    wide_search_minimum_score: float = 0.6
    """A front-end match scoring below this (mean likelihood 0..1) is searched again in the wide
    window below and the better match kept (0 = off)."""
    wide_linear_search_window: float = 0.5
    """Translation half-width (m) of that second search (coarse-to-fine, ``wide_search_levels``)."""
    wide_angular_search_window: float = math.radians(30.0)
    """Rotation half-width (rad) of that second search."""
    wide_search_levels: int = 2
    """Pooled levels of the wide search: a beam of 48 candidates a level, or with
    ``wide_search_branch_and_bound`` the depth of the branch-and-bound (Cartographer
    ``branch_and_bound_depth``: the result does not depend on it, only the time; on Intel's
    relation pairs 3 and 4 alike, 2 about 15 % slower)."""
    wide_search_top_level_points: int | None = 25
    """The wide search's top level ranks its blocks (4 x 4 cells at 2 levels) by this many of the
    scan's points; the beam's lower levels score all of them (None: all at every level). The top
    level is most of the wide search's time (121 angles x 36 blocks)."""
    wide_search_branch_and_bound: bool = False
    """The wide search by exact branch-and-bound from the narrow match (the exhaustive search's
    result) rather than the beam. Off: measured no faster (docs/slam.md, stop 33), and the exact
    optimum moved Intel's rotational error 0.7167 -> 0.7211 deg (translational 0.03389 -> 0.03369 m;
    ACES and FR079 the same to every digit)."""
    match_unobserved_points: bool = False
    """Also match points that land in submap cells no scan has observed yet (False: such points
    are left out; front end and loop closure). A point on a newly seen surface (a wall further
    along at the edge of the range, a room's wall newly visible through a door) has no
    counterpart in the submap, so the likelihood field pulls it onto the nearest mapped cell,
    always on the side already seen: the match lags behind the true motion, and along the
    office corridor this shortened the map by 0.1 m in 25 m (issue 3). The points are chosen
    once, not per candidate (which would favour poses that put them onto mapped cells): at the
    prediction, or at a first match with all points when that lands more than a cell / 1 deg
    away (slip, lagging odometry); then the scan is matched again from the prediction."""
    unobserved_points_at_prediction: bool = False
    """Front end: the points left out as unobserved (``match_unobserved_points`` False) are always
    chosen at the odometry prediction, never at a first match with all points that landed more
    than a cell / 1 deg away. That first match is dragged back by those very points, a cell or two
    at a time; chosen there, they land on observed cells, are kept, and the drag stays: on straight
    office corridors in the simulator (exact odometry) 32 replays gave a slope of -0.103 % mean,
    0.245 % rms, -0.55 % at worst, with this on +0.014 % mean, 0.144 % rms (issue 18,
    docs/benchmarks.md, slamscale34). Off by default: with odometry that lags the laser (FR079's
    155 ms) the prediction is the wrong pose and the first match the right one; the live mapping
    stage pairs odometry at the scan's stamp and turns it on."""
    degeneracy_threshold: float = 0.03
    """Front end: a direction in which the scan's surface normals give less than about this
    fraction of the information of its best-constrained direction takes the position along it
    from the odometry prediction, not from the match (:func:`nav.slam.matcher.fuse_with_prediction`,
    smooth: half-way at the threshold, the match >= 92 % at 0.1). In an aisle between rows longer
    than the lidar's range (the stock greenhouse) or a corridor whose ends are out of range the
    match's score is flat along it, and its noise used to move the robot along the aisle (issue
    16); 0 = off (the match alone, as before)."""
    search_levels: int = 0
    """Front-end coarse-to-fine levels over max-pooled fields (0 = exhaustive search); 2 cost 25 %
    less at equal accuracy on FR079's first 1600 scans (not yet measured on the full logs)."""
    translation_weight: float = 3.0
    """Least-squares pull towards the correlative result, front end and loop closure (the field
    term is a mean over points, as Cartographer's occupied_space_weight / sqrt(N)). Cartographer's
    10 pulls towards its *prediction*; here the target is the search's lattice pose (0.05 m
    steps), and at 10 the prior outweighed the field's curvature, so refined poses stayed near the
    lattice: 3 let FR079's local relations go 0.036 -> 0.033 m, ACES 0.0495 -> 0.046 m."""
    rotation_weight: float = 10.0
    """Least-squares pull towards the correlative heading (0.5 deg lattice); was 40 (Cartographer's
    front end), lowered with ``translation_weight``."""
    loop_search_maximum_distance: float = 8.0
    """Finished submaps whose nodes' centre is within this distance (m) of a node are searched."""
    loop_search_space_dimension: float = 2.0
    """Loop-closure window half-width (m) (slam_toolbox ``loop_search_space_dimension`` 8 = full)."""
    loop_search_angular_window: float = math.radians(20.0)
    """Loop-closure window half-width (rad) (Cartographer constraint builder 30 deg)."""
    loop_search_angular_step: float = math.radians(0.5)
    """Loop-closure angle step (rad)."""
    loop_search_levels: int = 4
    """Coarse-to-fine levels of the loop-closure search (max block 2^levels cells)."""
    loop_match_minimum_response_fine: float = 0.6
    """Minimum mean likelihood (0..1) to accept a loop closure (slam_toolbox 0.45)."""
    loop_search_every_n_nodes: int = 3
    """Only every n-th node is searched for loop closures (Cartographer ``sampling_ratio`` 0.3)."""
    loop_max_candidates: int = 2
    """Nearest finished submaps searched per node."""
    loop_field_cache_size: int = 12
    """Finished submaps whose likelihood field is kept for loop search (least recently searched
    ones release it; it is rebuilt on demand). Bounds memory on long logs."""
    global_search_drift: float = 0.0
    """Pose uncertainty (m) per metre driven since the last accepted loop closure (0 = off, the
    default: see docs/slam.md, "Global loop search", for why it is not on yet). Once it exceeds
    ``loop_search_space_dimension`` a node's closures are searched globally: in every older
    finished submap whose centre is within ``loop_search_maximum_distance`` + the uncertainty (all
    of them once that exceeds the map), over the part of the submap's trajectory within the
    uncertainty of the guess (Cartographer's global constraint search, bounded by the drift)."""
    global_search_angular_drift: float = math.radians(0.1)
    """Heading uncertainty (rad) per metre driven since the last loop closure, added to
    ``loop_search_angular_window`` (at most pi) in a global search."""
    global_search_every_n_nodes: int = 10
    """Only every n-th node is searched globally (Cartographer's global ``sampling_ratio`` is lower;
    a revisit lasts many nodes, so a few searches along it suffice)."""
    global_search_max_candidates: int = 3
    """Submaps searched globally per node: the nearest (by the drifted estimate) but one, and one
    more taken in turn from all the other candidates, so every older submap is searched."""
    global_search_levels: int = 6
    """Coarse-to-fine levels of the global search (max-pooled blocks of 2^6 cells = 3.2 m)."""
    global_search_beam: int = 256
    """Candidates kept per level of the global search."""
    global_match_minimum_score: float = 0.65
    """Minimum mean likelihood of *all* the node's points (none left out) for a global match."""
    global_match_minimum_observed: float = 0.8
    """A global match must put at least this fraction of the points on cells the submap observed."""
    global_ambiguity_separation: float = 1.0
    """A global match is rejected when a candidate more than this far (m) from it ...
    """
    global_ambiguity_margin: float = 0.05
    """... scores within this much (mean likelihood) of it: the scan fits two places equally (a
    corridor seen along its length looks the same a few metres further)."""
    global_agreement_nodes: int = 150
    """A global match is accepted only with a second one, from another node at most this many nodes
    away, that implies the same correction (:func:`nav.slam.loop_closure.proposals_agree`)."""
    global_agreement_translation: float = 0.3
    """Translation tolerance (m) of that agreement."""
    global_agreement_rotation: float = math.radians(2.0)
    """Rotation tolerance (rad) of that agreement."""
    global_max_residual: float = 10.0
    """After optimization an accepted global closure whose Mahalanobis error sqrt(e^T Omega e) is
    still above this (0.2 m at the 0.02 m constraint sigma) fights the rest of the graph: the
    batch's global closures are dropped and the graph optimized without them (chi2 check)."""
    loop_max_residual: float = 10.0
    """After optimization a new local loop closure whose Mahalanobis error sqrt(e^T Omega e) is
    still above this (0.2 m at the 0.02 m constraint sigma) is dropped and the graph optimized
    again without it (0 = off): the rest of the graph does not agree with it (chi2 check)."""
    surface_wins_across_submaps: bool = False
    """Map rendering: a cell any submap holds occupied stays occupied whatever free evidence other
    submaps add (:func:`nav.slam.render.render_submaps`). Off: on the office's full loop it halved
    the free cells left on true walls (62 -> 29; greenhouse 51 -> 50) but it would keep a walker or
    a moved chair that one submap saw in the map for good (docs/slam.md, "No ghost free space")."""
    optimize_every_n_nodes: int = 100
    """Back end optimizes after this many new nodes even without a new loop (Cartographer 90)."""
    constraint_translation_sigma: float = 0.02
    """Std-dev (m) of a scan-to-submap constraint."""
    constraint_rotation_sigma: float = 0.01
    """Std-dev (rad) of a scan-to-submap constraint."""
    odometry_translation_sigma: float = 0.05
    """Std-dev (m) of the front-end chain between consecutive nodes."""
    odometry_rotation_sigma: float = 0.02
    """Std-dev (rad) of the front-end chain between consecutive nodes."""
    huber_delta: float = 3.0
    """Huber threshold (Mahalanobis units) of loop-closure edges."""
    loop_robust_kernel: Literal["huber", "dcs"] = "huber"
    """Robust kernel of loop-closure edges (:class:`nav.slam.pose_graph.PoseGraphOptions`):
    ``huber`` (``huber_delta``) or ``dcs`` (Dynamic Covariance Scaling, ``loop_dcs_phi``)."""
    loop_dcs_phi: float = 9.0
    """DCS's Phi: squared Mahalanobis error up to which a loop edge keeps its full weight."""
    loop_ambiguity_margin: float = 0.0
    """Local loop closures: rejected when a candidate more than ``global_ambiguity_separation`` m
    from the best scores within this much of it (0 = off; the global search always checks)."""
    max_iterations: int = 15
    """Pose-graph Gauss-Newton iterations."""

    odometry_lag_estimation_nodes: int = 150
    """Offline only (:func:`nav.slam.offline.run_offline` with the log's raw odometry): after this
    many nodes the odometry-to-laser time offset is estimated from the data and, if significant,
    the run restarts with odometry interpolated at ``t_scan - lag`` (0 = off)."""
    odometry_lag_minimum: float = 0.02
    """Smaller estimated lags (s) are not worth a restart."""
    odometry_lag_max: float = 0.3
    """Lags searched (s), both signs."""
    heading_drift_time_constant: float = 20.0
    """Odometry heading drift (a gyro's bias, rad/s) is estimated from the matches and removed from
    the prediction; each node's heading correction moves the estimate by ``correction /
    time_constant`` (s; 0 = off). Why: near a correct prediction the likelihood field is flat (its
    Gaussian has no slope at distance 0) and the correlative lattice is 0.5 deg, so a match keeps
    little of a heading offset smaller than that, and a drifting prediction is followed: on the
    office's full loop the skid4 gyro's 0.002 rad/s bias turned into 2.8 deg of front-end heading
    drift and corridor walls built 0.1-0.27 m off (docs/slam.md, "No ghost free space")."""
    heading_drift_max: float = 0.05
    """Bound (rad/s) on the estimated heading drift (an MPU6050's bias after calibration is
    ~0.002-0.01 rad/s): a run of bad matches cannot make the prediction turn by itself."""

    def grid_options(self) -> LogOddsOptions:
        return LogOddsOptions(resolution=self.resolution, grow_margin=2.0)

    def front_end_windows(self) -> tuple[SearchWindow, SearchWindow]:
        """The front end's search window and its wide re-search window."""
        narrow = SearchWindow(
            self.linear_search_window,
            self.angular_search_window,
            self.angular_search_step,
            self.search_levels,
        )
        wide = SearchWindow(
            self.wide_linear_search_window,
            self.wide_angular_search_window,
            self.angular_search_step,
            self.wide_search_levels,
            branch_and_bound=self.wide_search_branch_and_bound,
            top_level_points=self.wide_search_top_level_points,
        )
        return narrow, wide

    def refine_options(self) -> RefineOptions:
        """The front end's (and loop closure's) Gauss-Newton refinement."""
        return RefineOptions(translation_weight=self.translation_weight, rotation_weight=self.rotation_weight)


@dataclass
class _Node:
    stamp: float
    local: Pose2D
    points: np.ndarray  # matching points, base_link frame
    submaps: list[int] = field(default_factory=list)


def _voxel_filter(pts: np.ndarray, size: float, max_points: int) -> np.ndarray:
    """One point per ``size`` cell (first in beam order, so deterministic), then a uniform stride."""
    if pts.shape[0] == 0:
        return pts
    keys = np.floor(pts / size).astype(np.int64)
    _, idx = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    pts = pts[np.sort(idx)]
    if pts.shape[0] > max_points:
        pts = pts[np.linspace(0, pts.shape[0] - 1, max_points).astype(np.int64)]
    return pts


def _dropout_reach(r: np.ndarray, hit: np.ndarray, resolution: float) -> np.ndarray:
    """Per beam: how far a beam without return may clear when a neighbouring beam returned
    (+inf elsewhere). Such a beam is most likely a dropout on the surface its neighbours hit, not a
    view into open space, so it clears up to one cell short of the nearer neighbour's return; a
    run of return-less beams (open space, a doorway) keeps ``missing_data_ray_length``."""
    near = np.where(hit, r, np.inf)
    left = np.concatenate(([np.inf], near[:-1]))
    right = np.concatenate((near[1:], [np.inf]))
    reach = np.minimum(left, right) - resolution
    return np.where(np.isinf(r) & np.isfinite(reach), np.maximum(reach, 0.0), np.inf)


def grazing_shortening(
    pts: np.ndarray, margin: float, neighbours: bool = False, heading_sigma: float = 0.0
) -> np.ndarray:
    """Per return (``pts`` (N, 2) in the laser frame, beam order): how far short of it its ray
    stops clearing, ``margin / sin(a)`` with ``a`` the angle between the beam and the surface it
    hit (the :func:`surface_lines` line through its neighbours; 90 deg, head-on, where there is no
    line: a corner, a post, clutter), at most the whole ray: over that stretch the beam ran within
    ``margin`` of the surface, through cells the surface may cross.

    ``neighbours``: where there is no line, the smaller angle between the beam and the segments to
    the previous and the next return instead of head-on. A face seen at a few degrees from the end
    of an aisle or a corridor has its returns metres apart, and the seven-return window spans the
    gap to the beams that went out of range and the opposite face, so no line fits; a single
    neighbour on the same face still gives its direction. A neighbour on another surface (a depth
    jump) gives a segment near the beam's direction: that ray counts as grazing, which only keeps
    the map view from clearing with it (:attr:`SlamOptions.view_grazing_margin`).

    ``heading_sigma`` (rad): the margin grows by ``range * heading_sigma``, how far a heading error
    of that size moves the ray's end across its surface (a face seen from 5 m is placed to within
    a few centimetres, not half a cell)."""
    if pts.shape[0] == 0 or margin <= 0.0:
        return np.zeros(pts.shape[0])
    r = np.hypot(pts[:, 0], pts[:, 1])
    margin = margin + heading_sigma * r
    along, line = surface_lines(pts)
    sin_a = np.abs(pts[:, 0] * np.sin(along) - pts[:, 1] * np.cos(along)) / np.maximum(r, 1e-9)
    fallback = _neighbour_sin(pts, r) if neighbours else 1.0
    sin_a = np.where(line, sin_a, fallback)
    return np.minimum(margin / np.maximum(sin_a, margin / np.maximum(r, margin)), r)


def _neighbour_sin(pts: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Per return, the smaller |sin| of the angles between its beam and the segments to the previous
    and next return (1 where it has neither)."""
    seg = np.diff(pts, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    cross = np.abs(pts[:-1, 0] * seg[:, 1] - pts[:-1, 1] * seg[:, 0])  # beam i x (p[i+1] - p[i])
    cross_next = np.abs(pts[1:, 0] * seg[:, 1] - pts[1:, 1] * seg[:, 0])  # beam i+1 x the same
    ok = length > 1e-9
    to_next = np.where(ok, cross / np.maximum(r[:-1] * length, 1e-12), 1.0)
    to_prev = np.where(ok, cross_next / np.maximum(r[1:] * length, 1e-12), 1.0)
    out = np.ones(pts.shape[0])
    out[:-1] = to_next
    out[1:] = np.minimum(out[1:], to_prev)
    return out


def _close(a: Pose2D, b: Pose2D, resolution: float) -> bool:
    """Within a cell and a degree of each other."""
    return a.distance_to(b) <= resolution and abs(a.relative_to(b).theta) <= math.radians(1.0)


def _compose_arr(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise SE(2) composition of (N, 3) arrays."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    th = (a[:, 2] + b[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack((a[:, 0] + c * b[:, 0] - s * b[:, 1], a[:, 1] + s * b[:, 0] + c * b[:, 1], th))


class _RowCache:
    """Rows ``f(0), f(1), ...`` (poses as (3,) arrays) computed once each and kept stacked: the
    pose graph's front-end edge measurements, which never change once their nodes exist."""

    def __init__(self) -> None:
        self._stack = np.zeros((0, 3))

    def rows(self, count: int, f: Callable[[int], Pose2D]) -> np.ndarray:
        """(count, 3): the first ``count`` rows, computing the missing ones with ``f``."""
        have = len(self._stack)
        if count > have:
            new = np.array([f(k).as_array() for k in range(have, count)]).reshape(-1, 3)
            self._stack = np.vstack((self._stack, new))
        return self._stack[:count]


class GraphSlam:
    """Graph SLAM over submaps. Deterministic for a given input sequence."""

    def __init__(self, options: SlamOptions | None = None) -> None:
        self.options = options or SlamOptions()
        o = self.options
        self._lock = threading.Lock()
        self._backend_lock = threading.Lock()
        self._window, self._wide_window = o.front_end_windows()
        self._loop_window = SearchWindow(
            o.loop_search_space_dimension,
            o.loop_search_angular_window,
            o.loop_search_angular_step,
            o.loop_search_levels,
            64,
        )
        self._refine = o.refine_options()
        self._nodes: list[_Node] = []
        self._global: list[np.ndarray] = []  # map pose per node
        self._submaps: list[Submap] = []
        self._submap_global: list[np.ndarray] = []
        self._loops: list[LoopCandidate] = []
        self._field_lru: dict[int, None] = {}  # finished submaps holding a field, oldest first
        # front-end edges' measurements, computed once (back end): per submap, its nodes' poses in
        # it; per node i >= 1, its pose relative to node i - 1
        self._sm_rows: dict[int, _RowCache] = {}
        self._chain = _RowCache()
        # per scan (every add_scan call): stamp, reference node, pose relative to that node
        self._scan_stamp: list[float] = []
        self._scan_node: list[int] = []
        self._scan_delta: list[np.ndarray] = []
        self._scan_laser: list[np.ndarray] = []  # laser pose in base_link given with each scan
        self._last_odom: Pose2D | None = None
        self._last_local = Pose2D()
        self._last_node_odom: Pose2D | None = None
        self._last_node_stamp = -math.inf
        self._correction = Pose2D()  # map <- local
        self._heading_drift = 0.0  # estimated odometry heading drift (rad/s), removed from predictions
        self._last_stamp: float | None = None
        self._optimized_upto = 0  # nodes [0, n) have optimized map poses
        self._searched_upto = 0
        self._seen_at: dict[int, int] = {}  # submap -> newest node loop-closed with it (back end)
        self._pending: list[GlobalProposal] = []  # global matches awaiting agreement (back end)
        self._global_turn = 0  # rotates the global search through all candidate submaps
        self.global_closures = 0
        """Global loop closures accepted (confirmed and consistent after optimization)."""
        self.rejected_global = 0
        """Confirmed global closures dropped because the optimized graph did not agree with them."""
        self.rejected_local = 0
        """Local loop closures dropped because the optimized graph did not agree with them."""
        self._map: OccupancyGrid | None = None
        self._map_nodes = -1
        self._render = SubmapRender(o.grid_options(), o.surface_wins_across_submaps)
        self._render_lock = threading.Lock()  # one map render at a time (it keeps a cached sum)
        self.last_score = float("nan")
        self.odometry_lag = 0.0
        """Odometry-to-laser lag (s) the offline driver corrected (informational)."""

    # -- front end ----------------------------------------------------------------------------------
    def add_scan(self, scan: LaserScan, odom_pose: Pose2D, laser_pose: Pose2D = _IDENTITY) -> Pose2D:
        """Process one scan with the odometry pose (odom -> base_link) at its stamp and the laser
        pose in base_link. Returns the map-frame pose of base_link."""
        o = self.options
        with self._lock:
            if self._last_odom is None:
                pred = Pose2D()
            else:
                step = odom_pose.relative_to(self._last_odom)
                dt = float(scan.stamp) - self._last_stamp if self._last_stamp is not None else 0.0
                step = Pose2D(step.x, step.y, step.theta - self._heading_drift * max(dt, 0.0))
                pred = self._last_local.compose(step)
            self._last_odom = odom_pose
            self._last_stamp = float(scan.stamp)
            moved = self._last_node_odom is None or (
                odom_pose.distance_to(self._last_node_odom) >= o.minimum_travel_distance
                or abs(odom_pose.relative_to(self._last_node_odom).theta) >= o.minimum_travel_heading
                or scan.stamp - self._last_node_stamp >= o.minimum_time_interval
            )
            local = pred
            if moved:
                local = self._add_node(scan, pred, laser_pose, odom_pose)
            elif o.match_every_scan:
                local = self._match(self._split(scan, laser_pose)[0], pred, laser_pose)[0]
            self._last_local = local
            ref = len(self._nodes) - 1  # -1: no node yet (scans without returns so far)
            delta = local.relative_to(self._nodes[ref].local) if ref >= 0 else local
            self._scan_stamp.append(float(scan.stamp))
            self._scan_node.append(ref)
            self._scan_delta.append(delta.as_array())
            self._scan_laser.append(laser_pose.as_array())
            return self._map_pose(ref).compose(delta)

    def _split(self, scan: LaserScan, laser_pose: Pose2D) -> tuple[np.ndarray, np.ndarray]:
        o = self.options
        r = scan.ranges
        a = scan.angles
        hit = np.isfinite(r) & (r >= max(o.min_laser_range, scan.range_min)) & (r <= o.max_laser_range)
        miss = ~hit & ~np.isnan(r) & ~(r < max(o.min_laser_range, scan.range_min))
        rm = np.minimum(np.where(np.isfinite(r), r, np.inf), o.max_laser_range)
        rm = np.where(r > o.max_laser_range, np.minimum(rm, o.missing_data_ray_length), rm)
        # a beam without return says nothing beyond the sensor's own range: never clear past it
        rm = np.where(np.isinf(r), min(o.missing_data_ray_length, scan.range_max), rm)
        rm = np.minimum(rm, _dropout_reach(r, hit, o.resolution))
        pts = np.column_stack((r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])))
        misses = np.column_stack((rm[miss] * np.cos(a[miss]), rm[miss] * np.sin(a[miss])))
        return pts, misses

    def _add_node(self, scan: LaserScan, pred: Pose2D, laser_pose: Pose2D, odom_pose: Pose2D) -> Pose2D:
        o = self.options
        pts_laser, misses = self._split(scan, laser_pose)
        if pts_laser.shape[0] < 3:  # nothing to match or insert: dead-reckon on odometry
            return pred
        local, match_pts = self._match(pts_laser, pred, laser_pose)
        self._track_heading_drift(local, pred)
        index = len(self._nodes)
        node = _Node(float(scan.stamp), local, match_pts)
        self._nodes.append(node)
        self._global.append(self._correction.compose(local).as_array())
        self._last_node_odom = odom_pose
        self._last_node_stamp = float(scan.stamp)
        # submap bookkeeping: start a new one when the newest has submap_num_range_data nodes
        if not self._submaps or len(self._submaps[-1].nodes) >= o.submap_num_range_data:
            sm = Submap(
                len(self._submaps), local, o.grid_options(), o.likelihood_sigma, o.view_grazing_margin > 0.0
            )
            self._submaps.append(sm)
            self._submap_global.append(self._correction.compose(local).as_array())
        shorten = grazing_shortening(pts_laser, o.grazing_ray_margin)
        view_shorten = grazing_shortening(
            pts_laser, o.view_grazing_margin, neighbours=True, heading_sigma=o.constraint_rotation_sigma
        )
        for sm in self._submaps[-2:]:  # the older, fuller submap first: it shortens the misses
            if not sm.finished:
                misses = sm.insert(index, local, laser_pose, pts_laser, misses, shorten, view_shorten)
                node.submaps.append(sm.index)
                if len(sm.nodes) >= 2 * o.submap_num_range_data:
                    sm.finished = True
                    sm.release_field()
        return local

    def _track_heading_drift(self, match: Pose2D, pred: Pose2D) -> None:
        """Move the odometry heading-drift estimate by the node's heading correction over the time
        constant (an integrator: it settles where matches no longer correct the prediction's
        heading on average). Poor matches (below the wide-search score) are not trusted."""
        o = self.options
        if o.heading_drift_time_constant <= 0.0 or not self.last_score >= o.wide_search_minimum_score:
            return
        correction = float(wrap_angle(match.theta - pred.theta))
        drift = self._heading_drift - correction / o.heading_drift_time_constant
        self._heading_drift = float(np.clip(drift, -o.heading_drift_max, o.heading_drift_max))

    def _match(self, pts_laser: np.ndarray, pred: Pose2D, laser_pose: Pose2D) -> tuple[Pose2D, np.ndarray]:
        """Front-end pose of a scan (laser-frame hits) predicted at ``pred``, and its matching points."""
        o = self.options
        match_pts = _voxel_filter(
            laser_pose.transform_points(pts_laser), o.voxel_filter_size, o.max_match_points
        )
        target = self._matching_submap()
        if target is None or match_pts.shape[0] < 3:
            return pred, match_pts
        prior = pred.relative_to(target.local_pose)
        window = self._window
        if o.linear_search_window_per_radian > 0:
            turn = abs(pred.relative_to(self._last_local).theta)
            wide = o.linear_search_window + o.linear_search_window_per_radian * turn
            window = replace(window, linear_search_window=wide)
        try:
            if o.match_unobserved_points:
                in_submap, self.last_score = self._search(target, match_pts, prior, window)
            else:
                # Points in cells the submap has not observed have no counterpart in it (a wall
                # further along at the edge of the range, a room newly visible through a door);
                # matched, they are pulled onto the nearest mapped cell, always on the side seen
                # already, and the match lags behind the robot. They are left out, chosen once (not
                # per candidate, which would favour poses that put them onto mapped cells) and the
                # scan matched again from the same prediction. Chosen at the prediction, which is
                # unbiased, unless the first match lands away from it (slip, lagging odometry: the
                # right points would be chosen out), then at that match. Chosen at the prediction
                # always (``unobserved_points_at_prediction``), no first match is needed unless
                # every point (or fewer than 3) is kept.
                first: tuple[Pose2D, float] | None = None
                ref = prior
                if not o.unobserved_points_at_prediction:
                    first = self._search(target, match_pts, prior, window)
                    ref = prior if _close(first[0], prior, o.resolution) else first[0]
                kept = observed_subset(match_pts, target.observed(ref.transform_points(match_pts)))
                if kept is not None:
                    first = self._search(target, kept, prior, window)
                elif first is None:
                    first = self._search(target, match_pts, prior, window)
                in_submap, self.last_score = first
        except ScanMatchError:
            return pred, match_pts
        return target.local_pose.compose(in_submap), match_pts

    def _search(
        self, target: Submap, pts: np.ndarray, prior: Pose2D, window: SearchWindow
    ) -> tuple[Pose2D, float]:
        """Match ``pts`` in ``target`` around ``prior``; a poor fit is searched again in the wide
        window (the prediction may be outside the narrow one: slip, fast turn), the better kept."""
        pose, score = match_scan_with_fallback(
            target.field(),
            pts,
            prior,
            window,
            self._wide_window,
            self.options.wide_search_minimum_score,
            self._refine,
        )
        if self.options.degeneracy_threshold > 0:
            info = translation_information(pts, pose.theta)
            pose = fuse_with_prediction(pose, prior, info, self.options.degeneracy_threshold)
        return pose, score

    def _matching_submap(self) -> Submap | None:
        active = [s for s in self._submaps[-2:] if not s.finished and s.nodes]
        return active[0] if active else None

    def _map_pose(self, node: int) -> Pose2D:
        """Map pose of a node; ``-1`` (before the first node) is the map origin."""
        if node < 0:
            return Pose2D()
        if node < self._optimized_upto:
            return Pose2D.from_array(self._global[node])
        return self._correction.compose(self._nodes[node].local)

    # -- back end -----------------------------------------------------------------------------------
    def optimize_if_due(self) -> bool:
        """Run the back end when enough new nodes arrived; True if it optimized."""
        with self._lock:
            due = len(self._nodes) - self._optimized_upto >= self.options.optimize_every_n_nodes
        return self.run_backend() if due else False

    def run_backend(self) -> bool:
        """Loop-closure search for nodes added since the last call, then pose-graph optimization.
        Safe to call from a worker thread while ``add_scan`` runs; returns True if it optimized."""
        o = self.options
        with self._backend_lock:
            with self._lock:  # snapshot (brief)
                n = len(self._nodes)
                nodes = self._nodes[:n]
                glob = np.array(self._global[:n]) if n else np.zeros((0, 3))
                for k in range(self._optimized_upto, n):
                    glob[k] = self._correction.compose(nodes[k].local).as_array()
                m = len(self._submaps)
                submaps = self._submaps[:m]
                finished = [s.index for s in submaps if s.finished]
                sm_nodes = [list(s.nodes) for s in submaps]
                sm_glob = np.array(self._submap_global[:m]) if m else np.zeros((0, 3))
                start = self._searched_upto
            if n < 2:
                return False
            new_loops, new_global, searched = self._search_loops(
                nodes, glob, submaps, finished, sm_nodes, sm_glob, start, n
            )
            if not new_loops and not new_global and start > 0:
                # No new constraint: the new nodes already satisfy their front-end edges at the
                # current correction, so re-optimizing would barely move anything. Skip it.
                with self._lock:
                    self._searched_upto = n
                    self._global[start:n] = list(glob[start:n])
                    self._optimized_upto = max(self._optimized_upto, n)
                return False
            x0 = np.vstack((glob, sm_glob))
            graph_options = PoseGraphOptions(
                max_iterations=o.max_iterations,
                kernel=o.loop_robust_kernel,
                huber_delta=o.huber_delta,
                dcs_phi=o.loop_dcs_phi,
            )
            edges = self._edges(nodes, submaps, sm_nodes, n, m, self._loops + new_loops + new_global)
            x, _w = optimize_pose_graph(x0, edges, 0, graph_options)
            if new_global and self._global_misfit(x, edges, len(new_global)):
                # the confirmed global closures still fight the rest of the graph: a wrong pair
                # (aliasing) would fold the map, so the batch's global closures are dropped
                self.rejected_global += len(new_global)
                new_global = []
                edges = self._edges(nodes, submaps, sm_nodes, n, m, self._loops + new_loops)
                x, _w = optimize_pose_graph(x0, edges, 0, graph_options)
            if new_loops and o.loop_max_residual > 0:
                # a local closure the optimized graph still cannot satisfy slid along a corridor
                # to where the walls look the same (aliasing the +-2 m window admits); Huber only
                # bounds its pull, and a few of them shifted the office's corridor by 0.05 m
                first = len(edges) - len(new_global) - len(new_loops)
                bad = self._misfits(x, edges, first, len(new_loops), o.loop_max_residual)
                if bad.any():
                    self.rejected_local += int(np.count_nonzero(bad))
                    new_loops = [lc for lc, b in zip(new_loops, bad, strict=True) if not b]
                    edges = self._edges(nodes, submaps, sm_nodes, n, m, self._loops + new_loops + new_global)
                    x, _w = optimize_pose_graph(x0, edges, 0, graph_options)
            with self._lock:  # publish (brief)
                self._loops.extend(new_loops + new_global)
                self.global_closures += len(new_global)
                for lc in new_global:
                    self._seen_at[lc.submap] = max(self._seen_at.get(lc.submap, 0), lc.node)
                self._searched_upto = searched
                self._global[:n] = list(x[:n])
                self._submap_global[:m] = list(x[n:])
                last = nodes[n - 1]
                self._correction = Pose2D.from_array(x[n - 1]).compose(last.local.inverse())
                for k in range(n, len(self._nodes)):
                    self._global[k] = self._correction.compose(self._nodes[k].local).as_array()
                for k in range(m, len(self._submaps)):
                    self._submap_global[k] = self._correction.compose(self._submaps[k].local_pose).as_array()
                self._optimized_upto = n
            return True

    def _search_loops(
        self,
        nodes: list[_Node],
        glob: np.ndarray,
        submaps: list[Submap],
        finished: list[int],
        sm_nodes: list[list[int]],
        sm_glob: np.ndarray,
        start: int,
        n: int,
    ) -> tuple[list[LoopCandidate], list[LoopCandidate], int]:
        """Loop closures for nodes ``[start, n)`` against finished submaps (snapshot data): the ones
        found by the local search of nearby submaps, the global ones that were confirmed, and the
        node the search stopped before (``n``, or just after the first confirmed global ones)."""
        o = self.options
        if not finished:
            return [], [], n
        fin = np.array(finished)
        centres = np.array([glob[sm_nodes[j]][:, :2].mean(axis=0) for j in finished])
        path = np.zeros(0)  # distance driven up to each node: only the global search needs it
        if o.global_search_drift > 0:
            local_xy = np.array([nd.local.as_array()[:2] for nd in nodes])
            path = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(local_xy, axis=0).T))))
        found: list[LoopCandidate] = []
        agreed: list[LoopCandidate] = []
        for i in range(start, n):
            local_due = i % o.loop_search_every_n_nodes == 0
            global_due = o.global_search_drift > 0 and i % o.global_search_every_n_nodes == 0
            if not (local_due or global_due):
                continue
            d = np.hypot(*(centres - glob[i, :2]).T)
            # not its own submaps nor the ones just before and just after them (the one before
            # shares the older one's first half of the scans, the one after starts a few nodes
            # later): a match there is no loop, the node sits at that submap's thin edge and
            # the front end's chain already ties the two. On the office corridor the previous
            # one's matches pulled the far end back by up to 0.1 m; on MIT Killian the next
            # one's were 216 of 2159 closures and 128 of them still fought the optimized graph
            # (Mahalanobis error > 10, up to 4 m off), most of them slid along a corridor
            mine = set(nodes[i].submaps)
            if mine:
                mine |= {min(mine) - 1, max(mine) + 1}
            eligible = ~np.isin(fin, list(mine))
            uncertainty = (
                o.global_search_drift * self._path_since_seen(path, i, fin, sm_nodes)
                if o.global_search_drift > 0
                else np.zeros(len(fin))
            )
            if local_due:
                # the local window only covers a small drift: where it may be larger, a match in
                # it is as likely the corridor's next door as the right one (only the global
                # search, with its agreement check, looks there)
                near = eligible & (d <= o.loop_search_maximum_distance)
                if o.global_search_drift > 0:
                    near &= uncertainty <= o.loop_search_space_dimension
                order = [k for k in np.argsort(d, kind="stable") if near[k]]
                for k in order[: o.loop_max_candidates]:
                    j = int(fin[k])
                    guess = Pose2D.from_array(glob[i]).relative_to(Pose2D.from_array(sm_glob[j]))
                    cand = find_loop_closure(
                        submaps[j],
                        i,
                        nodes[i].points,
                        guess,
                        self._loop_window,
                        o.loop_match_minimum_response_fine,
                        self._refine,
                        o.match_unobserved_points,
                        ambiguity=(
                            (o.global_ambiguity_separation, o.loop_ambiguity_margin)
                            if o.loop_ambiguity_margin > 0
                            else None
                        ),
                    )
                    if cand is not None:
                        found.append(cand)
                        self._seen_at[j] = i
                    self._keep_field(submaps, j)
            if global_due:
                agreed.extend(
                    self._search_global(
                        i, nodes, glob, submaps, fin, sm_nodes, sm_glob, d, eligible, uncertainty
                    )
                )
                if agreed:
                    # the later nodes' estimates are metres off until the graph is optimized with
                    # these closures: they are searched in the next round, from corrected poses
                    return found, agreed, i + 1
        return found, agreed, n

    def _path_since_seen(
        self, path: np.ndarray, i: int, fin: np.ndarray, sm_nodes: list[list[int]]
    ) -> np.ndarray:
        """Per finished submap ``j``: the path length (m) whose drift separates node ``i`` from it,
        ``min_k (path since k was last seen) + (path between k's and j's centres)`` over every
        finished submap ``k`` (k = j: straight back along the trajectory; else through the last
        loop closure with k, one shortcut)."""
        centre = np.array([path[sm_nodes[j]].mean() for j in fin])
        seen = np.array([path[max(self._seen_at.get(int(j), sm_nodes[j][-1]), sm_nodes[j][-1])] for j in fin])
        since = np.maximum(path[i] - seen, 0.0)
        return np.min(since[:, None] + np.abs(centre[:, None] - centre[None, :]), axis=0)

    def _search_global(
        self,
        i: int,
        nodes: list[_Node],
        glob: np.ndarray,
        submaps: list[Submap],
        fin: np.ndarray,
        sm_nodes: list[list[int]],
        sm_glob: np.ndarray,
        d: np.ndarray,
        eligible: np.ndarray,
        uncertainty: np.ndarray,
    ) -> list[LoopCandidate]:
        """Global search of node ``i`` in the submaps it may be in given ``uncertainty`` (m, per
        finished submap) beyond what the local search covers; returns closures confirmed by a
        second, agreeing one (both)."""
        o = self.options
        wide = eligible & (uncertainty > o.loop_search_space_dimension)
        wide &= d <= o.loop_search_maximum_distance + uncertainty
        order = np.flatnonzero(wide)[np.argsort(d[wide], kind="stable")]
        near = o.global_search_max_candidates - 1
        picked = list(order[:near])
        if len(order) > near:
            picked.append(order[near + self._global_turn % (len(order) - near)])
            self._global_turn += 1
        self._pending = [p for p in self._pending if i - p.candidate.node <= o.global_agreement_nodes]
        confirmed: list[LoopCandidate] = []
        pts = nodes[i].points
        for k in picked:
            j = int(fin[k])
            sm = submaps[j]
            guess = Pose2D.from_array(glob[i]).relative_to(Pose2D.from_array(sm_glob[j]))
            node_xy = np.array(
                [nodes[q].local.relative_to(sm.local_pose).as_array()[:2] for q in sm_nodes[j]]
            )
            region = global_search_region(node_xy, guess, float(uncertainty[k]))
            if region is None:
                continue
            prior, half = region
            turn = o.global_search_angular_drift * float(uncertainty[k]) / o.global_search_drift
            window = SearchWindow(
                half,
                min(math.pi, o.loop_search_angular_window + turn),
                o.loop_search_angular_step,
                o.global_search_levels,
                o.global_search_beam,
            )
            cand = find_loop_closure(
                sm,
                i,
                pts,
                prior,
                window,
                o.global_match_minimum_score,
                self._refine,
                ambiguity=(o.global_ambiguity_separation, o.global_ambiguity_margin),
            )
            self._keep_field(submaps, j)
            if cand is None or observed_fraction(sm, pts, cand.relative) < o.global_match_minimum_observed:
                continue
            implied = Pose2D.from_array(sm_glob[j]).compose(cand.relative).as_array()
            proposal = GlobalProposal(cand, implied, glob[i])
            partners = [
                p
                for p in self._pending
                if p.candidate.node != i
                and proposals_agree(p, proposal, o.global_agreement_translation, o.global_agreement_rotation)
            ]
            if not partners:
                self._pending.append(proposal)
                continue

            confirmed.extend(p.candidate for p in [*partners, proposal])
            self._pending = [p for p in self._pending if p not in partners]
        return confirmed

    def _global_misfit(self, x: np.ndarray, edges: EdgeSet, count: int) -> bool:
        """Whether any of the last ``count`` edges (the new global closures) has a Mahalanobis
        error above ``global_max_residual`` at the optimized poses ``x``."""
        first = len(edges) - count
        return bool(self._misfits(x, edges, first, count, self.options.global_max_residual).any())

    @staticmethod
    def _misfits(x: np.ndarray, edges: EdgeSet, first: int, count: int, limit: float) -> np.ndarray:
        """(count,) bool: edges ``[first, first + count)`` whose Mahalanobis error sqrt(e^T Omega e)
        at the optimized poses ``x`` is above ``limit``."""
        part = slice(first, first + count)
        sub = EdgeSet(*(a[part] for a in (edges.i, edges.j, edges.z, edges.sqrt_info, edges.robust)))
        return np.sqrt(np.sum((edge_errors(x, sub) * sub.sqrt_info) ** 2, axis=1)) > limit

    def _keep_field(self, submaps: list[Submap], j: int) -> None:
        """Finished submaps keep their (pooled) likelihood field for the next loop searches, which
        mostly hit the same few nearby submaps; beyond ``loop_field_cache_size`` the least recently
        searched one drops it (a field with its pooled levels is 4x the submap's grid in memory,
        which on Intel would pass 1 GB). Back-end thread only."""
        self._field_lru.pop(j, None)
        self._field_lru[j] = None
        while len(self._field_lru) > self.options.loop_field_cache_size:
            old = next(iter(self._field_lru))
            del self._field_lru[old]
            submaps[old].release_field()

    def _edges(
        self,
        nodes: list[_Node],
        submaps: list[Submap],
        sm_nodes: list[list[int]],
        n: int,
        m: int,
        loops: list[LoopCandidate],
    ) -> EdgeSet:
        """Graph edges: node-in-submap (front end), consecutive nodes, and robust loop closures.
        Variables are the n nodes followed by the m submaps. The front-end edges' measurements
        depend only on front-end poses, which never change, so each is computed once and cached
        (back-end thread only): rebuilding them every optimization cost O(n) Python per call."""
        o = self.options
        c_info = [1 / o.constraint_translation_sigma] * 2 + [1 / o.constraint_rotation_sigma]
        o_info = [1 / o.odometry_translation_sigma] * 2 + [1 / o.odometry_rotation_sigma]
        sm_i, sm_j, sm_z = [], [], []
        for j in range(m):
            rows = self._sm_rows.setdefault(j, _RowCache())
            members = sm_nodes[j]
            count = bisect_left(members, n)  # a submap's nodes are in increasing order
            pose = submaps[j].local_pose
            z = rows.rows(
                count, lambda k, members=members, pose=pose: nodes[members[k]].local.relative_to(pose)
            )
            sm_i.append(np.full(count, n + j, dtype=np.int64))
            sm_j.append(np.asarray(members[:count], dtype=np.int64))
            sm_z.append(z)
        chain = self._chain.rows(n - 1, lambda k: nodes[k + 1].local.relative_to(nodes[k].local))
        k_sm = sum(len(a) for a in sm_i)
        ii = np.concatenate(
            (*sm_i, np.arange(n - 1), np.array([n + lc.submap for lc in loops], dtype=np.int64))
        )
        jj = np.concatenate((*sm_j, np.arange(1, n), np.array([lc.node for lc in loops], dtype=np.int64)))
        zz = np.vstack((*sm_z, chain, np.array([lc.relative.as_array() for lc in loops]).reshape(-1, 3)))
        ww = np.repeat(np.array([c_info, o_info, c_info]), [k_sm, n - 1, len(loops)], axis=0)
        rb = np.concatenate((np.zeros(k_sm + n - 1, dtype=bool), np.ones(len(loops), dtype=bool)))
        return EdgeSet(ii, jj, zz, ww, rb)

    # -- outputs ------------------------------------------------------------------------------------
    def map(self) -> OccupancyGrid:
        """The global occupancy grid, re-rendered from the submaps at their latest map poses
        (incrementally: :class:`nav.slam.render.SubmapRender`, equal to
        :func:`nav.slam.render.render_submaps`)."""
        with self._render_lock:
            with self._lock:
                n = len(self._nodes)
                if self._map is not None and self._map_nodes == n:
                    return self._map
                poses = np.array(self._submap_global, dtype=float).reshape(-1, 3)
                finished = next(
                    (j for j, sm in enumerate(self._submaps) if not sm.finished), len(self._submaps)
                )
                kept = self._render.kept(poses)
                layers = self._submap_layers(kept, finished, view=True)
            out = self._render.render(poses, finished, layers).to_occupancy_grid()
            with self._lock:
                self._map, self._map_nodes = out, n
            return out

    def evidence_map(self) -> OccupancyGrid:
        """The submaps placed at their latest map poses by plain nearest-neighbour resampling,
        without :meth:`map`'s "surface wins" widening of every surface: what map-consistency checks
        read (:func:`nav.slam.consistency.slam_see_through_rate`), so that they judge the poses
        and not the display rule. Not cached (offline evaluation)."""
        with self._lock:
            grids = self._submap_layers()
        return render_submaps(grids, self.options.grid_options(), surface_wins=False).to_occupancy_grid()

    def _submap_layers(self, first: int = 0, finished: int = 0, view: bool = False) -> list[SubmapLayer]:
        """The submaps from ``first`` on with their map poses (caller holds the lock); the grids of
        the first ``finished`` submaps, which no scan changes any more, by reference, the others
        copied. ``view``: the log-odds as users see them (:func:`nav.slam.render.view_logodds`, always
        a new array), else the plain evidence."""
        l_occ = self.options.grid_options().l_occ
        return [
            (
                Pose2D.from_array(self._submap_global[j]),
                sm.grid.origin.copy(),
                view_logodds(sm.grid.logodds, sm.grid.view, l_occ)
                if view
                else (sm.grid.logodds if j < finished else sm.grid.logodds.copy()),
                sm.grid.seen if j < finished else sm.grid.seen.copy(),
            )
            for j, sm in enumerate(self._submaps[first:], start=first)
        ]

    def trajectory(self, sensor: bool = False) -> np.ndarray:
        """(N, 4) ``t, x, y, theta`` of base_link in the map frame, one row per ``add_scan`` call.

        ``sensor=True``: the laser's pose instead (base_link composed with the ``laser_pose`` given
        with that scan). Scan matching estimates the laser's pose; ground truth derived from the
        scans themselves, such as the Freiburg benchmark relations, is in that frame (it differs
        from base_link only when the laser is mounted off the base's origin: FR079, 0.04 m)."""
        with self._lock:
            if not self._scan_stamp:
                return np.zeros((0, 4))
            ref = np.array(self._scan_node)
            base = np.array([self._map_pose(k).as_array() for k in range(-1, len(self._nodes))])
            poses = _compose_arr(base[ref + 1], np.array(self._scan_delta))
            if sensor:
                poses = _compose_arr(poses, np.array(self._scan_laser))
            return np.column_stack((np.array(self._scan_stamp), poses))

    def front_end_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (n,) and front-end (local frame) poses (n, 3) of the graph's nodes."""
        with self._lock:
            stamps = np.array([nd.stamp for nd in self._nodes], dtype=float)
            poses = np.array([nd.local.as_array() for nd in self._nodes], dtype=float).reshape(-1, 3)
        return stamps, poses

    def node_poses(self) -> np.ndarray:
        """(n, 3) map poses of the graph's scan nodes."""
        with self._lock:
            return np.array([self._map_pose(k).as_array() for k in range(len(self._nodes))]).reshape(-1, 3)

    def loop_closure_edges(self) -> np.ndarray:
        """(E, 2, 2) segments from each loop-closed submap's origin to its node (map frame), for display."""
        with self._lock:
            segs = [
                (self._submap_global[lc.submap][:2], self._map_pose(lc.node).as_array()[:2])
                for lc in self._loops
            ]
        return np.array(segs, dtype=float).reshape(-1, 2, 2)

    def map_to_odom(self) -> Pose2D:
        """map -> odom transform: map pose of base_link composed with the inverse odometry pose."""
        with self._lock:
            if not self._scan_stamp or self._last_odom is None:
                return Pose2D()
            ref = self._scan_node[-1]
            base = self._map_pose(ref).compose(Pose2D.from_array(self._scan_delta[-1]))
            return base.compose(self._last_odom.inverse())

    @property
    def num_nodes(self) -> int:
        return len(self._nodes)

    @property
    def unsearched_nodes(self) -> int:
        """Nodes not yet searched for loop closures by the back end."""
        with self._lock:
            return len(self._nodes) - self._searched_upto

    @property
    def num_loop_closures(self) -> int:
        return len(self._loops)
