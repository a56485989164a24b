"""``navdeck bench peers``: navdeck's kernels side by side with the libraries a user would pick
instead (issue 20). Install the peers with ``pip install -e .[peers]``; every peer import is
optional here (a missing peer prints "not installed" and the other rows still run), and nothing
outside ``bench/`` imports a peer.

Method: each pair runs in this one process, the two sides alternating (which one goes first flips
every round, so neither always sees a warm or a cold cache), after one warm-up call of each (numba
load, peer set-up); each figure is the median wall time of ``ROUNDS`` rounds.

A* inputs: the Willow Garage floor (navigation_stage/willow-full-0.05, 0.2 m robot inflation,
opposite extreme cells of the largest free region), a 2000 x 2000 grid with 20 % random blocked
cells (seed 0, corner to corner) and 20 MovingAI den312d scenarios (the first 20 of
``den312d-random-1.scen``, whose optimal octile lengths are checked; each round plans them
``SCENARIO_PASSES`` times). Both sides get the same
traversability with unit cell weight; navdeck runs the kernel the planner picks
(``nav.planning.kernel``: on these uniform-cost grids the canonical-ordering one; exact octile,
no corner cutting, path traced), pyastar2d runs ``astar_path(..., allow_diagonal=True)`` (a
diagonal step costs 1 and blocked corners may be cut: an easier problem).

Scan matching inputs (Intel Research Lab log, 180-beam laser at base_link's origin): 50 consecutive
scan pairs (from scan ``CONSECUTIVE_START``) and the first 50 ground-truth relations of
``intel.relations`` whose heading change is below ``RELATION_MAX_TURN`` (larger motion, seconds
apart: the two 180 deg scans still overlap). The current scan is matched against the reference
scan alone, from the odometry prior. Both sides use the same 0.05 m grid and the same range limit
(``MATCH_RANGE``, navdeck's ``max_laser_range`` and slam_toolbox's default); each side builds its
own grid from the reference scan inside the timed call. navdeck: ``LikelihoodField.from_points`` of
the reference's returns, the current scan's points the reference did not observe left out (chosen
at the prior, ``nav.slam.coverage.observed_by_scan``, as the live front end leaves out points its
submap has not observed), then ``match_scan_with_fallback`` with the SLAM front end's windows
(+-0.1 m / +-10 deg at 0.5 deg; below score 0.6 again in +-0.5 m / +-30 deg); karto-scanmatcher
(OpenKarto's ScanMatcher): its defaults (+-0.15 m, +-20 deg coarse at 2 deg, fine at 0.2 deg,
smear 0.03 m, distance / angle penalties) at resolution 0.05, ``match_scan(scan, [reference],
penalize=True, refine=True)``. Accuracy on the relation pairs: translational error of each side's
estimate against the relation (Kuemmerle et al. 2009's ``|translation(z^-1 d)|``).
"""

from __future__ import annotations

import contextlib
import importlib
import math
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

from bench import pythonrobotics_dwa as prd
from bench.amcl import LASER_POSE, load_map, synth_scans
from bench.amcl import WILLOW as WILLOW_01
from bench.core import Benchmark, Figure
from bench.datasets import MOVINGAI, ROS_MAPS, SLAM_BENCHMARK
from bench.planning import _component_corners, _real_map_costmap
from nav.control import DwaController, DwaOptions, NoValidControl
from nav.costmap.inflation import InflationOptions, inflate
from nav.localization import Amcl, AmclOptions
from nav.planning.kernel import octile_search
from nav.slam.metric import parse_relations, relative_poses
from nav.slam.scan_to_scan import ScanToScanMatcher
from nav.slam.system import SlamOptions
from nav.types import LETHAL_OBSTACLE, Costmap, GridGeometry, LaserScan, OccupancyGrid, Pose2D, Twist2D
from nav.types import Path as NavPath
from robot.clock import VirtualClock
from robot.logs.reader import load_raw_log
from robot.profiles import load_profile
from robot.sim import SimDriver, SimOptions, World

ROUNDS = 7
# a round of 50 scan matches is ~10-15 ms, so the shared machine's noise moves 7 rounds' median
# by ~5 % (stop 38: one build's relation-pair ratio 1.04-1.17 over three runs); 31 rounds cost ~1 s
MATCH_ROUNDS = 31
WILLOW = ROS_MAPS / "navigation_stage/willow-full-0.05.yaml"
DEN312D = MOVINGAI / "mapf/den312d"
SCENARIOS = 20
# A round plans the den312d scenarios this many times: one pass lasts ~1 ms, the length of a
# scheduler time slice, so on a loaded machine single passes gave medians 4x apart between runs.
SCENARIO_PASSES = 10
INTEL_BAG = SLAM_BENCHMARK / "bags/intel.orig.bag"
INTEL_RELATIONS = SLAM_BENCHMARK / "relations/intel.relations"
PAIRS = 50
CONSECUTIVE_START = 100
"""First scan of the consecutive pairs (the robot is moving there)."""
RELATION_MAX_TURN = math.radians(45.0)
MATCH_RANGE = 20.0
MOVINGAI_PASSABLE = frozenset(".GS")  # MovingAI map legend: '.', 'G', 'S' passable; '@', 'O', 'T', 'W' not


@dataclass
class Row:
    kernel: str
    navdeck_ms: float | None
    peer: str
    peer_ms: float | None
    note: str = ""
    extra: tuple[Figure, ...] = ()  # figures of the row beyond the two times and their ratio

    @property
    def ratio(self) -> float | None:
        if self.navdeck_ms is None or not self.peer_ms:
            return None
        return self.navdeck_ms / self.peer_ms


def optional_import(name: str) -> ModuleType | None:
    """The peer module, or None if it is not installed (or fails to import)."""
    try:
        return importlib.import_module(name)
    except Exception:  # a broken peer install must not stop the other rows
        return None


# The peers, imported once at module level; a missing or broken one is None and only its row is
# skipped (see optional_import).
PYASTAR2D = optional_import("pyastar2d")
KARTO = optional_import("karto_scanmatcher")
REPORTED_PEERS = {name: optional_import(name) for name in ("amcl", "irsim")}
MPIMG = optional_import("matplotlib.image")  # installed with ir-sim; writes its image map


def alternating_medians(
    ours: Callable[[], object], theirs: Callable[[], object], rounds: int = ROUNDS
) -> tuple[float, float]:
    """Median wall ms of each side over ``rounds`` alternating rounds, after one warm-up each."""
    ours()
    theirs()
    a: list[float] = []
    b: list[float] = []
    for k in range(rounds):
        order = ((ours, a), (theirs, b)) if k % 2 == 0 else ((theirs, b), (ours, a))
        for fn, out in order:
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
    return statistics.median(a) * 1e3, statistics.median(b) * 1e3


# --- A* inputs -----------------------------------------------------------------------------------


def random_grid(size: int = 2000, blocked: float = 0.2, seed: int = 0) -> np.ndarray:
    """(size, size) bool passable grid, ``blocked`` fraction of random blocked cells; corners free."""
    free = np.random.default_rng(seed).random((size, size)) >= blocked
    free[0, 0] = free[-1, -1] = True
    return free


def load_movingai_map(path: Path) -> np.ndarray:
    """A MovingAI ``.map`` file as a (height, width) bool passable grid."""
    lines = path.read_text().splitlines()
    start = lines.index("map") + 1
    rows = [line.rstrip("\n") for line in lines[start:] if line.strip()]
    return np.array([[ch in MOVINGAI_PASSABLE for ch in row] for row in rows], dtype=bool)


def load_scenarios(path: Path, count: int) -> list[tuple[tuple[int, int], tuple[int, int], float]]:
    """The first ``count`` scenarios as ((row, col) start, (row, col) goal, optimal octile length)."""
    out = []
    for line in path.read_text().splitlines()[1 : count + 1]:
        f = line.split("\t")
        sx, sy, gx, gy = (int(v) for v in f[4:8])
        out.append(((sy, sx), (gy, gx), float(f[8])))
    return out


def willow_grid() -> tuple[np.ndarray, tuple[int, int], tuple[int, int]]:
    cm = _real_map_costmap(WILLOW, 0.2)
    s, g = _component_corners(cm)
    rs, cs = cm.geometry.world_to_cell(np.array([[s.x, s.y], [g.x, g.y]]))
    return cm.costs < 253, (int(rs[0]), int(cs[0])), (int(rs[1]), int(cs[1]))


def navdeck_astar(passable: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """Exact octile A* path cost start -> goal (the kernel the planner picks for a uniform-cost grid,
    which also traces the path as pyastar2d does); inf if unreachable."""
    return octile_search(passable, start, goal)[0]


def _astar_rows(pyastar2d: ModuleType | None) -> list[Row]:
    def pair(passable: np.ndarray, jobs: list[tuple[tuple[int, int], tuple[int, int]]]) -> tuple:
        weights = np.where(passable, 1.0, np.inf).astype(np.float32)

        def ours() -> None:
            for s, g in jobs:
                navdeck_astar(passable, s, g)

        def theirs() -> None:
            for s, g in jobs:
                pyastar2d.astar_path(weights, s, g, allow_diagonal=True)

        if pyastar2d is None:
            ours()
            times = []
            for _ in range(ROUNDS):
                t = time.perf_counter()
                ours()
                times.append(time.perf_counter() - t)
            return statistics.median(times) * 1e3, None
        return alternating_medians(ours, theirs)

    rows: list[Row] = []
    peer = "pyastar2d" if pyastar2d is not None else "pyastar2d (not installed)"
    if WILLOW.exists():
        passable, s, g = willow_grid()
        a, b = pair(passable, [(s, g)])
        rows.append(Row("A*, Willow Garage 0.05 m map corner to corner", a, peer, b))
    else:
        rows.append(Row("A*, Willow Garage map", None, peer, None, f"{WILLOW} missing"))
    grid = random_grid()
    a, b = pair(grid, [((0, 0), (grid.shape[0] - 1, grid.shape[1] - 1))])
    rows.append(Row("A*, 2000 x 2000, 20 % random obstacles (seed 0)", a, peer, b))
    den_map = DEN312D / "den312d.map"
    if den_map.exists():
        passable = load_movingai_map(den_map)
        scen = load_scenarios(DEN312D / "den312d-random-1.scen", SCENARIOS)
        exact = sum(abs(navdeck_astar(passable, s, g) - opt) < 1e-4 for s, g, opt in scen)
        a, b = pair(passable, [(s, g) for s, g, _ in scen] * SCENARIO_PASSES)
        plans = len(scen) * SCENARIO_PASSES
        rows.append(
            Row(
                f"A*, {len(scen)} MovingAI den312d scenarios, per plan",
                a / plans,
                peer,
                None if b is None else b / plans,
                f"navdeck optimal on {exact}/{len(scen)}",
            )
        )
    else:
        rows.append(Row("A*, MovingAI den312d", None, peer, None, f"{DEN312D} missing"))
    return rows


# --- scan matching -------------------------------------------------------------------------------

MatchPair = tuple[LaserScan, LaserScan, Pose2D]  # reference, current, odometry prior (current in ref)


def _scan_points(scan: LaserScan) -> np.ndarray:
    r = scan.ranges
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= MATCH_RANGE)
    a = scan.angles[ok]
    return np.column_stack((r[ok] * np.cos(a), r[ok] * np.sin(a)))


class NavdeckScanMatcher:
    """navdeck's scan-to-scan match (:class:`nav.slam.scan_to_scan.ScanToScanMatcher`): the
    reference's likelihood field, then the front end's search (narrow window, the wide one below
    the front end's score threshold) and refinement."""

    def __init__(self) -> None:
        self.matcher = ScanToScanMatcher(SlamOptions(), MATCH_RANGE)

    def match(self, scan: LaserScan, reference: np.ndarray, current: np.ndarray, prior: Pose2D) -> Pose2D:
        """``current``'s pose in the frame of ``scan`` (whose returns are ``reference``)."""
        return self.matcher.match(scan, reference, current, prior)[0]


class KartoScanMatcher:
    """karto-scanmatcher (OpenKarto's ScanMatcher via pybind11) on the same scans."""

    def __init__(self, karto: ModuleType, scan: LaserScan) -> None:
        self.k = karto
        cfg = karto.ScanMatcherConfig()
        cfg.resolution = SlamOptions().resolution
        cfg.range_threshold = MATCH_RANGE
        self.wrapper = karto.Wrapper(cfg)
        n = scan.ranges.shape[0]
        self.laser = karto.LaserScanConfig(
            float(scan.angle_min),
            float(scan.angle_min + scan.angle_increment * (n - 1)),
            float(scan.angle_increment),
            float(scan.range_min),
            float(scan.range_max),
            MATCH_RANGE,
            "laser",
        )

    def scan(self, scan: LaserScan, pose: Pose2D, num: int) -> object:
        # karto ignores readings beyond range_threshold: no return / invalid -> beyond it
        r = np.where(np.isfinite(scan.ranges), scan.ranges, MATCH_RANGE + 1.0)
        p = self.k.Pose2(pose.x, pose.y, pose.theta)
        return self.k.LocalizedRangeScan(self.laser, r.astype(float).tolist(), p, p, num, float(scan.stamp))

    def match(self, reference: object, current: object) -> Pose2D:
        result = self.wrapper.match_scan(current, [reference], True, True)
        b = result.best_pose
        return Pose2D(b.x, b.y, b.yaw)


def intel_pairs() -> tuple[list[MatchPair], list[MatchPair], np.ndarray]:
    """(consecutive pairs, relation pairs, the relation pairs' true relative poses (N, 3))."""
    raw = load_raw_log(INTEL_BAG)
    recs = raw.records()
    stamps = np.array([float(r.scan.stamp) for r in recs])
    consecutive = [
        (recs[k].scan, recs[k + 1].scan, recs[k + 1].odom.relative_to(recs[k].odom))
        for k in range(CONSECUTIVE_START, CONSECUTIVE_START + PAIRS)
    ]
    related, truth = [], []
    for t1, t2, x, y, yaw in parse_relations(INTEL_RELATIONS.read_text()):
        if abs(yaw) >= RELATION_MAX_TURN:
            continue
        i, j = np.searchsorted(stamps, [t1, t2])
        if j >= len(stamps) or abs(stamps[i] - t1) > 1e-3 or abs(stamps[j] - t2) > 1e-3:
            continue
        related.append((recs[i].scan, recs[j].scan, recs[j].odom.relative_to(recs[i].odom)))
        truth.append((x, y, yaw))
        if len(related) == PAIRS:
            break
    return consecutive, related, np.array(truth)


def _match_rows(karto: ModuleType | None) -> list[Row]:
    if not (INTEL_BAG.exists() and INTEL_RELATIONS.exists()):
        return [Row("scan matching, Intel", None, "karto-scanmatcher", None, f"{INTEL_BAG} missing")]
    consecutive, related, truth = intel_pairs()
    ours = NavdeckScanMatcher()
    theirs = KartoScanMatcher(karto, consecutive[0][0]) if karto is not None else None
    return [
        _match_row("scan-to-scan match, 50 consecutive Intel pairs", consecutive, None, ours, theirs),
        _match_row(
            "scan match, 50 ground-truth relation pairs (larger motion)", related, truth, ours, theirs
        ),
    ]


def _match_row(
    label: str,
    pairs: list[MatchPair],
    truth: np.ndarray | None,
    ours: NavdeckScanMatcher,
    theirs: KartoScanMatcher | None,
) -> Row:
    """Per-match median time of both sides over ``pairs``; with ``truth``, their accuracy."""
    pts = [(a, _scan_points(a), _scan_points(b), prior) for a, b, prior in pairs]
    estimates: dict[str, list[Pose2D]] = {}

    def run_ours() -> None:
        estimates["navdeck"] = [ours.match(scan, ref, cur, prior) for scan, ref, cur, prior in pts]

    if theirs is not None:
        kscans = [(theirs.scan(a, Pose2D(), 0), theirs.scan(b, prior, 1)) for a, b, prior in pairs]

        def run_theirs() -> None:
            estimates["karto"] = [theirs.match(ref, cur) for ref, cur in kscans]

        a_ms, b_ms = alternating_medians(run_ours, run_theirs, MATCH_ROUNDS)
    else:
        a_ms, b_ms = _single(run_ours), None
    note = "per match"
    if truth is not None:
        err = {
            side: np.hypot(*relative_poses(truth, np.array([p.as_array() for p in est]))[:, :2].T)
            for side, est in estimates.items()
        }
        note += f"; error to truth: navdeck {100 * err['navdeck'].mean():.2f} cm mean"
        if "karto" in err:
            closer = int(np.count_nonzero(err["navdeck"] < err["karto"]))
            note += (
                f", worst {100 * err['navdeck'].max():.1f} cm; karto {100 * err['karto'].mean():.2f} cm, "
                f"worst {100 * err['karto'].max():.1f} cm; navdeck closer on {closer}/{len(pairs)}"
            )
    n = len(pairs)
    peer = "karto-scanmatcher" if theirs is not None else "karto-scanmatcher (not installed)"
    return Row(label, a_ms / n, peer, None if b_ms is None else b_ms / n, note)


# --- AMCL, DWA and simulator rows ------------------------------------------------------------------

AMCL_PARTICLES = 2000
DWA_SIZE_ROUNDS = 101
SIM_ROUNDS = 31  # a step is ~1 ms: more rounds than ROUNDS against the shared machine's noise
# An update is ~15-20 ms of CPU, 60-120 ms of wall time on the loaded 2-core machine: 7 rounds
# gave beam-model ratios 0.88-1.12 for one build, so this row takes more
AMCL_ROUNDS = 31
AMCL_TRUTH = np.array([[14.0, 33.0, 0.3], [14.1, 33.0, 0.3]])  # a room of Willow Garage (0.1 m map)


def _single(fn: Callable[[], object]) -> float:
    """Median wall ms of ``ROUNDS`` calls after one warm-up (a row whose peer is missing)."""
    fn()
    times = []
    for _ in range(ROUNDS):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def _amcl_rows(amcl: ModuleType | None) -> list[Row]:
    """One full filter update (motion, measurement, resampling) of 2000 particles x 60 beams on
    Willow Garage (0.1 m cells) per side, both with Nav2's default model parameters. The PyPI
    ``amcl`` binary binds Nav2's BeamModel only, so the likelihood-field row has no peer here."""

    if not WILLOW_01.exists():
        return [Row("AMCL update", None, "Nav2 AMCL", None, f"{WILLOW_01} missing")]
    grid = load_map()
    scans = synth_scans(grid, AMCL_TRUTH, np.random.default_rng(1))
    rows: list[Row] = []
    for model in ("likelihood_field", "beam"):
        # pf_err tiny keeps KLD at max_particles: every update runs on 2000 particles
        o = AmclOptions(laser_model_type=model, update_min_d=0.0, update_min_a=0.0, pf_err=1e-4)
        ours_filter = Amcl(o, grid, seed=0)
        ours_filter.set_initial_pose(Pose2D.from_array(AMCL_TRUTH[0]), np.diag([0.1, 0.1, 0.05]))
        step = iter(range(1 << 30))

        def ours(f: Amcl = ours_filter, it=step) -> None:
            i = next(it)
            f.update(Pose2D(0.001 * i, 0.0, 0.0), scans[i % 2], LASER_POSE)

        kernel = f"AMCL update, {model.replace('_', ' ')}, {AMCL_PARTICLES} particles x 60 beams"
        if model != "beam" or amcl is None:
            peer = "Nav2 AMCL (PyPI amcl binds the beam model only)" if amcl else "Nav2 AMCL (not installed)"
            rows.append(Row(kernel, _single(ours), peer, None))
            continue
        theirs = _nav2_amcl_update(amcl, grid, scans, o)
        a, b = alternating_medians(ours, theirs, rounds=AMCL_ROUNDS)
        rows.append(Row(kernel, a, "Nav2 AMCL via PyPI amcl", b))
    return rows


def _nav2_amcl_update(
    amcl: ModuleType, grid: OccupancyGrid, scans: list, o: AmclOptions
) -> Callable[[], None]:
    """A closure running one update of the PyPI ``amcl`` filter (Nav2's C++) per call, on the same
    map (occupied 100, unknown -1), scans ([range, bearing] pairs, no-returns at range_max), laser
    mount and parameters as navdeck's side; its map origin is the grid's corner, as checked by
    localizing at the truth."""

    g = grid.geometry
    data = np.where(grid.occupied_mask(), 100, np.where(grid.data < 0, -1, 0)).astype(int)
    occ = amcl.create_occupancy_grid_from_list(data.tolist(), g.resolution, g.origin.x, g.origin.y)
    laser = amcl.LaserParameters(
        o.z_hit, o.z_short, o.z_max, o.z_rand, o.sigma_hit, o.lambda_short, 0.0, o.laser_max_beams
    )
    motion = amcl.MotionParameters(o.alpha1, o.alpha2, o.alpha3, o.alpha4, o.alpha5)
    f = amcl.AMCL(
        AMCL_PARTICLES,
        AMCL_PARTICLES,
        o.recovery_alpha_slow,
        o.recovery_alpha_fast,
        motion,
        laser,
        "differential",
    )
    f.set_map(occ)
    f.set_laser_pose(amcl.Vector3D(LASER_POSE.x, LASER_POSE.y, LASER_POSE.theta))
    x, y, th = AMCL_TRUTH[0]
    f.set_initial_pose(amcl.Vector3D(x, y, th), amcl.create_diagonal_covariance(0.1, 0.1, 0.05))
    peer_scans = []
    for sc in scans:
        bearings = sc.angle_min + sc.angle_increment * np.arange(sc.ranges.size)
        r = np.where(np.isfinite(sc.ranges), sc.ranges, sc.range_max)
        peer_scans.append(
            amcl.create_laser_scan_from_list(np.column_stack((r, bearings)).tolist(), sc.range_max)
        )
    step = iter(range(1 << 30))

    def theirs() -> None:
        i = next(step)
        f.update(peer_scans[i % 2], amcl.Vector3D(0.001 * i, 0.0, 0.0))

    return theirs


def _dwa_rows() -> list[Row]:
    """One DWA cycle in PythonRobotics' demo world (its 15 point obstacles, start at rest, goal
    (10, 10)) with its limits, window (dt 0.1 s) and 3 s horizon. navdeck: the obstacles as lethal
    cells of a 0.05 m costmap with Nav2 inflation, a straight path to the goal, DWB critics,
    20 x 20 samples; PythonRobotics: its own 4 x 80 samples and objective (bench.pythonrobotics_dwa,
    written from the published algorithm: PythonRobotics is not on PyPI). The same world with a
    0.1 m robot has no peer: it shows how navdeck's cycle grows with the robot's size."""

    cfg = prd.Config()
    ours_1m, ours_small = _navdeck_dwa_cycle(1.0), _navdeck_dwa_cycle(0.1)
    theirs = lambda: prd.dwa_control(prd.START, cfg, prd.GOAL, prd.OBSTACLES)  # noqa: E731
    a, b = alternating_medians(ours_1m, theirs)
    # the size ratio from its own pairing, many rounds: both cycles are ~1 ms, so one busy spell
    # of the shared machine would otherwise decide it
    big, small = alternating_medians(ours_1m, ours_small, rounds=DWA_SIZE_ROUNDS)
    hall_big, hall_small = alternating_medians(
        _navdeck_dwa_cycle(1.0, corridor=True), _navdeck_dwa_cycle(0.1, corridor=True), rounds=DWA_SIZE_ROUNDS
    )
    return [
        Row(
            "DWA cycle, PythonRobotics' world and 1.0 m robot",
            a,
            "PythonRobotics DWA (from its algorithm)",
            b,
        ),
        Row(
            "DWA cycle, same world, 0.1 m robot",
            small,
            "",
            None,
            f"1.0 m robot {big:.3g} ms in the same pairing: {big / small:.2f}x (target <= 2)",
            (Figure("DWA cycle 1.0 m / 0.1 m robot", big / small, "x", "<= 2", big / small <= 2.0),),
        ),
        Row(
            "DWA cycle, 2.5 m corridor along the start heading, 1.0 m robot",
            hall_big,
            "",
            None,
            f"0.1 m robot {hall_small:.3g} ms, same pairing: {hall_big / hall_small:.2f}x (target <= 2)",
            (
                Figure(
                    "DWA cycle in a corridor, 1.0 m / 0.1 m robot",
                    hall_big / hall_small,
                    "x",
                    "<= 2",
                    hall_big / hall_small <= 2.0,
                ),
            ),
        ),
    ]


def _navdeck_dwa_cycle(radius: float, corridor: bool = False) -> Callable[[], None]:
    """One DWA cycle from PythonRobotics' start (at rest) in its world, or (``corridor``) between
    two walls 2.5 m apart along the start's heading, cruising at 0.5 m/s 0.1 m off the centre line,
    where many poses of a 1 m robot are near a wall."""
    cfg, res, size = prd.Config(), 0.05, 400
    geo = GridGeometry(res, size, size, Pose2D(-3.0, -3.0, 0.0))
    base = np.zeros((size, size), dtype=np.uint8)
    points = prd.OBSTACLES
    if corridor:
        s = np.arange(-3.0, 17.0, res / 2)
        c, si = math.cos(prd.START[2]), math.sin(prd.START[2])
        points = np.vstack([np.column_stack((s * c - off * si, s * si + off * c)) for off in (-1.25, 1.25)])
        points = points[(points >= -3.0).all(axis=1) & (points < 17.0).all(axis=1)]
    r, c = geo.world_to_cell(points)
    base[r, c] = LETHAL_OBSTACLE
    inflation = InflationOptions(inflation_radius=radius + 0.5, cost_scaling_factor=3.0)
    costmap = Costmap(geo, inflate(base, res, radius, inflation))
    options = DwaOptions(
        robot_radius=radius,
        min_vel_x=cfg.min_speed,
        max_vel_x=cfg.max_speed,
        max_speed_xy=cfg.max_speed,
        max_vel_theta=cfg.max_yaw_rate,
        acc_lim_x=cfg.max_accel,
        decel_lim_x=-cfg.max_accel,
        acc_lim_theta=cfg.max_delta_yaw_rate,
        decel_lim_theta=-cfg.max_delta_yaw_rate,
        controller_frequency=1.0 / cfg.dt,
        sim_time=cfg.predict_time,
        discretize_by_time=True,
        time_granularity=cfg.dt,
        forward_prune_distance=3.0,
    )
    ctl = DwaController(options)
    n = 200
    line = np.linspace(0.0, 1.0, n)
    ctl.set_path(NavPath(np.column_stack((prd.GOAL[0] * line, prd.GOAL[1] * line, np.full(n, math.pi / 4)))))
    pose = Pose2D(prd.START[0], prd.START[1], prd.START[2])
    velocity = Twist2D()
    if corridor:  # cruising 0.1 m off the centre line: the 3 s arcs sweep along both walls
        pose = Pose2D(pose.x - 0.1 * math.sin(pose.theta), pose.y + 0.1 * math.cos(pose.theta), pose.theta)
        velocity = Twist2D(0.5, 0.0, 0.0)

    def cycle() -> None:
        with contextlib.suppress(NoValidControl):  # a cycle rejecting every sample did the work too
            ctl.compute(pose, velocity, costmap)

    return cycle


def _sim_rows(irsim: ModuleType | None) -> list[Row]:
    """One simulator step of one lidar period (one motion update of a diff-drive robot driving,
    one 360-beam 6 m lidar scan) in navdeck's office world, against ir-sim on the same occupancy
    grid (an image map of the same size) with the same lidar. ir-sim and irsim-x both install
    ``irsim``: the row names the one that imported."""

    profile = load_profile("skid4")
    world = World.stock("office")
    _ = world.raycaster, world.clearance_map
    clock = VirtualClock()
    period = 1.0 / profile.lidar.rate_hz
    # one physics substep per lidar period, like ir-sim's step (navdeck runs 100 Hz substeps)
    options = SimOptions(physics_rate_hz=profile.lidar.rate_hz)
    driver = SimDriver(world, profile, clock, seed=0, options=options)

    def ours() -> None:
        driver.command(Twist2D(0.2, 0.0, 0.3))
        clock.advance(period)
        driver.read()

    kernel = "simulator step, 360-beam lidar, office"
    if irsim is None or MPIMG is None:
        return [Row(kernel, _single(ours), "ir-sim / irsim-x (not installed)", None)]
    name = "irsim-x" if _irsim_is_x(irsim) else "ir-sim"
    theirs = _irsim_step(irsim, world, period, profile.lidar.range_max)
    a, b = alternating_medians(ours, theirs, rounds=SIM_ROUNDS)
    return [Row(kernel, a, name, b)]


def _irsim_is_x(irsim: ModuleType) -> bool:
    """Whether the installed ``irsim`` is irsim-x's (its version module reads irsim-x's metadata;
    its compiled core is a separate top-level package)."""
    return "irsim-x" in Path(irsim.__file__).with_name("version.py").read_text()


def _irsim_step(irsim: ModuleType, world: World, period: float, range_max: float) -> Callable[[], None]:
    """ir-sim's env.step() closure on ``world``'s occupancy (an image in a temporary folder)."""

    folder = Path(tempfile.mkdtemp(prefix="navdeck-irsim-"))
    occ = world.occupied
    MPIMG.imsave(
        folder / "office.png",
        np.flipud(np.where(occ, 0, 255)).astype(np.uint8),
        cmap="gray",
        vmin=0,
        vmax=255,
    )
    g = world.geometry
    start = world.start_pose
    (folder / "office.yaml").write_text(
        f"""world:
  height: {g.height * g.resolution}
  width: {g.width * g.resolution}
  step_time: {period}
  offset: [{g.origin.x}, {g.origin.y}]
  obstacle_map: {folder / "office.png"}
  collision_mode: stop
robot:
  - kinematics: {{name: diff}}
    shape: {{name: circle, radius: 0.15}}
    state: [{start.x}, {start.y}, {start.theta}]
    sensors:
      - name: lidar2d
        range_min: 0.15
        range_max: {range_max}
        angle_range: 6.283185307179586
        number: 360
"""
    )
    env = irsim.make(str(folder / "office.yaml"), display=False, disable_all_plot=True)

    def theirs() -> None:
        env.step(np.array([[0.2], [0.3]]))

    return theirs


# --- report --------------------------------------------------------------------------------------


def _ms(v: float | None) -> str:
    return "" if v is None else f"{v:.3g} ms"


def markdown_table(rows: list[Row]) -> str:
    out = ["| kernel | navdeck | peer | ratio navdeck/peer | note |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        ratio = "" if r.ratio is None else f"{r.ratio:.2f}" if r.ratio >= 0.1 else f"{r.ratio:.2g}"
        out.append(f"| {r.kernel} | {_ms(r.navdeck_ms)} | {r.peer} {_ms(r.peer_ms)} | {ratio} | {r.note} |")
    return "\n".join(out)


def bench_peers() -> list[Figure]:
    rows = _astar_rows(PYASTAR2D) + _match_rows(KARTO)
    rows += _amcl_rows(REPORTED_PEERS["amcl"])
    rows += _dwa_rows()
    rows += _sim_rows(REPORTED_PEERS["irsim"])
    for name, module in REPORTED_PEERS.items():
        if module is None:
            print(f"peer {name}: not installed")
    print(markdown_table(rows))
    figs: list[Figure] = []
    for r in rows:
        if r.navdeck_ms is not None:
            figs.append(Figure(f"{r.kernel}: navdeck", r.navdeck_ms, "ms"))
        if r.peer_ms is not None:
            figs.append(Figure(f"{r.kernel}: {r.peer}", r.peer_ms, "ms"))
        if r.ratio is not None:
            figs.append(Figure(f"{r.kernel}: ratio", r.ratio, "x", "<= 1", r.ratio <= 1.0))
        figs.extend(r.extra)
    return figs


BENCHMARKS = [Benchmark(name="peers", run=bench_peers, group="peers")]
