"""Exploration (issue 18): explore stock and generated worlds from a random start with one click,
and send goals into unexplored parts of the office while mapping.

``explore``: ``navdeck explore`` on each stock world and on generated apartments and offices
(``robot/sim/worldgen``), each from a random start drawn from its seed. Figures per family:
- explored: of the *reachable free area* -- the world's free cells in the free region that holds
  the start (cells under tables and behind chair legs included: a lidar sees most of them) -- the
  share the built map knows as free (map_saver ``free_thresh``), compared in the world frame through
  the robot's true start pose (the SLAM map frame starts there, as in ``bench/ghost.py``);
- map agreement: known cells of the built map whose class agrees with the world: a free cell
  (<= 25) where the world is free inside its outer walls, an occupied cell (>= 65) within one cell
  of a world wall (the map's registration error); cells in between are not counted;
- collisions; time and the ratio to a lower bound of the time any tour that sees everything needs:
  the robot must at least reach, for the free cell hardest to see, a place within lidar range of
  it, so ``max over free cells of (the shortest path, at the profile's max_vel_x, from the start to
  the nearest reachable cell within the lidar's range square around it)`` -- walls do not block
  sight in the bound (relaxed), and it is one way, not a tour: a loose lower bound, and the ratio an
  upper bound of how far from the best tour the exploration is.

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

import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from app.commands.explore import ExploreConfig, build_explore_stack, load_world, random_start, run_explore
from bench.core import Benchmark, Figure
from bench.ghost import FREE_MAX, _world_free_and_exterior
from nav.exploration import FrontierExplorer, distance_field
from nav.types import INSCRIBED_INFLATED_OBSTACLE, Costmap, OccupancyGrid, Pose2D
from robot.profiles import load_profile

OCCUPIED_MIN = 65


@dataclass(frozen=True)
class Comparison:
    explored: float
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
    cell = wg.resolution * wg.resolution
    # every known cell of the built map, in the world
    kr, kc = np.nonzero(built.data >= 0)
    v = built.data[kr, kc]
    wpts = map_in_world.transform_points(bg.cell_to_world(kr, kc))
    wr, wc = wg.world_to_cell(wpts)
    ok = wg.in_bounds(wr, wc)
    wr, wc = np.clip(wr, 0, wg.height - 1), np.clip(wc, 0, wg.width - 1)
    interior, _ = _world_free_and_exterior(world.static_occupied)
    near_wall = ndimage.binary_dilation(world.static_occupied, structure=np.ones((3, 3), bool))
    is_free, is_occ = v <= FREE_MAX, v >= OCCUPIED_MIN
    agree_free = is_free & ok & interior[wr, wc]
    agree_occ = is_occ & ok & near_wall[wr, wc]
    counted = int(np.count_nonzero(is_free | is_occ))
    agree = int(np.count_nonzero(agree_free | agree_occ))
    return Comparison(
        explored=float(known_free.mean()) if rows.size else 0.0,
        explored_area_m2=float(np.count_nonzero(known_free)) * cell,
        reachable_area_m2=float(rows.size) * cell,
        agreement=agree / counted if counted else 0.0,
        free_cells=int(np.count_nonzero(is_free)),
        occupied_cells=int(np.count_nonzero(is_occ)),
    )


def tour_lower_bound_s(
    world, start: Pose2D, profile: str = "skid4", stride: float = 0.2, beams: int = 360
) -> float:
    """Seconds any exploration needs at least (module docstring): every free cell the lidar can see
    from somewhere must be seen, so the robot must at least reach, at ``max_vel_x``, a place from
    which the last of them is in sight. Candidate places: passable cells (the circumscribed radius
    clear of walls) every ``stride`` m; sight: the simulator's ray caster, ``beams`` rays up to the
    lidar's range. Places are taken in order of travel distance from the start (one Dijkstra field);
    the distance at which the last visible free cell is first seen is the bound."""
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
    d_view = dist[rows, cols]
    views = wg.cell_to_world(rows, cols)
    target = reachable_free(world, start)
    first_seen = np.full(target.shape, np.inf)
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    steps = np.arange(0.0, prof.lidar.range_max, res)
    for a in range(0, len(views), 32):
        v = views[a : a + 32]
        ranges = world.raycaster.cast(v, np.broadcast_to(angles, (len(v), beams)), prof.lidar.range_max)
        ranges = np.where(np.isfinite(ranges), ranges, prof.lidar.range_max)
        along = steps[None, None, :] < ranges[:, :, None]  # (V, B, S): samples before the hit
        vi, bi, si = np.nonzero(along)
        pts = v[vi] + steps[si, None] * np.column_stack((np.cos(angles[bi]), np.sin(angles[bi])))
        pr, pc = wg.world_to_cell(pts)
        ok = wg.in_bounds(pr, pc)
        # views come in increasing distance: a cell keeps the first (smallest) distance it got
        np.minimum.at(first_seen, (pr[ok], pc[ok]), d_view[a + vi[ok]])
    seen = first_seen[target]
    seen = seen[np.isfinite(seen)]
    return float(seen.max()) / prof.limits.max_vel_x if seen.size else 0.0


STOCK = ("apartment", "office", "greenhouse")
FAMILY_SEEDS = {"apartment": range(0, 4), "office": range(0, 2)}
"""Generated worlds per family in the default run (each is minutes of simulated exploring on the
2-core machine); ``run_family`` takes any range."""


def run_one(world_spec: str, seed: int, timeout: float = 1800.0) -> dict[str, float]:
    world = load_world(world_spec)
    start = random_start(world, "skid4", seed)
    res = run_explore(
        ExploreConfig(world=world_spec, start=(start.x, start.y, start.theta), seed=seed, timeout=timeout),
        world,
    )
    bound = tour_lower_bound_s(world, start)
    return {
        "explored_pct": res.explored_pct,
        "agreement_pct": res.map_agreement_pct,
        "collisions": float(res.collisions),
        "time_s": res.time_s,
        "bound_s": bound,
        "ratio": res.time_s / bound if bound > 0 else math.inf,
        "complete": float(res.state == "complete"),
        "path_m": res.path_length_m,
        "wall_s": res.wall_s,
    }


def _family_figures(name: str, runs: list[dict[str, float]]) -> list[Figure]:
    n = len(runs)
    explored = np.array([r["explored_pct"] for r in runs])
    agree = np.array([r["agreement_pct"] for r in runs])
    coll = sum(r["collisions"] for r in runs)
    ratio = np.array([r["ratio"] for r in runs])
    return [
        Figure(
            f"{name} (N={n}): explored, mean",
            float(explored.mean()),
            "%",
            ">= 95",
            bool(explored.min() >= 95),
        ),
        Figure(f"{name} (N={n}): explored, worst", float(explored.min()), "%"),
        Figure(
            f"{name} (N={n}): map agreement, worst", float(agree.min()), "%", ">= 98", bool(agree.min() >= 98)
        ),
        Figure(f"{name} (N={n}): collisions", float(coll), "", "0", coll == 0),
        Figure(
            f"{name} (N={n}): ended with no reachable frontier",
            float(sum(r["complete"] for r in runs)),
            "runs",
        ),
        Figure(f"{name} (N={n}): time, mean", float(np.mean([r["time_s"] for r in runs])), "s"),
        Figure(f"{name} (N={n}): time / lower bound, median", float(np.median(ratio)), "x"),
    ]


def run_family(family: str, seeds: range) -> list[Figure]:
    return _family_figures(f"generated {family}", [run_one(f"{family}:{s}", s) for s in seeds])


def _explore() -> list[Figure]:
    out: list[Figure] = []
    for name in STOCK:
        out.extend(_family_figures(f"stock {name}", [run_one(name, 0)]))
    for family, seeds in FAMILY_SEEDS.items():
        out.extend(run_family(family, seeds))
    return out


BENCHMARKS = [Benchmark(name="explore", run=_explore, group="slow")]


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
        if explorer._blacklisted(g) or math.hypot(g[0] - pose.x, g[1] - pose.y) < 0.4:
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
