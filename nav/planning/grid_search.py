"""8-connected best-first grid search (Dijkstra 1959 / A*: Hart, Nilsson & Raphael 1968), compiled
with numba.

Why numba: a pure-Python ``heapq`` loop costs ~1-2 µs per push/pop, so a corner-to-corner search on
a 2000 x 2000 grid (millions of expansions) takes many seconds. ``scipy.sparse.csgraph.dijkstra``
is compiled but has no early exit at a goal and no heuristic, and building the 8-connected CSR graph
(with the no-corner-cutting rule) costs more than the search itself. A ``@njit(cache=True)`` indexed
binary heap (decrease-key, so the heap never exceeds the grid size; keys stored beside the node ids)
costs ~0.2-0.3 µs per expansion including its 8 relaxations on the 2-core development VM. (A lazy
duplicate-push heap measured 2x slower here.)

Rules (Moving AI octile benchmark and Nav2 Smac 2D semantics):
- 8 neighbours; a diagonal step is allowed only if both side cells it passes are traversable
  (no cutting a blocked corner);
- step cost ``(1 or sqrt2) * (1 + cost_travel_multiplier * cost[neighbour] / 252)``;
- heuristic ``heuristic_weight * octile(dx, dy)``: consistent for weight 1 (every step factor is
  >= 1), so A* stays optimal; weight 0 is Dijkstra.

Kernels are compiled with ``nogil=True``: a plan running on a worker thread does not hold the GIL,
so the control loop keeps its rate meanwhile. The search is resumable: ``SearchState`` holds every
array, and ``run`` expands at most ``budget`` nodes per call, so the caller can check a wall-clock
deadline between calls (numba has no clock).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit

SQRT2 = math.sqrt(2.0)

FOUND = 0
EXHAUSTED = 1
BUDGET = 2


class ResumableSearch(Protocol):
    """What the compiled searches share: ``run(budget)`` until FOUND or EXHAUSTED, then the result."""

    path: np.ndarray | None

    def run(self, budget: int) -> int: ...

    @property
    def expansions(self) -> int: ...

    @property
    def goal_cost(self) -> float: ...


def solve(search: ResumableSearch) -> tuple[float, np.ndarray | None, int]:
    """Run ``search`` to the end: (goal cost, (N, 2) path cells, expansions); ``inf`` and None when
    the goal is unreachable."""
    if search.run(1 << 62) != FOUND:
        return math.inf, None, search.expansions
    return search.goal_cost, search.path, search.expansions


# Neighbour offsets (d_row, d_col) and their base step lengths.
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)
_STEP = np.array([1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2])


@njit(cache=True, nogil=True, inline="always")
def _sift_up(heap: np.ndarray, hf: np.ndarray, hg: np.ndarray, pos: np.ndarray, i: int) -> None:
    # Keys live next to the node ids (hf, hg) so comparisons stay in the heap's cache lines.
    # Order by f, ties broken towards the larger g (deeper node): far fewer expansions on open floors.
    node = heap[i]
    fn = hf[i]
    gn = hg[i]
    while i > 0:
        parent = (i - 1) >> 1
        fp = hf[parent]
        if fn < fp or (fn == fp and gn > hg[parent]):
            other = heap[parent]
            heap[i] = other
            hf[i] = fp
            hg[i] = hg[parent]
            pos[other] = i
            i = parent
        else:
            break
    heap[i] = node
    hf[i] = fn
    hg[i] = gn
    pos[node] = i


@njit(cache=True, nogil=True, inline="always")
def _sift_down(heap: np.ndarray, hf: np.ndarray, hg: np.ndarray, pos: np.ndarray, i: int, size: int) -> None:
    node = heap[i]
    fn = hf[i]
    gn = hg[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and (hf[right] < hf[child] or (hf[right] == hf[child] and hg[right] > hg[child])):
            child = right
        fc = hf[child]
        if fc < fn or (fc == fn and hg[child] > gn):
            other = heap[child]
            heap[i] = other
            hf[i] = fc
            hg[i] = hg[child]
            pos[other] = i
            i = child
        else:
            break
    heap[i] = node
    hf[i] = fn
    hg[i] = gn
    pos[node] = i


@njit(cache=True, nogil=True, inline="always")
def _octile(r: int, c: int, gr: int, gc: int) -> float:
    dr = abs(r - gr)
    dc = abs(c - gc)
    if dr < dc:
        return dc + (SQRT2 - 1.0) * dr
    return dr + (SQRT2 - 1.0) * dc


@njit(cache=True, nogil=True, inline="always")
def octile_of_offsets(d_row: float, d_col: float) -> float:
    """``_octile`` of a cell ``d_row, d_col`` cells (whole numbers, as floats) from the goal, bit
    for bit (the same float operations on the same values), but branch-free: near the start-goal
    diagonal which of the two is larger flips from cell to cell, and ``_octile``'s branch
    mispredicts there (the bucket kernel's hot loop)."""
    a = abs(d_row)
    b = abs(d_col)
    return max(a, b) + (SQRT2 - 1.0) * min(a, b)


@njit(cache=True, nogil=True)
def _run(
    state: np.ndarray,
    cost: np.ndarray,
    width: int,
    goal: int,
    heuristic_weight: float,
    cost_factor: float,
    budget: int,
    g: np.ndarray,
    parent: np.ndarray,
    heap: np.ndarray,
    hf: np.ndarray,
    hg: np.ndarray,
    pos: np.ndarray,
    counters: np.ndarray,
    dr: np.ndarray,
    dc: np.ndarray,
    step: np.ndarray,
) -> int:
    """Expand up to ``budget`` nodes. ``counters`` = [heap size, total expansions].

    The grid is padded with a one-cell border of blocked cells (no bounds checks) and ``state``
    merges traversability and search state: 0 unseen, 1 open (``g``, ``parent``, ``pos`` valid),
    2 closed, 3 blocked. Only ``state`` and the padded costs are written at set-up; the other
    arrays are ``np.empty``, so set-up cost hardly grows with the grid size."""
    size = counters[0]
    gr = goal // width
    gc = goal - gr * width
    done = 0
    while size > 0:
        if done >= budget:
            counters[0] = size
            counters[1] += done
            return BUDGET
        node = heap[0]
        size -= 1
        if size > 0:
            heap[0] = heap[size]
            hf[0] = hf[size]
            hg[0] = hg[size]
            pos[heap[0]] = 0
            _sift_down(heap, hf, hg, pos, 0, size)
        state[node] = 2
        done += 1
        if node == goal:
            counters[0] = size
            counters[1] += done
            return FOUND
        r = node // width
        c = node - r * width
        gn = g[node]
        for k in range(8):
            nb = node + dr[k] * width + dc[k]
            s = state[nb]
            if s >= 2:
                continue  # closed or blocked
            if k >= 4 and (state[node + dc[k]] == 3 or state[node + dr[k] * width] == 3):
                continue  # no cutting past a blocked corner
            ng = gn + step[k] * (1.0 + cost_factor * cost[nb])
            if s == 0:
                state[nb] = 1
                p = size
                heap[p] = nb
                size += 1
            elif ng < g[nb]:
                p = pos[nb]
            else:
                continue
            g[nb] = ng
            parent[nb] = node
            hf[p] = ng + heuristic_weight * _octile(r + dr[k], c + dc[k], gr, gc)
            hg[p] = ng
            _sift_up(heap, hf, hg, pos, p)
    counters[0] = size
    counters[1] += done
    return EXHAUSTED


@njit(cache=True, nogil=True)
def _trace(parent: np.ndarray, node: int) -> np.ndarray:
    n = 1
    k = node
    while parent[k] >= 0:
        k = parent[k]
        n += 1
    out = np.empty(n, dtype=np.int64)
    k = node
    for i in range(n - 1, -1, -1):
        out[i] = k
        k = parent[k]
    return out


@dataclass
class SearchState:
    """Every array of one search over a (height, width) grid, stored padded to (height + 2,
    width + 2); flat index = (row + 1) * (width + 2) + col + 1. Public methods take (row, col)."""

    state: np.ndarray
    cost: np.ndarray
    width: int
    height: int
    start: int
    goal: int
    heuristic_weight: float
    cost_factor: float
    g: np.ndarray
    parent: np.ndarray
    heap: np.ndarray
    hf: np.ndarray
    hg: np.ndarray
    pos: np.ndarray
    counters: np.ndarray

    @classmethod
    def create(
        cls,
        passable: np.ndarray,
        cost: np.ndarray,
        start: tuple[int, int],
        goal: tuple[int, int],
        *,
        heuristic_weight: float = 1.0,
        cost_travel_multiplier: float = 0.0,
    ) -> SearchState:
        """``passable`` bool (H, W); ``cost`` (H, W) 0..255 cell costs; start/goal as (row, col).
        The start cell is expanded even if it is not passable (a robot may start in inflation)."""
        h, w = passable.shape
        pw = w + 2
        n = (h + 2) * pw
        if n >= 2**31:
            raise ValueError(f"grid of {h} x {w} cells is too large for int32 cell ids")
        state = np.full((h + 2, pw), 3, dtype=np.uint8)
        # uint8 all the way: np.where(passable, 0, 3) would build an int64 temporary (8 bytes a cell).
        np.multiply(~passable, np.uint8(3), out=state[1:-1, 1:-1], dtype=np.uint8)
        padded_cost = np.zeros((h + 2, pw), dtype=np.uint8)
        padded_cost[1:-1, 1:-1] = cost
        s = (start[0] + 1) * pw + start[1] + 1
        gl = (goal[0] + 1) * pw + goal[1] + 1
        # np.empty does not touch memory: only pages the search visits are ever faulted in.
        g = np.empty(n)
        hf = np.empty(n)
        hg = np.empty(n)
        # int32 ids (grids up to 2^31 cells): half the memory traffic of int64 on large maps.
        parent = np.empty(n, dtype=np.int32)
        pos = np.empty(n, dtype=np.int32)
        heap = np.empty(n, dtype=np.int32)
        state = state.ravel()
        state[s] = 1
        parent[s] = -1
        g[s] = 0.0
        hf[0] = heuristic_weight * _octile(start[0], start[1], goal[0], goal[1])
        hg[0] = 0.0
        heap[0] = s
        pos[s] = 0
        return cls(
            state=state,
            cost=padded_cost.ravel(),
            width=w,
            height=h,
            start=s,
            goal=gl,
            heuristic_weight=float(heuristic_weight),
            cost_factor=float(cost_travel_multiplier) / 252.0,
            g=g,
            parent=parent,
            heap=heap,
            hf=hf,
            hg=hg,
            pos=pos,
            counters=np.array([1, 0], dtype=np.int64),
        )

    def run(self, budget: int) -> int:
        """Expand at most ``budget`` nodes; returns FOUND, EXHAUSTED or BUDGET."""
        return int(
            _run(
                self.state,
                self.cost,
                self.width + 2,
                self.goal,
                self.heuristic_weight,
                self.cost_factor,
                int(budget),
                self.g,
                self.parent,
                self.heap,
                self.hf,
                self.hg,
                self.pos,
                self.counters,
                _DR,
                _DC,
                _STEP,
            )
        )

    @property
    def closed(self) -> np.ndarray:
        """(H, W) bool mask of expanded cells."""
        return self.state.reshape(self.height + 2, self.width + 2)[1:-1, 1:-1] == 2

    @property
    def expansions(self) -> int:
        return int(self.counters[1])

    def _flat(self, row: int, col: int) -> int:
        return (row + 1) * (self.width + 2) + col + 1

    def reached(self, row: int, col: int) -> bool:
        return bool(self.state[self._flat(row, col)] == 2)

    def cells_to(self, row: int, col: int) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the path start -> (row, col), which must have been expanded."""
        flat = _trace(self.parent, self._flat(row, col))
        pw = self.width + 2
        return flat // pw - 1, flat % pw - 1

    def cost_to(self, row: int, col: int) -> float:
        """Accumulated step cost from the start to an expanded cell."""
        return float(self.g[self._flat(row, col)])
