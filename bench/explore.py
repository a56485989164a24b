"""Exploration (issue 18): explore stock and generated worlds from a random start with one click,
and send goals into unexplored parts of the office while mapping.

``explore``: ``navdeck explore`` on each stock world from the start drawn from seed 0.
``explore.family``: one new generated world per trial (``apartment:SEED``, ``office:SEED``,
``robot/sim/worldgen``), each from the start drawn from its seed; how many, which families and a
wall-time budget come from ``NAVDECK_EXPLORE_*`` (``FamilyConfig``). Figures per family:
- explored: of the *reachable free area* -- the world's free cells in the free region that holds
  the start (cells under tables and behind chair legs included: a lidar sees most of them) -- the
  share the built map holds in agreement with the world, by the agreement's own rule below: known
  free (map_saver ``free_thresh``), or occupied within one cell of a world wall (the wall's face at
  the map's resolution: a 5 cm map cell that straddles the face is occupied, ``nav/slam/render.py``
  "surface wins", and the two lattices are offset), compared in the world frame through the robot's
  true start pose (the SLAM map frame starts there, as in ``bench/ghost.py``); ``explored_free``
  is the share known free alone;
- map agreement: known cells of the built map whose class agrees with the world: a free cell
  (<= 25) where the world is free inside its outer walls, an occupied cell (>= 65) within one cell
  of a world wall (the map's registration error); cells in between are not counted; the world
  has a one-cell border of open ground (outer walls end at its grid's edge);
- SLAM's drift (``slam_drift``): its trajectory against the true one, and the map's scale error
  from an affine fit; a wall d metres from the start is drawn about d x scale off, which is why
  an office's agreement falls where an apartment's does not;
- collisions (runs with any control tick in contact, and the ticks);
- time, against the shortest tour that sees everything, which is not computed exactly (a watchman
  route: NP-hard) but bracketed (``Sight``: places every 0.2 m the robot's centre may occupy, sight
  by the simulator's ray caster all round to the lidar's range, travel at ``max_vel_x``, no
  turning): from below by ``tour_lower_bound_s`` (the robot must at least reach a place from which
  the last visible free cell is in sight: one way, not a tour), from above by ``greedy_tour`` (a
  feasible tour: greedy set cover of the visible cells, then nearest neighbour + 2-opt over
  shortest paths). time / greedy tour <= time / shortest tour <= time / lower bound.

``explore.navigate_while_mapping``: in the office, mapping from the corridor's west end, goals
drawn at random in the building's free space (0.45 m clear, >= 4 m from the start), most of them
in rooms the map has not seen. A goal in unknown space is refused, so the bench clicks as an
operator who knows the building would: the goal itself once the live map has it, else the open edge
of the map (a frontier) that leads there best (travel on the map to it plus the way on through the
building), again and again as the map grows; a click that fails is not repeated. Reached: the
robot's true position within 0.35 m of the goal (the goal checker's 0.25 m plus the SLAM map's
offset) within 300 s; collisions counted.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage, sparse

from app.commands.explore import ExploreConfig, build_explore_stack, load_world, random_start, run_explore
from bench.core import Benchmark, Figure
from bench.ghost import FREE_MAX, _world_free_and_exterior
from bench.visibility import visible_cells
from nav.exploration import FrontierExplorer, distance_field
from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, OccupancyGrid, Pose2D
from robot.profiles import load_profile
from robot.sim.worldgen import FAMILIES as WORLD_FAMILIES

OCCUPIED_MIN = 65


@dataclass(frozen=True)
class Comparison:
    explored: float
    """Share of the reachable free cells the map holds in agreement with the world: known free, or
    the wall's face (occupied within one cell of a world wall)."""
    explored_free: float
    """Share of the reachable free cells the map knows as free."""
    explored_area_m2: float
    reachable_area_m2: float
    agreement: float
    free_cells: int
    occupied_cells: int


def reachable_free(world, start: Pose2D) -> np.ndarray:
    """(H, W) bool: world free cells (inside the outer walls) connected to the start's cell."""
    interior, _ = _world_free_and_exterior(world.static_occupied)
    labels, _ = ndimage.label(interior, structure=np.ones((3, 3), bool))
    rows, cols = world.geometry.world_to_cell(np.array([[start.x, start.y]]))
    lab = labels[int(rows[0]), int(cols[0])]
    if lab == 0:
        raise ValueError(f"start ({start.x:.2f}, {start.y:.2f}) is not in the world's free space")
    return labels == lab


def compare(built: OccupancyGrid, world, map_in_world: Pose2D, start: Pose2D) -> Comparison:
    """The built map against the world (see the module docstring)."""
    wg = world.geometry
    reach = reachable_free(world, start)
    rows, cols = np.nonzero(reach)
    pts = wg.cell_to_world(rows, cols)
    bg = built.geometry
    br, bc = bg.world_to_cell(map_in_world.inverse().transform_points(pts))
    inside = bg.in_bounds(br, bc)
    vals = np.full(rows.size, -1, dtype=np.int16)
    vals[inside] = built.data[br[inside], bc[inside]]
    known_free = (vals >= 0) & (vals <= FREE_MAX)
    # within one cell of a wall, on the world grid with a one-cell border of open ground (below)
    near_wall_b = ndimage.binary_dilation(np.pad(world.static_occupied, 1), structure=np.ones((3, 3), bool))
    near_wall = near_wall_b[1:-1, 1:-1]
    # A free cell at a wall's face often lies, on the map's offset and rotated lattice, in a cell that
    # also covers the wall, and such a cell is occupied (nav/slam/render.py, surface wins; apartment:0:
    # 1180 of the 1456 free cells next to a wall): it is mapped as the wall's face, which the
    # agreement below also counts as agreeing.
    mapped = known_free | ((vals >= OCCUPIED_MIN) & near_wall[rows, cols])
    cell = wg.resolution * wg.resolution
    # every known cell of the built map, in the world
    kr, kc = np.nonzero(built.data >= 0)
    v = built.data[kr, kc]
    wpts = map_in_world.transform_points(bg.cell_to_world(kr, kc))
    wr, wc = wg.world_to_cell(wpts)
    # The world grid is judged with a one-cell border of open ground around it: generated worlds'
    # outer walls end at the grid's edge, so a map cell just past a wall's outer face lay off the
    # grid and counted as wrong even when occupied within one cell of that wall (office:4: 115 of
    # its 6175 disagreeing cells). A cell further out, or free out there, is still wrong.
    interior, _ = _world_free_and_exterior(world.static_occupied)
    interior_b = np.pad(interior, 1)
    wr, wc = wr + 1, wc + 1
    ok = (wr >= 0) & (wr < interior_b.shape[0]) & (wc >= 0) & (wc < interior_b.shape[1])
    wr, wc = np.clip(wr, 0, interior_b.shape[0] - 1), np.clip(wc, 0, interior_b.shape[1] - 1)
    is_free, is_occ = v <= FREE_MAX, v >= OCCUPIED_MIN
    agree_free = is_free & ok & interior_b[wr, wc]
    agree_occ = is_occ & ok & near_wall_b[wr, wc]
    counted = int(np.count_nonzero(is_free | is_occ))
    agree = int(np.count_nonzero(agree_free | agree_occ))
    return Comparison(
        explored=float(mapped.mean()) if rows.size else 0.0,
        explored_free=float(known_free.mean()) if rows.size else 0.0,
        explored_area_m2=float(np.count_nonzero(mapped)) * cell,
        reachable_area_m2=float(rows.size) * cell,
        agreement=agree / counted if counted else 0.0,
        free_cells=int(np.count_nonzero(is_free)),
        occupied_cells=int(np.count_nonzero(is_occ)),
    )


@dataclass(frozen=True)
class Drift:
    """SLAM's trajectory against the robot's true one, both in the world frame (the map frame
    placed at the true start pose, as ``compare`` places the map)."""

    mean_m: float
    """Mean position error (m) over the scans: the absolute trajectory error, no re-alignment."""
    max_m: float
    scale_pct: tuple[float, float]
    """The map's scale error along world x and y (%) of the least-squares affine fit
    ``slam - start = A (truth - start) + b``: ``diag(A) - 1``; negative when SLAM's map is smaller
    than the world. A wall ``d`` metres from the start is drawn about ``d * scale`` off."""
    residual_m: float
    """RMS position error (m) left after that fit: what the affine drift does not explain."""


def slam_drift(slam_traj: np.ndarray, truth: np.ndarray, map_in_world: Pose2D) -> Drift:
    """``slam_traj`` (N, >= 3) ``t, x, y, ...`` in the map frame (``GraphSlam.trajectory``) against
    ``truth`` (M, >= 3) ``t, x, y`` in the world, interpolated at the scans' stamps (scans outside
    the truth's time span are left out)."""
    inside = (slam_traj[:, 0] >= truth[0, 0]) & (slam_traj[:, 0] <= truth[-1, 0])
    traj = slam_traj[inside]
    if len(traj) < 3:
        return Drift(math.nan, math.nan, (math.nan, math.nan), math.nan)
    est = map_in_world.transform_points(traj[:, 1:3])
    true = np.column_stack(
        (np.interp(traj[:, 0], truth[:, 0], truth[:, 1]), np.interp(traj[:, 0], truth[:, 0], truth[:, 2]))
    )
    err = np.hypot(*(est - true).T)
    origin = np.array([map_in_world.x, map_in_world.y])
    design = np.column_stack((true - origin, np.ones(len(true))))
    fit, *_ = np.linalg.lstsq(design, est - origin, rcond=None)
    residual = est - origin - design @ fit
    return Drift(
        mean_m=float(err.mean()),
        max_m=float(err.max()),
        scale_pct=(float(100.0 * (fit[0, 0] - 1.0)), float(100.0 * (fit[1, 1] - 1.0))),
        residual_m=float(np.sqrt((residual**2).sum(axis=1).mean())),
    )


@dataclass(frozen=True)
class Sight:
    """What the lidar can see of the reachable free area, and from where (the tour figures' input).

    Candidate places are the passable cells (the circumscribed radius clear of walls) every
    ``stride`` m that the robot can reach from the start; sight is the simulator's ray caster,
    ``beams`` rays up to the lidar's range, all round (the robot can turn on the spot)."""

    views: np.ndarray
    """(V, 2) world x, y of the candidate places, in order of travel from the start."""
    travel: np.ndarray
    """(V,) shortest travel (m) from the start to each place over the passable cells."""
    sees: sparse.csr_matrix
    """(V, N) bool: place v sees target cell n (the reachable free cells, row-major order)."""
    passable: np.ndarray
    """(H, W) bool over the world: cells the robot's centre may occupy."""
    max_vel_x: float


def sight(world, start: Pose2D, profile: str = "skid4", stride: float = 0.2, beams: int = 360) -> Sight:
    """The candidate places and what each sees (class docstring): rays cast per chunk of places,
    the cells along them walked by a compiled kernel (``bench.visibility``)."""
    prof = load_profile(profile)
    wg = world.geometry
    res = wg.resolution
    passable = world.clearance_map >= prof.circumscribed_radius
    costs = np.where(passable, 0, 254).astype(np.uint8)
    dist = distance_field(Costmap(wg, costs), start, cost_travel_multiplier=0.0)
    k = max(1, round(stride / res))
    sub = np.zeros_like(passable)
    sub[::k, ::k] = True
    rows, cols = np.nonzero(sub & np.isfinite(dist))
    order = np.argsort(dist[rows, cols], kind="stable")
    rows, cols = rows[order], cols[order]
    views = wg.cell_to_world(rows, cols)
    target = reachable_free(world, start)
    index = np.full(target.shape, -1, dtype=np.int64)
    index[target] = np.arange(int(np.count_nonzero(target)))
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    steps = np.arange(0.0, prof.lidar.range_max, res)
    ranges = np.empty((len(views), beams))
    for a in range(0, len(views), 256):
        v = views[a : a + 256]
        ranges[a : a + 256] = world.raycaster.cast(
            v, np.broadcast_to(angles, (len(v), beams)), prof.lidar.range_max
        )
    ranges = np.where(np.isfinite(ranges), ranges, prof.lidar.range_max)
    sees = visible_cells(wg, index, views, ranges, angles, steps)
    return Sight(views, dist[rows, cols], sees, passable, prof.limits.max_vel_x)


def tour_lower_bound_s(s: Sight) -> float:
    """Seconds any exploration needs at least (module docstring): every free cell the lidar can see
    from somewhere must be seen, so the robot must at least reach, at ``max_vel_x``, a place from
    which the last of them is in sight. Places are taken in order of travel from the start; the
    distance at which the last visible free cell is first seen is the bound (one way, no turning)."""
    coo = s.sees.tocoo()
    if coo.nnz == 0:
        return 0.0
    first_seen = np.full(s.sees.shape[1], np.inf)
    np.minimum.at(first_seen, coo.col, s.travel[coo.row])
    seen = first_seen[np.isfinite(first_seen)]
    return float(seen.max()) / s.max_vel_x


@dataclass(frozen=True)
class Tour:
    """A tour from the start through places that together see every visible reachable free cell."""

    places: np.ndarray
    """(K, 2) world x, y in the order visited."""
    length_m: float
    seconds: float
    """``length_m`` at ``max_vel_x`` (no turning, no acceleration)."""


def greedy_tour(world, start: Pose2D, s: Sight) -> Tour:
    """A watchman tour by the usual two steps: greedy set cover (the place that sees most of the
    still unseen cells, until every visible cell is seen), then an open path from the start through
    those places (nearest neighbour, improved by 2-opt) over shortest-path travel distances.

    It is a feasible tour, not the optimum: the shortest tour that sees everything (with the same
    sight and no turning) is no longer than it; ``tour_lower_bound_s`` bounds it from below."""
    sees = s.sees.astype(np.float32)
    unseen = np.asarray(sees.sum(axis=0)).ravel() > 0  # only cells some place sees
    chosen: list[int] = []
    while unseen.any():
        gain = sees @ unseen.astype(np.float32)
        v = int(np.argmax(gain))
        if gain[v] <= 0:
            break
        chosen.append(v)
        unseen[sees.indices[sees.indptr[v] : sees.indptr[v + 1]]] = False
    if not chosen:
        return Tour(np.zeros((0, 2)), 0.0, 0.0)
    wg = world.geometry
    costs = Costmap(wg, np.where(s.passable, 0, 254).astype(np.uint8))
    places = s.views[chosen]
    nodes = [start, *(Pose2D(float(x), float(y), 0.0) for x, y in places)]
    rows, cols = wg.world_to_cell(np.array([[p.x, p.y] for p in nodes]))
    d = np.empty((len(nodes), len(nodes)))
    for i, p in enumerate(nodes):  # one Dijkstra field per place (tens)
        d[i] = distance_field(costs, p, cost_travel_multiplier=0.0)[rows, cols]
    d = np.minimum(d, d.T)  # the grid search is symmetric up to ties
    order = _nearest_neighbour_path(d)
    order = _two_opt_path(d, order)
    length = float(d[order[:-1], order[1:]].sum())
    return Tour(places[np.asarray(order[1:]) - 1], length, length / s.max_vel_x)


def _nearest_neighbour_path(d: np.ndarray) -> list[int]:
    """An open path from node 0 through every node, always to the nearest one not visited."""
    left = np.ones(len(d), dtype=bool)
    left[0] = False
    order = [0]
    while left.any():
        row = np.where(left, d[order[-1]], np.inf)
        nxt = int(np.argmin(row))
        order.append(nxt)
        left[nxt] = False
    return order


def _two_opt_path(d: np.ndarray, order: list[int]) -> list[int]:
    """2-opt on an open path with a fixed first node: reverse ``order[i:j+1]`` while that shortens
    it (the last node is free, so a reversal up to the end changes one edge only)."""
    o = np.asarray(order)
    n = len(o)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            j = np.arange(i + 1, n)
            before = d[o[i - 1], o[i]] + np.where(j + 1 < n, d[o[j], o[np.minimum(j + 1, n - 1)]], 0.0)
            after = d[o[i - 1], o[j]] + np.where(j + 1 < n, d[o[i], o[np.minimum(j + 1, n - 1)]], 0.0)
            gain = before - after
            k = int(np.argmax(gain))
            if gain[k] > 1e-9:
                o[i : j[k] + 1] = o[i : j[k] + 1][::-1].copy()
                improved = True
    return o.tolist()


STOCK = ("apartment", "office", "greenhouse")
FAMILIES = ("apartment", "office")


@dataclass(frozen=True)
class FamilyConfig:
    """``explore.family`` from the environment (``NAVDECK_EXPLORE_*``; see docs/benchmarks.md)."""

    trials: int = 25
    """Generated worlds per family (``NAVDECK_EXPLORE_TRIALS``): 25 apartments + 25 offices = 50."""
    families: tuple[str, ...] = FAMILIES
    """``NAVDECK_EXPLORE_FAMILIES``, comma-separated worldgen family names."""
    first_seed: int = 0
    """``NAVDECK_EXPLORE_SEED0``: seeds ``first_seed .. first_seed + trials - 1`` (world and start)."""
    budget_s: float = math.inf
    """``NAVDECK_EXPLORE_BUDGET_S``: wall seconds after which no new trial starts (the one running
    finishes); the figures say how many trials ran."""
    timeout_s: float = 1800.0
    """``NAVDECK_EXPLORE_TIMEOUT_S``: simulated seconds one exploration may take."""
    log: str | None = None
    """``NAVDECK_EXPLORE_LOG``: a JSONL file each trial's result is appended to as it ends."""

    @classmethod
    def from_env(cls, env: Mapping[str, str]) -> FamilyConfig:
        def num(name: str, default: float, kind: type = float) -> Any:
            raw = env.get(name, "").strip()
            if not raw:
                return default
            try:
                value = kind(raw)
            except ValueError:
                raise ValueError(f"{name}={raw!r} is not a number") from None
            if not (value > 0 or (name == "NAVDECK_EXPLORE_SEED0" and value >= 0)):
                raise ValueError(f"{name}={raw!r} must be positive")
            return value

        names = tuple(f.strip() for f in env.get("NAVDECK_EXPLORE_FAMILIES", "").split(",") if f.strip())
        unknown = [f for f in names if f not in WORLD_FAMILIES]
        if unknown:
            raise ValueError(
                f"NAVDECK_EXPLORE_FAMILIES: unknown {unknown}; one of {', '.join(WORLD_FAMILIES)}"
            )
        return cls(
            trials=num("NAVDECK_EXPLORE_TRIALS", cls.trials, int),
            families=names or FAMILIES,
            first_seed=num("NAVDECK_EXPLORE_SEED0", cls.first_seed, int),
            budget_s=num("NAVDECK_EXPLORE_BUDGET_S", cls.budget_s),
            timeout_s=num("NAVDECK_EXPLORE_TIMEOUT_S", cls.timeout_s),
            log=env.get("NAVDECK_EXPLORE_LOG") or None,
        )

    def worlds(self) -> list[tuple[str, int]]:
        """(family, seed) in the order run: families interleaved, so a budget cut leaves each with
        about as many trials."""
        return [(f, s) for s in range(self.first_seed, self.first_seed + self.trials) for f in self.families]


def run_one(world_spec: str, seed: int, timeout: float = 1800.0) -> dict[str, float]:
    """One exploration of ``world_spec`` from the start drawn from ``seed``, with its tour figures."""
    world = load_world(world_spec)
    start = random_start(world, "skid4", seed)
    res = run_explore(
        ExploreConfig(world=world_spec, start=(start.x, start.y, start.theta), seed=seed, timeout=timeout),
        world,
    )
    seen = sight(world, start)
    bound = tour_lower_bound_s(seen)
    tour = greedy_tour(world, start, seen)
    return {
        "explored_pct": res.explored_pct,
        "explored_free_pct": res.explored_free_pct,
        "agreement_pct": res.map_agreement_pct,
        "collisions": float(res.collisions),
        "time_s": res.time_s,
        "bound_s": bound,
        "ratio": res.time_s / bound if bound > 0 else math.inf,
        "tour_s": tour.seconds,
        "tour_places": float(len(tour.places)),
        "tour_ratio": res.time_s / tour.seconds if tour.seconds > 0 else math.inf,
        "complete": float(res.state == "complete"),
        "goals_sent": float(res.goals_sent),
        "goals_failed": float(res.goals_failed),
        "path_m": res.path_length_m,
        "wall_s": res.wall_s,
        "slam_error_mean_m": res.slam_error_mean_m,
        "slam_error_max_m": res.slam_error_max_m,
        "slam_scale_x_pct": res.slam_scale_pct[0],
        "slam_scale_y_pct": res.slam_scale_pct[1],
    }


def _family_figures(name: str, runs: list[dict[str, float]]) -> list[Figure]:
    n = len(runs)
    if n == 0:
        return [Figure(f"{name}: trials run", 0.0, "", ">= 1", False)]
    explored = np.array([r["explored_pct"] for r in runs])
    free = np.array([r["explored_free_pct"] for r in runs])
    agree = np.array([r["agreement_pct"] for r in runs])
    coll = np.array([r["collisions"] for r in runs])
    ratio = np.array([r["ratio"] for r in runs])
    tour_ratio = np.array([r["tour_ratio"] for r in runs])
    time_s = np.array([r["time_s"] for r in runs])
    # SLAM's drift beside the agreement: a map drawn d metres from the start is about d * scale off
    scale = np.abs([[r.get("slam_scale_x_pct", math.nan), r.get("slam_scale_y_pct", math.nan)] for r in runs])
    slam_max = np.array([r.get("slam_error_max_m", math.nan) for r in runs])
    return [
        Figure(f"{name} (N={n}): explored, mean", float(explored.mean()), "%"),
        Figure(
            f"{name} (N={n}): explored, worst",
            float(explored.min()),
            "%",
            ">= 95",
            bool(explored.min() >= 95),
        ),
        Figure(f"{name} (N={n}): runs explored >= 95 %", float(np.count_nonzero(explored >= 95)), "runs"),
        Figure(f"{name} (N={n}): known free (wall faces not counted), mean", float(free.mean()), "%"),
        Figure(f"{name} (N={n}): known free (wall faces not counted), worst", float(free.min()), "%"),
        Figure(f"{name} (N={n}): map agreement, mean", float(agree.mean()), "%"),
        Figure(
            f"{name} (N={n}): map agreement, worst", float(agree.min()), "%", ">= 98", bool(agree.min() >= 98)
        ),
        Figure(
            f"{name} (N={n}): runs with a collision",
            float(np.count_nonzero(coll)),
            "runs",
            "0",
            not coll.any(),
        ),
        Figure(f"{name} (N={n}): control ticks in contact, total", float(coll.sum()), "ticks"),
        Figure(
            f"{name} (N={n}): ended with no reachable frontier",
            float(sum(r["complete"] for r in runs)),
            "runs",
        ),
        Figure(f"{name} (N={n}): time, median", float(np.median(time_s)), "s"),
        Figure(f"{name} (N={n}): time, worst", float(time_s.max()), "s"),
        Figure(f"{name} (N={n}): time / greedy watchman tour, median", float(np.median(tour_ratio)), "x"),
        Figure(f"{name} (N={n}): time / tour lower bound, median", float(np.median(ratio)), "x"),
        Figure(f"{name} (N={n}): SLAM trajectory error, worst max", _worst(slam_max), "m"),
        Figure(f"{name} (N={n}): SLAM map scale error, worst |%|", _worst(scale), "%"),
    ]


def _worst(values: np.ndarray) -> float:
    """The largest finite value (nan when there is none: runs from before the figure existed)."""
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else math.nan


def run_family(cfg: FamilyConfig, clock: Callable[[], float] = time.monotonic) -> dict[str, list[dict]]:
    """Explore one new generated world per trial (``cfg.worlds()``) until done or the wall budget is
    spent; each result is printed (and appended to ``cfg.log``) as it ends."""
    runs: dict[str, list[dict]] = {f: [] for f in cfg.families}
    t0 = clock()
    for family, seed in cfg.worlds():
        if clock() - t0 >= cfg.budget_s:
            print(f"  explore.family: wall budget of {cfg.budget_s:g} s spent, trials stop here")
            break
        r = run_one(f"{family}:{seed}", seed, timeout=cfg.timeout_s)
        runs[family].append(r)
        line = {"world": f"{family}:{seed}", **{k: round(v, 3) for k, v in r.items()}}
        print(f"  {json.dumps(line)}", flush=True)
        if cfg.log:
            with open(cfg.log, "a") as fh:
                fh.write(json.dumps(line) + "\n")
    return runs


def _explore() -> list[Figure]:
    out: list[Figure] = []
    for name in STOCK:
        out.extend(_family_figures(f"stock {name}", [run_one(name, 0)]))
    return out


def _explore_family() -> list[Figure]:
    runs = run_family(FamilyConfig.from_env(os.environ))
    return [fig for family, rs in runs.items() for fig in _family_figures(f"generated {family}", rs)]


BENCHMARKS = [
    Benchmark(name="explore", run=_explore, group="slow"),
    Benchmark(name="explore.family", run=_explore_family, group="slow"),
]


# --------------------------------------------------------------------------- navigate while mapping
OFFICE_START = Pose2D(2.0, 10.0, 0.0)  # the corridor's west end (bench/mapping.py)


def _unexplored_goals(world, start: Pose2D, n: int, seed: int, clearance: float) -> list[Pose2D]:
    """``n`` world poses in free space with ``clearance`` m around them, each at least 4 m from the
    start, in the order drawn (the map has not seen most of them when they are sent)."""
    rng = np.random.default_rng(seed)
    reach = reachable_free(world, start) & (world.clearance_map >= clearance)
    rows, cols = np.nonzero(reach)
    pts = world.geometry.cell_to_world(rows, cols)
    pts = pts[np.hypot(pts[:, 0] - start.x, pts[:, 1] - start.y) >= 4.0]
    pick = rng.choice(len(pts), size=n, replace=False)
    return [Pose2D(float(x), float(y), float(rng.uniform(-math.pi, math.pi))) for x, y in pts[pick]]


def _known(nav, target: Pose2D) -> bool:
    """Whether the live costmap has ``target`` as a traversable known cell (a goal it accepts)."""
    cm = nav.global_costmap
    rows, cols = cm.geometry.world_to_cell(np.array([[target.x, target.y]]))
    return bool(
        cm.geometry.in_bounds(rows, cols)[0] and cm.costs[rows[0], cols[0]] < INSCRIBED_INFLATED_OBSTACLE
    )


def _toward(nav, explorer, target: Pose2D, pose: Pose2D, onward) -> Pose2D | None:
    """What an operator clicks to get to ``target`` (map frame) while mapping: the target itself
    once the map knows it as traversable, else the goal of the open edge of the map (a frontier)
    that leads there best: least travel to it plus ``onward(x, y)``, the way on from there to the
    target through the building (the operator knows the building; the robot's map does not).
    None: no frontier is left to try."""
    if _known(nav, target):
        return target
    report = explorer.find(nav.live_grid, nav.global_costmap, pose)
    best, score = None, math.inf
    for f in report.reachable:
        g = f.goal
        if explorer.is_banned(g) or math.hypot(g[0] - pose.x, g[1] - pose.y) < 0.4:
            continue
        s = f.travel + onward(g[0], g[1])
        if s < score:
            best, score = g, s
    return None if best is None else Pose2D(best[0], best[1], target.theta)


def _print_goal(i: int, goal: Pose2D, reached: bool, sim_s: float, collisions: int) -> None:
    mark = "ok " if reached else "MISS"
    print(
        f"  {mark} goal {i} ({goal.x:.2f}, {goal.y:.2f}) at {sim_s:.1f} s simulated, "
        f"{collisions} collision ticks",
        file=sys.stderr,
        flush=True,
    )


def navigate_while_mapping(
    n_goals: int = 20,
    seed: int = 0,
    per_goal_s: float = 300.0,
    on_goal: Callable[[int, Pose2D, bool, float, int], None] | None = _print_goal,
) -> dict[str, float]:
    """Office, mapping from the corridor: goals drawn in its free space, reached by clicking towards
    each on the growing map (``_toward``) until it is known, then on it. Reached: the robot's true
    position within 0.35 m of the goal (the goal checker's 0.25 m plus the SLAM map's drift).
    ``on_goal(index, goal, reached, simulated s so far, collision ticks so far)`` after each goal."""
    world = load_world("office")
    radius = load_profile("skid4").circumscribed_radius
    passable = np.where(world.clearance_map >= radius, 0, 254).astype(np.uint8)
    stack = build_explore_stack(world, OFFICE_START, seed=seed)
    s, nav = stack.session, stack.navigation
    start_truth = stack.driver.truth_pose
    reached = failed_goals = 0
    sim0 = s.clock.now()
    try:
        stack.mapping.start()
        while not nav.mapping_live():
            s.run_for(s.period)
        goals = _unexplored_goals(world, OFFICE_START, n_goals, seed, clearance=0.45)
        for i, g in enumerate(goals):
            target = g.relative_to(start_truth)  # the map frame starts at the true start pose
            to_goal = distance_field(Costmap(world.geometry, passable), g, cost_travel_multiplier=0.0)
            # a map cell near a wall may lie just off the truth's passable cells: look 0.3 m around
            to_goal = ndimage.minimum_filter(to_goal, size=13, mode="constant", cval=np.inf)

            def onward(x: float, y: float, field=to_goal) -> float:
                p = start_truth.transform_points(np.array([[x, y]]))
                r, c = world.geometry.world_to_cell(p)
                inside = world.geometry.in_bounds(r, c)[0]
                return float(field[r[0], c[0]]) if inside else math.inf

            t0 = s.clock.now()
            edges = FrontierExplorer()  # frontiers clicked in vain for this goal are not clicked again
            while s.clock.now() - t0 < per_goal_s:
                click = _toward(nav, edges, target, s.pose, onward)
                if click is None:
                    break
                try:
                    nav.set_goals([click])
                except (ValueError, RuntimeError):
                    edges.mark_failed((click.x, click.y))
                    s.run_for(1.0)
                    continue
                while s.clock.now() - t0 < per_goal_s:
                    s.run_for(s.period)
                    if not nav.active and nav.pending_request() is None:
                        break
                    if click is not target and nav.active and _known(nav, target):
                        break  # the target came into the map on the way: click it now
                kind = (nav.last_outcome or {}).get("kind")
                if click is target and kind == "reached":
                    break
                if kind == "failed":
                    edges.mark_failed((click.x, click.y))
            truth = stack.driver.truth_pose
            ok = truth.distance_to(g) <= 0.35
            reached += ok
            failed_goals += not ok
            if on_goal is not None:
                on_goal(i, g, ok, s.clock.now() - sim0, s.collisions)
        return {
            "goals": float(len(goals)),
            "reached": float(reached),
            "collisions": float(s.collisions),
            "sim_s": s.clock.now() - sim0,
            "mode_changes": float(sum(1 for e in s.events if e["type"] == "mode")),
        }
    finally:
        s.close()


GOALS_VAR = "NAVDECK_NWM_GOALS"
"""Goals of ``explore.navigate_while_mapping`` (default 50, the issue's N)."""


def _navigate_while_mapping() -> list[Figure]:
    r = navigate_while_mapping(n_goals=int(os.environ.get(GOALS_VAR, "50")))
    n = int(r["goals"])
    rate = r["reached"] / n if n else 0.0
    return [
        Figure(
            f"office, goals in unexplored parts (N={n}): reached", 100.0 * rate, "%", ">= 95", rate >= 0.95
        ),
        Figure(
            f"office, goals in unexplored parts (N={n}): collisions",
            r["collisions"],
            "",
            "0",
            r["collisions"] == 0,
        ),
        Figure(f"office, goals in unexplored parts (N={n}): simulated time", r["sim_s"], "s"),
    ]


BENCHMARKS.append(Benchmark(name="explore.navigate_while_mapping", run=_navigate_while_mapping, group="slow"))
