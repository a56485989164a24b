"""``navdeck explore``: explore a simulated world with one click, on a virtual clock.

The server's session with its mapping, localization, navigation and exploration features (no HTTP),
the simulator running the real world, the robot starting with no map at all. Exploration runs until
no reachable frontier is left, the time budget or the timeout; the map SLAM built is then compared
with the world's truth (``bench.explore.compare``). Prints (``--json``) ``{"state", "explored_pct",
"time_s", "path_length_m", "collisions", "map_agreement_pct", ...}``.

``--world`` is a stock world name (``apartment``, ``office``, ``greenhouse``), a world YAML path,
or a generated world ``FAMILY:SEED`` (``apartment:3``, ``office:12``; docs/worldgen.md).
``run_explore`` is the library entry point of the benchmark (``bench/explore.py``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli import CliError
from app.commands.sim_nav import _pose_arg

if TYPE_CHECKING:
    from app.features.exploration import Exploration
    from app.features.mapping import Mapping
    from app.features.navigation import Navigation
    from app.session import Session
    from nav.types import Pose2D
    from robot.sim import SimDriver, World


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "explore",
        help="explore a simulated world from no map (SLAM + frontiers + navigation) on a virtual clock",
    )
    p.add_argument(
        "--world", required=True, help="stock world name, world YAML, or a generated FAMILY:SEED (office:3)"
    )
    p.add_argument(
        "--start", type=_pose_arg, help="start x,y,theta in the world (default: a random free pose)"
    )
    p.add_argument("--profile", default="skid4", help="robot profile name or TOML path (default skid4)")
    p.add_argument("--seed", type=int, default=0, help="simulator noise and random start")
    p.add_argument("--time-budget", type=float, default=None, help="exploration time budget (simulated s)")
    p.add_argument("--timeout", type=float, default=1200.0, help="simulated seconds before giving up")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


@dataclass(frozen=True)
class ExploreConfig:
    world: str
    start: tuple[float, float, float] | None = None
    profile: str = "skid4"
    seed: int = 0
    time_budget: float | None = None
    timeout: float = 1200.0


@dataclass
class ExploreResult:
    world: str
    state: str
    reason: str
    explored_pct: float
    """Of the free area the robot can see from where it can go (``bench.explore.compare``), the
    share its map holds in agreement with the world: known free, or the wall's face (%)."""
    explored_free_pct: float
    """Of the same area, the share its map knows as free (%)."""
    explored_area_m2: float
    reachable_free_area_m2: float
    map_agreement_pct: float
    """Known cells of the built map whose class (free / occupied) matches the world (%)."""
    time_s: float
    path_length_m: float
    collisions: int
    goals_sent: int
    goals_failed: int
    start: tuple[float, float, float]
    wall_s: float
    slam_error_mean_m: float = math.nan
    """SLAM's trajectory against the true one (``bench.explore.slam_drift``): mean position error."""
    slam_error_max_m: float = math.nan
    slam_scale_pct: tuple[float, float] = (math.nan, math.nan)
    """The map's scale error along world x and y (%): a wall d metres from the start is drawn about
    d * scale off (negative: the map is smaller than the world)."""

    def as_dict(self) -> dict[str, Any]:
        def clean(v: Any) -> Any:
            if isinstance(v, float):
                return round(v, 3) if math.isfinite(v) else None
            if isinstance(v, tuple):
                return [clean(x) for x in v]
            return v

        return {k: clean(v) for k, v in asdict(self).items()}


@dataclass
class ExploreStack:
    session: Session
    driver: SimDriver
    world: World
    mapping: Mapping
    navigation: Navigation
    exploration: Exploration


def load_world(spec: str) -> World:
    """A stock name, a YAML path or ``FAMILY:SEED``; ``CliError`` when it is none of them."""
    from maps.stock import UnknownWorldError, stock_world_path
    from robot.sim import World
    from robot.sim.worldgen import WorldgenError, generate

    family, sep, seed = spec.partition(":")
    if sep:
        try:
            return generate(family, int(seed)).world()
        except (ValueError, WorldgenError) as exc:
            raise CliError(f"--world {spec}: {exc}") from None
    path = Path(spec)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise CliError(f"--world {spec}: no such file")
        return World.from_yaml(path)
    try:
        return World.from_yaml(stock_world_path(spec))
    except UnknownWorldError as exc:
        raise CliError(str(exc)) from None


def random_start(world: World, profile: str, seed: int) -> Pose2D:
    """A free pose with room to turn (the circumscribed radius + 0.2 m clear), drawn from ``seed``
    among the cells of the largest region the robot fits in."""
    import numpy as np
    from scipy import ndimage

    from nav.types import Pose2D
    from robot.profiles import load_profile

    radius = load_profile(profile).circumscribed_radius
    clear = world.clearance_map >= radius + world.geometry.resolution
    labels, n = ndimage.label(clear, structure=np.ones((3, 3), bool))
    if n == 0:
        raise CliError(f"{world.name}: no place the robot fits")
    biggest = int(np.argmax(np.bincount(labels.ravel())[1:])) + 1
    ok = (labels == biggest) & (world.clearance_map >= radius + 0.2)
    rows, cols = np.nonzero(ok)
    rng = np.random.default_rng(seed)
    i = int(rng.integers(rows.size))
    xy = world.geometry.cell_to_world(rows[i : i + 1], cols[i : i + 1])[0]
    return Pose2D(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))


def build_explore_stack(
    world: World, start: Pose2D, *, profile: str = "skid4", seed: int = 0
) -> ExploreStack:
    """The server's pipeline on a virtual clock, wired as ``Runtime.start`` does, with no prior map:
    the localization feature has none (AMCL is off while mapping anyway)."""
    from app.features.exploration import Exploration
    from app.features.localization import Localization
    from app.features.mapping import Mapping
    from app.features.navigation import Navigation
    from app.session import Session
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.sim import SimDriver

    prof = load_profile(profile)
    clock = VirtualClock()
    driver = SimDriver(world, prof, clock, seed=seed, start_pose=start)
    session = Session(driver, clock=clock, grid=None, start_pose=start)
    mapping = Mapping(session)
    session.add_stage(mapping)
    loc = Localization(session, seed=seed)
    session.add_stage(loc)
    nav = Navigation(session, loc)
    nav.mapping = mapping
    mapping.add_grid_listener(nav.on_live_map)
    session.add_stage(nav)
    exploration = Exploration(session, mapping, nav)
    session.add_stage(exploration)
    return ExploreStack(session, driver, world, mapping, nav, exploration)


def run_explore(cfg: ExploreConfig, world: World | None = None) -> ExploreResult:
    """Explore ``cfg.world`` (or ``world``) to the end and compare the map with the truth."""
    import numpy as np

    from app.features.exploration import ENDED
    from bench.explore import compare, slam_drift
    from nav.types import Pose2D

    world = world if world is not None else load_world(cfg.world)
    start = Pose2D(*cfg.start) if cfg.start is not None else random_start(world, cfg.profile, cfg.seed)
    stack = build_explore_stack(world, start, profile=cfg.profile, seed=cfg.seed)
    s, ex = stack.session, stack.exploration
    wall0 = time.perf_counter()
    try:
        start_truth = stack.driver.truth_pose
        ex.start(cfg.time_budget)
        t0 = s.clock.now()
        last = start_truth
        length = 0.0
        path = [(s.clock.now(), start_truth.x, start_truth.y)]  # the true trajectory, per tick
        while s.clock.now() - t0 < cfg.timeout:
            s.run_for(s.period)
            truth = stack.driver.truth_pose
            length += last.distance_to(truth)
            last = truth
            path.append((s.clock.now(), truth.x, truth.y))
            if ex.state in ENDED:
                break
        elapsed = s.clock.now() - t0
        if ex.state not in ENDED:
            ex.stop("timeout")
            s.run_for(s.period)
        if stack.mapping.running:
            stack.mapping.stop()
        grid = stack.mapping.current_map()
        cmp = compare(grid, world, start_truth, start)
        slam = stack.mapping.slam
        drift = slam_drift(slam.trajectory(), np.array(path), start_truth) if slam is not None else None
        status = ex.status()
        return ExploreResult(
            world=cfg.world,
            state=status["state"] if elapsed < cfg.timeout else "timeout",
            reason=status["reason"],
            explored_pct=100.0 * cmp.explored,
            explored_free_pct=100.0 * cmp.explored_free,
            explored_area_m2=cmp.explored_area_m2,
            reachable_free_area_m2=cmp.reachable_area_m2,
            map_agreement_pct=100.0 * cmp.agreement,
            time_s=elapsed,
            path_length_m=length,
            collisions=s.collisions,
            goals_sent=status["goals_sent"],
            goals_failed=status["goals_failed"],
            start=(start.x, start.y, start.theta),
            wall_s=time.perf_counter() - wall0,
            **(
                {}
                if drift is None
                else {
                    "slam_error_mean_m": drift.mean_m,
                    "slam_error_max_m": drift.max_m,
                    "slam_scale_pct": drift.scale_pct,
                }
            ),
        )
    finally:
        s.close()


def run(args: argparse.Namespace) -> int:
    if args.time_budget is not None and not args.time_budget > 0:
        raise CliError("--time-budget must be a positive number of seconds")
    cfg = ExploreConfig(
        world=args.world,
        start=args.start,
        profile=args.profile,
        seed=args.seed,
        time_budget=args.time_budget,
        timeout=args.timeout,
    )
    res = run_explore(cfg)
    if args.json:
        print(json.dumps(res.as_dict()))
    else:
        print(
            f"{res.world}: {res.state} ({res.reason}) explored {res.explored_pct:.1f} % "
            f"({res.explored_area_m2:.1f} of {res.reachable_free_area_m2:.1f} m2) in {res.time_s:.0f} s, "
            f"path {res.path_length_m:.1f} m, collisions {res.collisions}, "
            f"map agreement {res.map_agreement_pct:.1f} %"
        )
    return 0
