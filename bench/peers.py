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
traversability with unit cell weight; navdeck runs the planner's kernel (``nav.planning.bucket_search``:
exact octile, no corner cutting, path traced), pyastar2d runs ``astar_path(..., allow_diagonal=True)``
(a diagonal step costs 1 and blocked corners may be cut: an easier problem).
"""

from __future__ import annotations

import importlib
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

from bench.core import Benchmark, Figure
from bench.datasets import MOVINGAI, ROS_MAPS
from bench.planning import _component_corners, _real_map_costmap
from nav.planning.bucket_search import octile_search

ROUNDS = 7
WILLOW = ROS_MAPS / "navigation_stage/willow-full-0.05.yaml"
DEN312D = MOVINGAI / "mapf/den312d"
SCENARIOS = 20
# A round plans the den312d scenarios this many times: one pass lasts ~1 ms, the length of a
# scheduler time slice, so on a loaded machine single passes gave medians 4x apart between runs.
SCENARIO_PASSES = 10
MOVINGAI_PASSABLE = frozenset(".GS")  # MovingAI map legend: '.', 'G', 'S' passable; '@', 'O', 'T', 'W' not


@dataclass
class Row:
    kernel: str
    navdeck_ms: float | None
    peer: str
    peer_ms: float | None
    note: str = ""

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
REPORTED_PEERS = {name: optional_import(name) for name in ("karto_scanmatcher", "amcl", "irsim")}


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
    """Exact octile A* path cost start -> goal (navdeck's bucketed kernel, which also traces the
    path as pyastar2d does); inf if unreachable."""
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


# --- report --------------------------------------------------------------------------------------


def _ms(v: float | None) -> str:
    return "" if v is None else f"{v:.3g} ms"


def markdown_table(rows: list[Row]) -> str:
    out = ["| kernel | navdeck | peer | ratio navdeck/peer | note |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        ratio = "" if r.ratio is None else f"{r.ratio:.2f}"
        out.append(f"| {r.kernel} | {_ms(r.navdeck_ms)} | {r.peer} {_ms(r.peer_ms)} | {ratio} | {r.note} |")
    return "\n".join(out)


def bench_peers() -> list[Figure]:
    rows = _astar_rows(PYASTAR2D)
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
    return figs


BENCHMARKS = [Benchmark(name="peers", run=bench_peers, group="peers")]
