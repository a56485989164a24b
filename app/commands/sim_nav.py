"""``navdeck sim-nav``: drive the simulated robot to a goal with the whole stack, as fast as possible.

The same ``Session`` and the same localization and navigation features as the server (no HTTP), on
a ``VirtualClock`` that the loop advances one control period at a time: deterministic for a seed and
limited only by the CPU. Prints ``{"reached", "time_s", "path_length_m", "recoveries", "collisions",
"min_clearance_m", "localization_error_m", "controller", ...}`` (``--json``) or a one-line summary.
``--controller teb`` drives with TEB instead of DWA; ``--people N`` adds N random walkers
(0.5-1.2 m/s, ``Crowd.populate``) that the robot must get round. ``--no-prior-map`` gives the robot
an all-unknown map of the world's size (the simulator still runs the real world): the costmaps fill
from the lidar, the planner crosses unknown space, goals in unknown space are accepted, and the pose
comes from the simulator's truth (AMCL cannot localize in a blank map; SLAM is ``navdeck slam``'s).

``run_sim_nav`` is the library entry point used by the scenario suite (``bench/scenarios``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli import CliError

if TYPE_CHECKING:
    from app.features.localization import Localization
    from app.features.navigation import Navigation
    from app.session import Session
    from nav.types import GridGeometry, OccupancyGrid, Pose2D
    from robot.sim import SimDriver, World


def _pose_arg(text: str) -> tuple[float, float, float]:
    try:
        values = [float(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,theta in metres/radians, got {text!r}") from None
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected x,y[,theta] with finite numbers, got {text!r}")
    return values[0], values[1], values[2] if len(values) == 3 else 0.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim-nav", help="simulate navigating to a goal (AMCL + costmaps + planner + DWA) on a virtual clock"
    )
    p.add_argument("--map", help="map YAML the robot localizes and plans in (required unless --no-prior-map)")
    p.add_argument("--world", help="world YAML the simulator runs (default: the map)")
    p.add_argument(
        "--no-prior-map",
        action="store_true",
        help="plan from an all-unknown map of the world's size (localization from the truth)",
    )
    p.add_argument("--profile", default="skid4", help="robot profile name or TOML path (default skid4)")
    p.add_argument("--start", required=True, type=_pose_arg, help="start x,y,theta in the map frame")
    p.add_argument(
        "--goal", required=True, type=_pose_arg, action="append", help="goal x,y,theta (repeat: waypoints)"
    )
    p.add_argument(
        "--controller", choices=["dwa", "teb"], default=None, help="local controller (default: the profile's)"
    )
    p.add_argument("--people", type=int, default=0, help="random walkers (0.5-1.2 m/s) in the world")
    p.add_argument("--planner", choices=["astar", "dijkstra"], default="astar")
    p.add_argument(
        "--localization",
        choices=["amcl", "truth"],
        default=None,
        help="default amcl (truth without a prior map)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timeout", type=float, default=120.0, help="simulated seconds before giving up")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


@dataclass(frozen=True)
class SimNavConfig:
    """One simulated navigation run."""

    map_path: Path
    start: tuple[float, float, float]
    goals: tuple[tuple[float, float, float], ...]
    world_path: Path | None = None
    profile: str = "skid4"
    planner: str = "astar"
    localization: str = "amcl"
    seed: int = 0
    timeout: float = 120.0
    rate_hz: float = 20.0
    obstacles: tuple[tuple[tuple[float, float], ...], ...] = ()
    """Polygons added to the simulated world only (unmapped obstacles the lidar must see)."""
    controller: str | None = None
    """Local controller, "dwa" | "teb"; None: the profile's."""
    people: int = 0
    """Random walkers added to the simulated world (away from the start)."""
    no_prior_map: bool = False
    """Give the robot an all-unknown map of the world's size instead of ``map_path`` (which then
    only names the world when ``world_path`` is None); needs ``localization="truth"``."""


@dataclass
class SimNavResult:
    reached: bool
    time_s: float
    path_length_m: float
    recoveries: int
    collisions: int
    min_clearance_m: float
    localization_error_m: float
    outcome: str = ""
    reason: str = ""
    goals_reached: int = 0
    localization_error_max_m: float = 0.0
    min_person_clearance_m: float | None = None
    """Smallest footprint-outline to person-disc distance (m); None without people."""
    wall_s: float = 0.0
    speedup: float = 0.0
    controller: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("extra")
        for k, v in d.items():
            if isinstance(v, float):
                d[k] = round(v, 4) if math.isfinite(v) else None
        return d


@dataclass
class SimStack:
    """A simulated robot with the server's session and features, on a virtual clock."""

    session: Session
    driver: SimDriver
    world: World
    localization: Localization
    navigation: Navigation


def build_sim_stack(
    grid: OccupancyGrid,
    world: World,
    start: Pose2D,
    *,
    profile: str = "skid4",
    planner: str = "astar",
    localization: str = "amcl",
    seed: int = 0,
    rate_hz: float = 20.0,
    controller: str | None = None,
) -> SimStack:
    """Session + SimDriver + localization and navigation features, as ``Runtime.start`` wires them."""
    from app.features.localization import Localization, LocalizationOptions
    from app.features.navigation import Navigation, NavigationOptions
    from app.session import Session, SessionOptions
    from robot.clock import VirtualClock
    from robot.profiles import load_profile
    from robot.sim import SimDriver

    prof = load_profile(profile)
    clock = VirtualClock()
    driver = SimDriver(world, prof, clock, seed=seed, start_pose=start)
    session = Session(
        driver, clock=clock, grid=grid, start_pose=start, options=SessionOptions(rate_hz=rate_hz)
    )
    loc = Localization(session, LocalizationOptions(source=localization), seed=seed)  # type: ignore[arg-type]
    session.add_stage(loc)
    nav = Navigation(session, loc, NavigationOptions(planner=planner, controller=controller))  # type: ignore[arg-type]
    session.add_stage(nav)
    return SimStack(session, driver, world, loc, nav)


def unknown_grid(geometry: GridGeometry) -> OccupancyGrid:
    """An all-unknown (-1) map over ``geometry``: what a robot knows before it has seen anything."""
    import numpy as np

    from nav.types import OccupancyGrid

    return OccupancyGrid(geometry, np.full((geometry.height, geometry.width), -1, dtype=np.int8))


def _outline(polygon, spacing: float = 0.02):
    import numpy as np

    poly = np.asarray(polygon, dtype=float)
    nxt = np.roll(poly, -1, axis=0)
    pts = []
    for a, b in zip(poly, nxt, strict=True):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / spacing))
        t = np.arange(n)[:, None] / n
        pts.append(a + t * (b - a))
    return np.vstack(pts)


def drive(
    stack: SimStack,
    goals: Sequence[Pose2D],
    timeout: float,
    on_step: Callable[[SimStack, float], None] | None = None,
    *,
    allow_unknown: bool | None = None,
) -> SimNavResult:
    """Send ``goals`` and step the loop until the navigation outcome or ``timeout`` simulated s;
    ``on_step(stack, elapsed)`` runs after every step (a scenario's events and its own figures);
    ``allow_unknown`` accepts goals in unknown space (the request field)."""
    import numpy as np

    s, nav, world = stack.session, stack.navigation, stack.world
    geo = world.geometry
    clear = world.clearance_map
    outline = _outline(stack.driver.profile.footprint_polygon())
    nav.set_goals(list(goals), allow_unknown=allow_unknown)
    t0, wall0 = s.clock.now(), time.perf_counter()
    min_clear, errs = math.inf, []
    last = stack.driver.truth_pose
    length = 0.0
    outcome = None
    collisions0 = s.collisions
    crowd = world.people
    min_person = math.inf
    while s.clock.now() - t0 < timeout:
        s.clock.sleep_until(s.clock.now() + s.period)
        s.step()
        if on_step is not None:
            on_step(stack, s.clock.now() - t0)
        truth = stack.driver.truth_pose
        length += last.distance_to(truth)
        last = truth
        rows, cols = geo.world_to_cell(truth.transform_points(outline))
        rows = np.clip(rows, 0, geo.height - 1)
        cols = np.clip(cols, 0, geo.width - 1)
        # cell-centre distance minus half a cell: distance to the obstacle cell's edge
        min_clear = min(min_clear, float(clear[rows, cols].min()) - 0.5 * geo.resolution)
        if len(crowd):  # people are not in the clearance map: outline points to each disc
            pts = truth.transform_points(outline)
            gap = np.hypot(pts[:, None, 0] - crowd.xy[None, :, 0], pts[:, None, 1] - crowd.xy[None, :, 1])
            min_person = min(min_person, float((gap - crowd.radius[None, :]).min()))
        errs.append(s.pose.distance_to(truth))
        if nav.last_outcome is not None and not nav.active:
            outcome = nav.last_outcome
            break
    sim_t = s.clock.now() - t0
    wall = time.perf_counter() - wall0
    e = np.asarray(errs) if errs else np.zeros(1)
    return SimNavResult(
        reached=outcome is not None and outcome["kind"] == "reached",
        time_s=sim_t,
        path_length_m=length,
        recoveries=nav.recoveries,
        collisions=s.collisions - collisions0,
        min_clearance_m=max(0.0, min_clear),
        localization_error_m=float(np.sqrt(np.mean(e**2))),
        outcome="timeout" if outcome is None else outcome["kind"],
        reason="" if outcome is None else outcome["reason"],
        goals_reached=0 if outcome is None else outcome["goals_reached"],
        localization_error_max_m=float(e.max()),
        min_person_clearance_m=max(0.0, min_person) if math.isfinite(min_person) else None,
        wall_s=wall,
        speedup=sim_t / wall if wall > 0 else math.inf,
        controller=nav.navigator.controller_name,
    )


def run_sim_nav(cfg: SimNavConfig) -> SimNavResult:
    """Load the map and world, build the stack, set the initial pose, navigate; typed errors from
    the features (``GoalRejected``, ``LocalizationRequestError``) propagate."""
    from maps.mapio import load_map_yaml
    from nav.types import Pose2D
    from robot.sim import World

    if cfg.no_prior_map and cfg.localization != "truth":
        raise ValueError("without a prior map the pose comes from the truth: localization must be 'truth'")
    world = World.from_yaml(cfg.world_path or cfg.map_path)
    grid = unknown_grid(world.geometry) if cfg.no_prior_map else load_map_yaml(cfg.map_path)
    for poly in cfg.obstacles:
        world.add_polygon(list(poly))
    start = Pose2D(*cfg.start)
    if cfg.people:
        import numpy as np

        # walkers start >= 1.5 m from the robot; the seed places them and picks their targets
        world.people.populate(cfg.people, np.random.default_rng(cfg.seed + 7919), avoid=(start.x, start.y))
    stack = build_sim_stack(
        grid,
        world,
        start,
        profile=cfg.profile,
        planner=cfg.planner,
        localization=cfg.localization,
        seed=cfg.seed,
        rate_hz=cfg.rate_hz,
        controller=cfg.controller,
    )
    try:
        stack.localization.set_initial_pose(start)
        goals = [Pose2D(*g) for g in cfg.goals]
        return drive(stack, goals, cfg.timeout, allow_unknown=True if cfg.no_prior_map else None)
    finally:
        stack.session.close()


def run(args: argparse.Namespace) -> int:
    from app.features.localization import LocalizationRequestError
    from app.features.navigation import GoalRejected, NavigationRefused
    from maps.mapio import MapFormatError
    from robot.profiles import ProfileError
    from robot.sim.people import PeopleError

    if args.map is None and not (args.no_prior_map and args.world):
        raise CliError("--map is required (or --no-prior-map with --world)")
    world_path = Path(args.world) if args.world else None
    map_path = Path(args.map) if args.map else world_path
    assert map_path is not None
    if not map_path.is_file():
        raise CliError(f"map file not found: {map_path}")
    localization = args.localization or ("truth" if args.no_prior_map else "amcl")
    if args.no_prior_map and localization != "truth":
        raise CliError("--no-prior-map needs --localization truth (AMCL cannot localize in a blank map)")
    if world_path is not None and not world_path.is_file():
        raise CliError(f"world file not found: {world_path}")
    if not math.isfinite(args.timeout) or args.timeout <= 0:
        raise CliError("--timeout must be a positive number of seconds")
    if not 0 <= args.people <= 100:
        raise CliError("--people must be between 0 and 100")
    cfg = SimNavConfig(
        map_path=map_path,
        world_path=world_path,
        profile=args.profile,
        start=args.start,
        goals=tuple(args.goal),
        planner=args.planner,
        localization=localization,
        seed=args.seed,
        timeout=args.timeout,
        controller=args.controller,
        people=args.people,
        no_prior_map=args.no_prior_map,
    )
    try:
        result = run_sim_nav(cfg)
    except (LocalizationRequestError, GoalRejected, NavigationRefused) as exc:
        raise CliError(str(exc)) from None
    except (MapFormatError, ProfileError, PeopleError, OSError, ValueError) as exc:
        raise CliError(f"cannot run: {exc}") from None
    d = result.as_dict()
    if args.json:
        print(json.dumps(d))
    else:
        status = "reached" if result.reached else f"not reached ({result.outcome} {result.reason})".strip()
        print(
            f"{status} with {result.controller} in {result.time_s:.1f} s simulated "
            f"({result.speedup:.0f}x real time), "
            f"{result.path_length_m:.2f} m driven, {result.collisions} collisions, "
            f"min clearance {result.min_clearance_m:.3f} m, "
            f"localization RMS {result.localization_error_m:.3f} m"
        )
    return 0
