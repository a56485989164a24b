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
def _search(
    passable: np.ndarray,
    cost: np.ndarray,
    use_cost: bool,
    cost_factor: float,
    heuristic_weight: float,
    sr: int,
    sc: int,
    gr: int,
    gc: int,
    width_f: float,
    stamp: np.ndarray,
    gen: int,
    g: np.ndarray,
    parent: np.ndarray,
    bucket_of: np.ndarray,
    e_node: np.ndarray,
    e_next: np.ndarray,
    head: np.ndarray,
    out: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Search ``start -> goal`` on (H, W) ``passable`` (uint8 0/1). ``stamp[cell] == gen`` marks an
    open cell of this search, ``gen + 1`` a closed one (anything else: unseen). ``out`` receives
    [status, goal cost, expansions]. Returns the entry pool, grown if it had to be."""
    h, w = passable.shape
    n_buckets = head.shape[0]
    mask = n_buckets - 1
    inv = 1.0 / width_f
    start = sr * w + sc
    goal = gr * w + gc
    f0 = heuristic_weight * _octile(sr, sc, gr, gc)
    for i in range(n_buckets):
        head[i] = -1
    # entry pool: entries below ``top`` were handed out; e_next chains the bucket stacks and the
    # free list of returned ones (nothing of the pool's size is initialised per call)
    n_entries = e_node.shape[0]
    free = -1
    top = 1
    closed = gen + 1
    best = np.inf
    stamp[start] = gen
    g[start] = 0.0
    parent[start] = -1
    bucket_of[start] = 0
    e_node[0] = start
    e_next[0] = -1
    head[0] = 0
    live = 1
    b = 0
    expansions = 0
    if start == goal:
        best = 0.0
    while live > 0:
        slot = b & mask
        e = head[slot]
        if e < 0:
            b += 1
            continue
        if f0 + b * width_f >= best:
            break  # no open node can lead to a cheaper goal path
        head[slot] = e_next[e]
        e_next[e] = free
        free = e
        live -= 1
        node = e_node[e]
        if stamp[node] != gen or bucket_of[node] != b:
            continue  # stale entry: the node moved to a lower bucket or was expanded since
        stamp[node] = closed
        expansions += 1
        r = node // w
        c = node - r * w
        gn = g[node]
        for k in range(8):
            rr = r + _DR[k]
            cc = c + _DC[k]
            if rr < 0 or rr >= h or cc < 0 or cc >= w or passable[rr, cc] == 0:
                continue
            if k >= 4 and (passable[r, cc] == 0 or passable[rr, c] == 0):
                continue  # no cutting past a blocked corner
            nb = rr * w + cc
            step = _STEP[k]
            if use_cost:
                step *= 1.0 + cost_factor * cost[rr, cc]
            ng = gn + step
            s = stamp[nb]
            if (s == gen or s == closed) and ng >= g[nb]:
                continue
            g[nb] = ng
            parent[nb] = node
            if nb == goal:
                stamp[nb] = closed  # never expanded: its cost is all the search needs
                best = ng
                continue
            f = ng + heuristic_weight * _octile(rr, cc, gr, gc)
            if f >= best:
                stamp[nb] = closed  # cannot improve the goal; keep g so a worse path stays out
                continue
            nbk = int((f - f0) * inv)
            if nbk < b:
                nbk = b  # rounding: a consistent heuristic never lowers f
            if s == gen and bucket_of[nb] == nbk:
                continue  # already in that bucket
            stamp[nb] = gen
            bucket_of[nb] = nbk
            if free >= 0:
                e = free
                free = e_next[e]
            else:
                if top == n_entries:  # grow the pool
                    n_entries *= 2
                    new_node = np.empty(n_entries, dtype=np.int32)
                    new_next = np.empty(n_entries, dtype=np.int32)
                    new_node[:top] = e_node
                    new_next[:top] = e_next
                    e_node = new_node
                    e_next = new_next
                e = top
                top += 1
            e_node[e] = nb
            s2 = nbk & mask
            e_next[e] = head[s2]
            head[s2] = e
            live += 1
    out[0] = FOUND if best < np.inf else UNREACHABLE
    out[1] = best
    out[2] = expansions
    return e_node, e_next


@njit(cache=True, nogil=True)
def _trace(parent: np.ndarray, node: int, w: int) -> np.ndarray:
    n = 1
    k = node
    while parent[k] >= 0:
        k = parent[k]
        n += 1
    cells = np.empty((n, 2), dtype=np.int64)
    k = node
    for i in range(n - 1, -1, -1):
        cells[i, 0] = k // w
        cells[i, 1] = k % w
        k = parent[k]
    return cells


class Workspace:
    """The per-cell arrays of searches over one grid size, reused call after call."""

    def __init__(self, height: int, width: int) -> None:
        n = height * width
        if n >= 2**31:
            raise ValueError(f"grid of {height} x {width} cells is too large for int32 cell ids")
        self.shape = (height, width)
        # np.empty/zeros do not fault pages in: a search touches only the cells it reaches.
        self.stamp = np.zeros(n, dtype=np.uint32)
        self.gen = 0
        self.g = np.empty(n)
        self.parent = np.empty(n, dtype=np.int32)
        self.bucket_of = np.empty(n, dtype=np.int64)
        entries = max(1024, min(n, 1 << 16))
        self.e_node = np.empty(entries, dtype=np.int32)
        self.e_next = np.empty(entries, dtype=np.int32)
        self.out = np.empty(3)

    def next_gen(self) -> int:
        """Stamp of the next search's open cells (closed is one more); clears on wrap-around."""
        self.gen += 2
        if self.gen >= 2**32 - 2:
            self.stamp[:] = 0
            self.gen = 2
        return self.gen


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
    for name, (r, c) in (("start", start), ("goal", goal)):
        if not (0 <= r < h and 0 <= c < w):
            raise ValueError(f"{name} {(r, c)} is outside the {h} x {w} grid")
    if heuristic_weight < 0 or not math.isfinite(heuristic_weight):
        raise ValueError(f"heuristic_weight must be finite and >= 0, got {heuristic_weight}")
    ws = workspace_for(h, w)
    grid = np.ascontiguousarray(passable).view(np.uint8) if passable.dtype == bool else passable
    use_cost = cost is not None and cost_travel_multiplier != 0.0
    cost_arr = np.ascontiguousarray(cost, dtype=np.uint8) if use_cost else _NO_COST
    cost_factor = float(cost_travel_multiplier) / 252.0
    max_step = SQRT2 * (1.0 + cost_factor * 255.0) if use_cost else SQRT2
    head = np.empty(_n_buckets(max_step, heuristic_weight, width), dtype=np.int32)
    ws.e_node, ws.e_next = _search(
        np.ascontiguousarray(grid),
        cost_arr,
        use_cost,
        cost_factor,
        float(heuristic_weight),
        int(start[0]),
        int(start[1]),
        int(goal[0]),
        int(goal[1]),
        float(width),
        ws.stamp,
        ws.next_gen(),
        ws.g,
        ws.parent,
        ws.bucket_of,
        ws.e_node,
        ws.e_next,
        head,
        ws.out,
    )
    status, best, expansions = ws.out
    if status != FOUND:
        return math.inf, None, int(expansions)
    return float(best), _trace(ws.parent, int(goal[0]) * w + int(goal[1]), w), int(expansions)


_NO_COST = np.zeros((1, 1), dtype=np.uint8)
