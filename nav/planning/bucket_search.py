"""Exact 8-connected A* / Dijkstra with a bucketed open list, compiled with numba: the planner's
kernel. ``grid_search`` (indexed binary heap) stays as the reference it is tested against.

Why buckets: a binary heap pays O(log open) sifts per push and pop; here the open list is a ring of
buckets of f-width ``BUCKET_WIDTH`` (Dial 1969), each a LIFO stack, so a push and a pop are O(1).
LIFO inside a bucket expands the newest (deepest) cell first, the effect of breaking f ties towards
the larger g. Measured 2x faster than the heap kernel on the 2000 x 2000 random grid and Willow.
The canonical-ordering kernel (``canonical_search``) is this same compiled loop with its pruning
switched on.

Why it stays exact: a bucket holds f values up to ``BUCKET_WIDTH`` apart, so a cell may be expanded
before its cheapest path is known. A later cheaper path re-opens it (label correcting), and the
search stops only when the lowest bucket's lower f bound reaches the goal's cost: every path not yet
explored passes an open cell whose f (a lower bound of its cost, the heuristic being consistent) is
at least that bound. Same rules and step costs as ``grid_search``: no corner cutting, step
``(1 or sqrt2) * (1 + cost_travel_multiplier * cost / 252)``, heuristic ``weight * octile``.

Why few allocations: one byte per cell holds traversability, search state (unseen, open, closed,
blocked) and the direction the cell was reached by (the path is traced along it: no parent array);
``g`` is ``np.empty`` and read only where that byte says it is valid, so a search writes the grid
once and then touches only the cells it reaches. ``workspace_for`` keeps one workspace per thread
between calls on same-sized grids (``kernel.octile_search`` uses it), so a small map's plan costs
microseconds of set-up. Kernels are ``nogil``; ``run`` expands at most ``budget`` cells per call so
the caller can check a wall-clock deadline between calls.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import numpy as np
from numba import njit

from nav.planning.grid_search import BUDGET, EXHAUSTED, FOUND, SQRT2, octile_of_offsets
from nav.planning.grid_search import _octile as octile_heuristic  # the heap kernel's, inlined
from nav.planning.prefetch import prefetch

# f-width of one bucket, in cells. Measured: with unit cells (random 20 %, Willow) 0.1, 0.25 and 0.5
# ran equally fast (1.0 expands 6 % more on the random grid); with Nav2's cost_travel_multiplier 2
# on Willow, re-opened cells grow with the width (265 k, 293 k, 330 k, 482 k expansions at 0.1,
# 0.25, 0.5, 1.0 against the heap's 254 k), and 0.1 was fastest.
BUCKET_WIDTH = 0.1

_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)
_DIAGONAL = np.array([0, 0, 0, 0, 1, 1, 1, 1], dtype=np.int64)
# the same offsets as floats, for the heuristic (no int -> float conversion per neighbour)
_DRF = _DR.astype(np.float64)
_DCF = _DC.astype(np.float64)
# the direction of (d_row, d_col), indexed by (d_row + 1) * 3 + d_col + 1
_INDEX = np.full(9, -1, dtype=np.int64)
for _k in range(8):
    _INDEX[(_DR[_k] + 1) * 3 + _DC[_k] + 1] = _k

_OPEN, _CLOSED, _BLOCKED = 1, 2, 3
_START = 8  # the start's "direction": every neighbour is a successor

# ctl slots: where a resumable search stands between calls
_PHASE, _BUCKET, _LIVE, _EXPANSIONS = 0, 1, 2, 3
# the kernel's answer when a bucket stack may overflow: the caller grows them and runs it again
# (growing inside the kernel reassigns an array in the hot loop, which numba then reference-counts
# on every iteration: measured 1.6x slower on the random grid)
_GROW = 3


@njit(cache=True, nogil=True)
def _trace(state: np.ndarray, start: int, node: int, w: int) -> np.ndarray:
    """(N, 2) unpadded (row, col) cells from ``start`` to the reached cell ``node`` (padded flat
    ids), stepping back along the direction each cell was reached by."""
    n = 1
    k = node
    while k != start:
        d = state[k] >> 2
        k -= _DR[d] * w + _DC[d]
        n += 1
    cells = np.empty((n, 2), dtype=np.int64)
    k = node
    for i in range(n - 1, -1, -1):
        r = k // w
        cells[i, 0] = r - 1
        cells[i, 1] = k - r * w - 1
        if i > 0:
            d = state[k] >> 2
            k -= _DR[d] * w + _DC[d]
    return cells


@njit(cache=True, nogil=True)
def _fill(
    passable: np.ndarray, cost: np.ndarray, use_cost: bool, state: np.ndarray, padded_cost: np.ndarray
) -> None:
    """Write the padded state (0 free, 3 blocked, a blocked border) and, if used, the costs."""
    h, wi = passable.shape
    w = wi + 2
    state[:w] = 3
    state[(h + 1) * w :] = 3
    for r in range(h):
        base = (r + 1) * w
        state[base] = 3
        state[base + w - 1] = 3
        for c in range(wi):  # branch-free, so the loop vectorizes
            state[base + 1 + c] = np.uint8(3) - np.uint8(3) * np.uint8(passable[r, c])
        if use_cost:
            for c in range(wi):
                padded_cost[base + 1 + c] = cost[r, c]


def _make_search(canonical: bool) -> Callable[..., tuple[int, np.ndarray]]:
    """The compiled search, with ``canonical_search``'s pruning or without (module docstring)."""

    @njit(cache=True, nogil=True)
    def search(
        passable: np.ndarray,
        cost: np.ndarray,
        use_cost: bool,
        cost_factor: float,
        step_scale: float,
        heuristic_weight: float,
        start: int,
        goal: int,
        width_f: float,
        budget: int,
        state: np.ndarray,
        padded_cost: np.ndarray,
        g: np.ndarray,
        buckets: np.ndarray,
        counts: np.ndarray,
        ctl: np.ndarray,
        best_out: np.ndarray,
    ) -> tuple[int, np.ndarray]:
        """Expand up to ``budget`` cells of the search ``start -> goal`` (padded flat ids) over (H, W)
        ``passable``; the first call (``ctl[_PHASE] == 0``) writes the grid and seeds the start. A
        straight step costs ``step_scale`` (a diagonal one sqrt2 times that), times ``1 + cost_factor
        * cost`` of the cell entered when ``use_cost``. ``canonical`` expands a cell only towards the
        successors of ``canonical_search``'s pruning rules (valid on uniform-cost grids only), else
        towards all 8 neighbours.

        Both kernels are this one loop, so the open list, the stopping rule and the resumable state
        exist once; ``canonical`` is a constant of each compiled version (the loop of the other is
        not in it). Sharing them through ``inline="always"`` helpers instead measured 1.25-1.5x
        slower: numba reference-counts the arrays handed to an inlined helper in the hot loop.

        ``state`` is the grid inside a border of blocked cells (no bounds checks), (H + 2) * (W + 2)
        flat; its low two bits are 0 unseen, 1 open, 2 closed, 3 blocked, the bits above them the
        direction (0-7, 8 for the start) of the step that reached the cell: the pruning reads it, and
        the path is traced back along it. ``g`` is valid where the cell is open or closed.
        ``buckets`` (a ring of LIFO stacks of cell ids) and ``counts`` hold the open list; a cell may
        sit in several stacks (its f dropped): only a pop that finds it open expands it.
        ``best_out[0]`` is the goal's cost so far. Returns the status (FOUND, EXHAUSTED, BUDGET or
        _GROW) and, when FOUND, the path's (N, 2) cells.

        Every array index in the loop is cast to ``np.uint64``: numba wraps a negative signed index
        around (a sign test and an add on each access, and the loop's registers then spill to the
        stack), an unsigned one it uses as it is. Every index here is a valid cell, bucket or direction id
        (never negative), so the cast changes no result; measured 0.80-0.86x the CPU time on the
        2000 x 2000 random grid. The row is divided unsigned for the same reason (no floor fixup)."""
        w = passable.shape[1] + 2
        n_buckets = counts.shape[0]
        mask = n_buckets - 1
        cap = buckets.shape[1]
        inv = 1.0 / width_f
        straight = step_scale
        diagonal = step_scale * SQRT2
        gr = goal // w
        gc = goal - gr * w
        sr = start // w
        f0 = heuristic_weight * octile_heuristic(sr, start - sr * w, gr, gc)
        if ctl[_PHASE] == 0:
            _fill(passable, cost, use_cost, state, padded_cost)
            counts[:] = 0
            state[start] = _OPEN | (_START << 2)
            g[start] = 0.0
            buckets[0, 0] = start
            counts[0] = 1
            ctl[:] = 0
            ctl[_PHASE] = 1
            ctl[_LIVE] = 1
            best_out[0] = 0.0 if start == goal else np.inf
        best = best_out[0]
        b = ctl[_BUCKET]
        live = ctl[_LIVE]
        done = 0
        status = EXHAUSTED
        fullest = cap  # an upper bound of the longest stack: recounted when it nears the capacity
        successors = np.arange(8)
        n_succ = 8
        while live > 0:
            slot = b & mask
            top = counts[np.uint64(slot)]
            if top == 0:
                b += 1
                continue
            if f0 + b * width_f >= best:
                break  # every open cell's f (a lower bound of a path through it) reaches the goal's cost
            if done >= budget:
                status = BUDGET
                break
            if fullest + 8 > cap:  # an expansion pushes at most 8 entries
                fullest = counts.max()
                if fullest + 8 > cap:
                    status = _GROW
                    break
            top -= 1
            counts[np.uint64(slot)] = top
            live -= 1
            node = buckets[np.uint64(slot), np.uint64(top)]
            if top > 0:  # the next pop, unless this expansion pushes onto the same stack
                ahead = buckets[np.uint64(slot), np.uint64(top - 1)]
                prefetch(state, ahead)
                prefetch(g, ahead)
                prefetch(state, ahead - w)
                prefetch(state, ahead + w)
                prefetch(g, ahead - w)
                prefetch(g, ahead + w)
            un = np.uint64(node)
            byte = state[un]
            if byte & 3 != _OPEN:
                continue  # expanded already from a lower bucket (this entry is stale)
            state[un] = byte + 1  # closed, the direction kept
            done += 1
            if canonical:  # the successors the pruning rules leave (canonical_search)
                arrived = np.uint64(byte >> 2)
                if arrived == _START:
                    for k in range(8):
                        successors[np.uint64(k)] = k
                    n_succ = 8
                else:
                    adr = _DR[arrived]
                    adc = _DC[arrived]
                    successors[0] = arrived
                    n_succ = 1
                    if _DIAGONAL[arrived]:
                        successors[1] = _INDEX[np.uint64((adr + 1) * 3 + 1)]
                        successors[2] = _INDEX[np.uint64(3 + adc + 1)]
                        n_succ = 3
                    else:
                        d = adr * w + adc
                        for side in (-1, 1):
                            sdr = side * adc  # perpendicular to (adr, adc)
                            sdc = side * adr
                            s = node + sdr * w + sdc
                            if state[np.uint64(s)] != _BLOCKED and state[np.uint64(s - d)] == _BLOCKED:
                                successors[np.uint64(n_succ)] = _INDEX[np.uint64((sdr + 1) * 3 + sdc + 1)]
                                successors[np.uint64(n_succ + 1)] = _INDEX[
                                    np.uint64((sdr + adr + 1) * 3 + sdc + adc + 1)
                                ]
                                n_succ += 2
            r = np.int64(np.uint32(node) // np.uint32(w))  # ids < 2**31 (Workspace)
            c = node - r * w
            # a neighbour's offset from the goal, as floats for ``octile_of_offsets``
            to_gr = float(r - gr)
            to_gc = float(c - gc)
            gn = g[un]
            for j in range(n_succ):
                k = successors[np.uint64(j)] if canonical else j
                dr = _DR[np.uint64(k)]
                dc = _DC[np.uint64(k)]
                nb = node + dr * w + dc
                unb = np.uint64(nb)
                s_nb = state[unb]
                if s_nb == _BLOCKED:
                    continue
                is_diagonal = k >= 4
                step = diagonal if is_diagonal else straight
                if not canonical and use_cost:  # one cost everywhere: in step_scale
                    step *= 1.0 + cost_factor * padded_cost[unb]
                ng = gn + step
                if s_nb != 0 and ng >= g[unb]:
                    continue  # most neighbours end here, so the corner test comes after
                if is_diagonal and (
                    state[np.uint64(node + dc)] == _BLOCKED or state[np.uint64(node + dr * w)] == _BLOCKED
                ):
                    continue  # no cutting past a blocked corner
                g[unb] = ng
                if nb == goal:
                    state[unb] = _CLOSED | (k << 2)  # never expanded: its cost is all the search needs
                    best = ng
                    continue
                to_goal = octile_of_offsets(to_gr + _DRF[np.uint64(k)], to_gc + _DCF[np.uint64(k)])
                f = ng + heuristic_weight * to_goal
                if f >= best:
                    state[unb] = _CLOSED | (k << 2)  # cannot lead to a cheaper goal path; g stays
                    continue
                nbk = int((f - f0) * inv)
                if nbk < b:
                    nbk = b  # rounding: a consistent heuristic never lowers f
                state[unb] = _OPEN | (k << 2)
                push = np.uint64(nbk & mask)
                top = counts[push]
                buckets[push, np.uint64(top)] = nb
                counts[push] = top + 1
                if top >= fullest:
                    fullest = top + 1
                live += 1
        ctl[_BUCKET] = b
        ctl[_LIVE] = live
        ctl[_EXPANSIONS] += done
        best_out[0] = best
        if status != EXHAUSTED:  # BUDGET or _GROW: the search goes on
            return status, np.empty((0, 2), dtype=np.int64)
        if best == np.inf:
            return EXHAUSTED, np.empty((0, 2), dtype=np.int64)
        ctl[_LIVE] = 0  # finished: a later run returns at once
        return FOUND, _trace(state, start, goal, w)

    return search


# both compiled once; ``canonical`` is a constant of each (numba prunes the other's branches, and
# caches them apart: a closure's variables are part of its cache key)
_SEARCH = {False: _make_search(False), True: _make_search(True)}


class Workspace:
    """The per-cell arrays of searches over one grid size (reusable by one search at a time)."""

    def __init__(self, height: int, width: int) -> None:
        n = (height + 2) * (width + 2)
        if n >= 2**31:
            raise ValueError(f"grid of {height} x {width} cells is too large for int32 cell ids")
        self.shape = (height, width)
        # np.empty does not fault pages in: a search writes the state and touches only the cells
        # it reaches in the others.
        self.state = np.empty(n, dtype=np.uint8)
        self.cost = np.empty(n, dtype=np.uint8)
        self.g = np.empty(n)
        self.buckets = np.empty((0, 0), dtype=np.int32)
        self.counts = np.empty(0, dtype=np.int64)

    def ring(self, n_buckets: int) -> None:
        """Size the open list for ``n_buckets`` buckets (kept between searches)."""
        if self.counts.shape[0] != n_buckets:
            self.buckets = np.empty((n_buckets, 4096), dtype=np.int32)
            self.counts = np.empty(n_buckets, dtype=np.int64)

    def grow(self) -> None:
        """Double every bucket stack's capacity, keeping the entries."""
        n_buckets, cap = self.buckets.shape
        grown = np.empty((n_buckets, 2 * cap), dtype=np.int32)
        grown[:, :cap] = self.buckets
        self.buckets = grown


_local = threading.local()


def workspace_for(height: int, width: int) -> Workspace:
    """This thread's shared workspace for (height, width) grids (the last size used is kept)."""
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


_NO_COST = np.zeros((1, 1), dtype=np.uint8)


class BucketSearch:
    """One search ``start -> goal`` over a (H, W) grid; ``run(budget)`` until FOUND or EXHAUSTED.

    ``passable`` (H, W) bool; ``cost`` (H, W) 0..255 cell costs (weighted only when
    ``cost_travel_multiplier`` is not 0); start/goal as (row, col). The start is expanded even if
    it is not passable (a robot may start in inflation); the goal must be passable (or be the
    start). ``step_scale`` (>= 1, keeping the heuristic consistent) multiplies every step. Without
    ``workspace`` the search gets arrays of its own."""

    canonical = False  # the kernel's pruning (CanonicalSearch)

    def __init__(
        self,
        passable: np.ndarray,
        cost: np.ndarray | None,
        start: tuple[int, int],
        goal: tuple[int, int],
        *,
        heuristic_weight: float = 1.0,
        cost_travel_multiplier: float = 0.0,
        step_scale: float = 1.0,
        width: float = BUCKET_WIDTH,
        workspace: Workspace | None = None,
    ) -> None:
        h, w = passable.shape
        sr, sc = int(start[0]), int(start[1])
        gr, gc = int(goal[0]), int(goal[1])
        if not (0 <= sr < h and 0 <= sc < w and 0 <= gr < h and 0 <= gc < w):
            raise ValueError(f"start {start} or goal {goal} is outside the {h} x {w} grid")
        if not (
            0.0 <= heuristic_weight < math.inf and 1.0 <= step_scale < math.inf and 0.0 < width < math.inf
        ):
            raise ValueError(
                "heuristic_weight must be finite >= 0, step_scale finite >= 1 and width > 0: "
                f"{heuristic_weight}, {step_scale}, {width}"
            )
        self.use_cost = cost is not None and cost_travel_multiplier != 0.0
        if self.use_cost and cost.shape != passable.shape:
            raise ValueError(f"cost {cost.shape} and passable {passable.shape} differ in shape")
        self.passable = passable
        self.cost = cost if self.use_cost else _NO_COST
        self.cost_factor = float(cost_travel_multiplier) / 252.0
        self.step_scale = float(step_scale)
        self.heuristic_weight = float(heuristic_weight)
        self.width = float(width)
        self.shape = (h, w)
        self.start = (sr + 1) * (w + 2) + sc + 1
        self.goal = (gr + 1) * (w + 2) + gc + 1
        self.ws = workspace if workspace is not None else Workspace(h, w)
        max_step = SQRT2 * self.step_scale * ((1.0 + self.cost_factor * 255.0) if self.use_cost else 1.0)
        self.ws.ring(_n_buckets(max_step, self.heuristic_weight, self.width))
        self.ctl = np.zeros(4, dtype=np.int64)
        self.best = np.empty(1)
        self.path: np.ndarray | None = None

    def run(self, budget: int) -> int:
        """Expand at most ``budget`` cells; returns FOUND, EXHAUSTED or BUDGET."""
        ws = self.ws
        before = self.expansions
        while True:
            status, cells = _SEARCH[self.canonical](
                self.passable,
                self.cost,
                self.use_cost,
                self.cost_factor,
                self.step_scale,
                self.heuristic_weight,
                self.start,
                self.goal,
                self.width,
                int(budget) - (self.expansions - before),
                ws.state,
                ws.cost,
                ws.g,
                ws.buckets,
                ws.counts,
                self.ctl,
                self.best,
            )
            if status != _GROW:
                break
            ws.grow()
        if status == FOUND:
            self.path = cells
        return int(status)

    @property
    def expansions(self) -> int:
        return int(self.ctl[_EXPANSIONS])

    @property
    def goal_cost(self) -> float:
        """The goal's cost (inf until a path reached it)."""
        return float(self.best[0])

    @property
    def closed(self) -> np.ndarray:
        """(H, W) bool mask of the cells whose cost is final or that were expanded."""
        h, w = self.shape
        return (self.ws.state.reshape(h + 2, w + 2)[1:-1, 1:-1] & 3) == _CLOSED

    def _flat(self, row: int, col: int) -> int:
        return (row + 1) * (self.shape[1] + 2) + col + 1

    def cells_to(self, row: int, col: int) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the path start -> (row, col), which must be closed."""
        cells = _trace(self.ws.state, self.start, self._flat(row, col), self.shape[1] + 2)
        return cells[:, 0], cells[:, 1]

    def cost_to(self, row: int, col: int) -> float:
        """Accumulated step cost from the start to a closed cell."""
        return float(self.ws.g[self._flat(row, col)])
