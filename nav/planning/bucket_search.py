"""Exact 8-connected A* / Dijkstra with a bucketed open list and a reusable workspace, compiled with
numba: the fast kernel beside ``grid_search`` (which stays the planner's resumable reference).

Why buckets: the binary heap of ``grid_search`` pays O(log open) sifts per push and pop; here the
open list is an array of buckets of f-width ``BUCKET_WIDTH`` (Dial 1969), each a LIFO stack, so a
push and a pop are O(1). LIFO inside a bucket expands the newest (deepest) node first, the same
effect as breaking f ties towards the larger g.

Why it stays exact: a bucket holds f values up to ``BUCKET_WIDTH`` apart, so a node may be expanded
before its cheapest path is known. A later cheaper path re-opens it (label correcting), and the
search stops only when the lowest bucket's lower f bound reaches the goal's cost: every path not yet
explored passes an open node whose f (a lower bound of its cost, the heuristic being consistent) is
at least that bound. Same rules and step costs as ``grid_search`` (no corner cutting, step
``(1 or sqrt2) * (1 + cost_factor * cost)``, heuristic ``weight * octile``).

Why a workspace: a search touches only the cells it reaches, so its arrays are reused between calls
(same grid size) and a generation stamp marks which cells belong to the current search: nothing of
the grid's size is allocated or cleared per call, and a small map's plan costs microseconds of set-up.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

SQRT2 = math.sqrt(2.0)
# f-width of one bucket. Measured (docs/benchmarks.md, "Peers"): narrower buckets re-open fewer
# nodes but walk more empty ones; 0.5 cell was fastest on Willow, random 20 % and den312d alike.
BUCKET_WIDTH = 0.5

_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)
_STEP = np.array([1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2])

FOUND = 0
UNREACHABLE = 1


@njit(cache=True, nogil=True, inline="always")
def _octile(r: int, c: int, gr: int, gc: int) -> float:
    dr = abs(r - gr)
    dc = abs(c - gc)
    if dr < dc:
        return dc + (SQRT2 - 1.0) * dr
    return dr + (SQRT2 - 1.0) * dc


@njit(cache=True, nogil=True)
def _trace(parent: np.ndarray, node: int, w: int) -> np.ndarray:
    """(N, 2) unpadded (row, col) cells of the parent chain ending at padded flat id ``node``."""
    n = 1
    k = node
    while parent[k] >= 0:
        k = parent[k]
        n += 1
    cells = np.empty((n, 2), dtype=np.int64)
    k = node
    for i in range(n - 1, -1, -1):
        r = k // w
        cells[i, 0] = r - 1
        cells[i, 1] = k - r * w - 1
        k = parent[k]
    return cells


@njit(cache=True, nogil=True)
def _search(
    passable: np.ndarray,
    cost: np.ndarray,
    use_cost: bool,
    cost_factor: float,
    heuristic_weight: float,
    start: int,
    goal: int,
    width_f: float,
    state: np.ndarray,
    padded_cost: np.ndarray,
    g: np.ndarray,
    parent: np.ndarray,
    buckets: np.ndarray,
    counts: np.ndarray,
    out: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Search ``start -> goal`` (padded flat ids) over (H, W) ``passable``.

    ``state`` is the grid padded with a border of blocked cells (no bounds checks), (H + 2) *
    (W + 2) flat: 0 unseen, 1 open, 2 closed, 3 blocked. ``g`` and ``parent`` are valid where state
    is 1 or 2, so nothing else is initialised per search. ``buckets`` (a ring of LIFO stacks of cell
    ids) and ``counts`` hold the open list; a cell may sit in several stacks (its f dropped): only
    a pop that finds it open expands it. ``out`` receives [found, goal cost, expansions]. Returns
    ``buckets`` (grown if a stack overflowed) and the path's (N, 2) cells (N = 0: not found)."""
    h, wi = passable.shape
    w = wi + 2
    for r in range(h):
        base = (r + 1) * w + 1
        for c in range(wi):
            state[base + c] = 0 if passable[r, c] else 3
            if use_cost:
                padded_cost[base + c] = cost[r, c]
    n_buckets = counts.shape[0]
    mask = n_buckets - 1
    cap = buckets.shape[1]
    inv = 1.0 / width_f
    gr = goal // w
    gc = goal - gr * w
    sr = start // w
    f0 = heuristic_weight * _octile(sr, start - sr * w, gr, gc)
    counts[:] = 0
    best = np.inf
    state[start] = 1
    g[start] = 0.0
    parent[start] = -1
    buckets[0, 0] = start
    counts[0] = 1
    live = 1
    b = 0
    expansions = 0
    if start == goal:
        best = 0.0
    while live > 0:
        slot = b & mask
        top = counts[slot]
        if top == 0:
            b += 1
            continue
        if f0 + b * width_f >= best:
            break  # every open cell's f (a lower bound of a path through it) reaches the goal's cost
        top -= 1
        counts[slot] = top
        live -= 1
        node = buckets[slot, top]
        if state[node] != 1:
            continue  # expanded already from a lower bucket (this entry is stale)
        state[node] = 2
        expansions += 1
        r = node // w
        c = node - r * w
        gn = g[node]
        for k in range(8):
            dr = _DR[k]
            dc = _DC[k]
            nb = node + dr * w + dc
            s = state[nb]
            if s == 3:
                continue
            if k >= 4 and (state[node + dc] == 3 or state[node + dr * w] == 3):
                continue  # no cutting past a blocked corner
            step = _STEP[k]
            if use_cost:
                step *= 1.0 + cost_factor * padded_cost[nb]
            ng = gn + step
            if s != 0 and ng >= g[nb]:
                continue
            g[nb] = ng
            parent[nb] = node
            if nb == goal:
                state[nb] = 2  # never expanded: its cost is all the search needs
                best = ng
                continue
            f = ng + heuristic_weight * _octile(r + dr, c + dc, gr, gc)
            if f >= best:
                state[nb] = 2  # cannot lead to a cheaper goal path; g stays to keep worse ones out
                continue
            nbk = int((f - f0) * inv)
            if nbk < b:
                nbk = b  # rounding: a consistent heuristic never lowers f
            state[nb] = 1
            slot = nbk & mask
            top = counts[slot]
            if top == cap:  # grow every stack (rare)
                grown = np.empty((n_buckets, 2 * cap), dtype=buckets.dtype)
                grown[:, :cap] = buckets
                buckets = grown
                cap *= 2
            buckets[slot, top] = nb
            counts[slot] = top + 1
            live += 1
    out[0] = 1.0 if best < np.inf else 0.0
    out[1] = best
    out[2] = expansions
    if best == np.inf:
        return buckets, np.empty((0, 2), dtype=np.int64)
    return buckets, _trace(parent, goal, w)


class Workspace:
    """The per-cell arrays of searches over one grid size, reused call after call."""

    def __init__(self, height: int, width: int) -> None:
        n = (height + 2) * (width + 2)
        if n >= 2**31:
            raise ValueError(f"grid of {height} x {width} cells is too large for int32 cell ids")
        self.shape = (height, width)
        # the search state and the costs inside a border of blocked cells, the inside rewritten
        # per search (flat, rows of width + 2)
        self.state = np.full(n, 3, dtype=np.uint8)
        self.cost = np.zeros(n, dtype=np.uint8)
        # np.empty does not fault pages in: a search touches only the cells it reaches.
        self.g = np.empty(n)
        self.parent = np.empty(n, dtype=np.int32)
        self.buckets = np.empty((0, 0), dtype=np.int32)
        self.counts = np.empty(0, dtype=np.int64)
        self.out = np.empty(3)

    def ring(self, n_buckets: int) -> None:
        """Size the open list for ``n_buckets`` buckets (kept between searches)."""
        if self.counts.shape[0] != n_buckets:
            self.buckets = np.empty((n_buckets, 4096), dtype=np.int32)
            self.counts = np.empty(n_buckets, dtype=np.int64)


_local = threading.local()


def workspace_for(height: int, width: int) -> Workspace:
    """This thread's workspace for (height, width) grids (the last size used is kept)."""
    ws = getattr(_local, "ws", None)
    if ws is None or ws.shape != (height, width):
        ws = Workspace(height, width)
        _local.ws = ws
    return ws


def _n_buckets(max_step: float, heuristic_weight: float, width_f: float) -> int:
    # One edge raises f by at most its step plus the heuristic's change (<= weight * sqrt2): the
    # open list spans fewer buckets than that, so a power-of-two ring of them suffices.
    span = (max_step + heuristic_weight * SQRT2) / width_f + 2
    return 1 << max(4, math.ceil(math.log2(span)))


def octile_search(
    passable: np.ndarray,
    start: tuple[int, int],
    goal: tuple[int, int],
    *,
    cost: np.ndarray | None = None,
    cost_travel_multiplier: float = 0.0,
    heuristic_weight: float = 1.0,
    width: float = BUCKET_WIDTH,
) -> tuple[float, np.ndarray | None, int]:
    """Optimal (goal cost, (N, 2) path cells as (row, col) start first, expansions); cost ``inf``
    and path None when the goal cannot be reached. ``passable`` (H, W) bool; ``cost`` optional
    (H, W) 0..255 cell costs weighted as in ``grid_search``. The start is expanded even if it is not
    passable (a robot may start in inflation); the goal must be passable (or be the start)."""
    h, w = passable.shape
    sr, sc = int(start[0]), int(start[1])
    gr, gc = int(goal[0]), int(goal[1])
    if not (0 <= sr < h and 0 <= sc < w and 0 <= gr < h and 0 <= gc < w):
        raise ValueError(f"start {start} or goal {goal} is outside the {h} x {w} grid")
    if not (0.0 <= heuristic_weight < math.inf) or not width > 0.0:
        raise ValueError(f"heuristic_weight must be finite >= 0 and width > 0: {heuristic_weight}, {width}")
    use_cost = cost is not None and cost_travel_multiplier != 0.0
    if use_cost and cost.shape != passable.shape:
        raise ValueError(f"cost {cost.shape} and passable {passable.shape} differ in shape")
    cost_factor = float(cost_travel_multiplier) / 252.0
    ws = workspace_for(h, w)
    ws.ring(_n_buckets(SQRT2 * (1.0 + cost_factor * 255.0) if use_cost else SQRT2, heuristic_weight, width))
    pw = w + 2
    ws.buckets, cells = _search(
        passable,
        cost if use_cost else _NO_COST,
        use_cost,
        cost_factor,
        float(heuristic_weight),
        (sr + 1) * pw + sc + 1,
        (gr + 1) * pw + gc + 1,
        float(width),
        ws.state,
        ws.cost,
        ws.g,
        ws.parent,
        ws.buckets,
        ws.counts,
        ws.out,
    )
    if not ws.out[0]:
        return math.inf, None, int(ws.out[2])
    return float(ws.out[1]), cells, int(ws.out[2])


_NO_COST = np.zeros((1, 1), dtype=np.uint8)
