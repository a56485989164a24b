"""``navdeck plan``: plan a global path on a map file and print it (text or JSON).

A typed planner failure (start in a wall, goal off the map, no path...) is a normal answer: it is
printed with ``"found": false`` and its Nav2-style error name, exit code 0. Bad input (unreadable
map, malformed coordinates) exits 2.
"""

from __future__ import annotations

import argparse
import json
import math

from app.cli import CliError


def _pose_arg(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y[,theta] in metres/radians, got {text!r}") from None
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected x,y[,theta] with finite numbers, got {text!r}")
    return values[0], values[1], values[2] if len(values) == 3 else 0.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan", help="plan a global path on a map (A* or Dijkstra over a Nav2-style costmap)")
    p.add_argument("--map", required=True, help="map YAML (map_server format)")
    p.add_argument("--start", required=True, type=_pose_arg, help="start x,y[,theta] in the map frame")
    p.add_argument("--goal", required=True, type=_pose_arg, help="goal x,y[,theta] in the map frame")
    p.add_argument("--planner", choices=["astar", "dijkstra"], default="astar")
    p.add_argument(
        "--cost-weight",
        type=float,
        default=2.0,
        help="cost_travel_multiplier: 0 = shortest geometric path (default 2.0, Nav2 Smac)",
    )
    p.add_argument("--no-inflation", action="store_true", help="plan on static obstacles only")
    p.add_argument("--robot-radius", type=float, default=None, help="robot radius in m (default 0.1, Nav2)")
    p.add_argument("--profile", help="take the footprint from this robot profile (e.g. skid4)")
    p.add_argument("--inflation-radius", type=float, default=0.55, help="m (Nav2 default 0.55)")
    p.add_argument("--tolerance", type=float, default=0.25, help="goal tolerance in m (default 0.25)")
    p.add_argument("--allow-unknown", action="store_true", help="let the path cross unknown cells")
    p.add_argument("--smooth", action="store_true", help="smooth the grid path (Nav2 simple smoother)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from nav.costmap import Costmap2D, CostmapOptions, InflationOptions
    from nav.planning import PlannerError, PlannerOptions, make_planner
    from nav.types import Pose2D

    path = Path(args.map)
    if not path.is_file():
        raise CliError(f"map file not found: {path}")
    try:
        from maps.mapio import load_map_yaml

        grid = load_map_yaml(path)
    except (OSError, ValueError) as exc:
        raise CliError(f"cannot read map {path}: {exc}") from None
    for name in ("cost_weight", "tolerance", "inflation_radius"):
        value = getattr(args, name)
        if not math.isfinite(value) or value < 0:
            raise CliError(f"--{name.replace('_', '-')} must be a finite number >= 0")
    footprint: tuple[tuple[float, float], ...] = ()
    radius = 0.1
    if args.profile:
        from robot.profiles import ProfileError, load_profile

        try:
            profile = load_profile(args.profile)
        except (ProfileError, OSError) as exc:
            raise CliError(f"cannot load profile {args.profile!r}: {exc}") from None
        footprint, radius = profile.footprint, profile.robot_radius or radius
    if args.robot_radius is not None:
        if not math.isfinite(args.robot_radius) or args.robot_radius < 0:
            raise CliError("--robot-radius must be a finite number >= 0")
        footprint, radius = (), args.robot_radius

    t0 = time.perf_counter()
    options = CostmapOptions(
        robot_radius=radius,
        footprint=footprint,
        use_obstacle_layer=False,
        use_inflation_layer=not args.no_inflation,
        inflation_layer=InflationOptions(inflation_radius=args.inflation_radius),
    )
    costmap = Costmap2D.from_map(grid, options).costmap()
    costmap_ms = (time.perf_counter() - t0) * 1e3
    planner = make_planner(
        args.planner,
        PlannerOptions(
            tolerance=args.tolerance,
            allow_unknown=args.allow_unknown,
            cost_travel_multiplier=args.cost_weight,
            smooth_path=args.smooth,
        ),
    )
    start, goal = Pose2D(*args.start), Pose2D(*args.goal)
    t1 = time.perf_counter()
    result: dict[str, object] = {"planner": args.planner}
    try:
        plan, stats = planner.plan_with_stats(costmap, start, goal)
    except PlannerError as exc:
        result.update(found=False, error=type(exc).__name__, message=str(exc), length_m=None, path=[])
    else:
        result.update(
            found=True,
            length_m=round(plan.length, 6),
            cost=round(stats.search_cost * costmap.geometry.resolution, 6),
            expansions=stats.expansions,
            goal_reached_exactly=stats.goal_reached_exactly,
            path=[[round(float(x), 4), round(float(y), 4)] for x, y in plan.poses[:, :2]],
        )
    result["time_ms"] = round((time.perf_counter() - t1) * 1e3, 3)
    result["costmap_ms"] = round(costmap_ms, 3)
    if args.json:
        print(json.dumps(result))
    elif result["found"]:
        print(
            f"{args.planner}: path of {result['length_m']:.3f} m, {len(result['path'])} poses, "  # type: ignore[arg-type]
            f"{result['expansions']} expansions, {result['time_ms']:.1f} ms (costmap {costmap_ms:.1f} ms)"
        )
    else:
        print(f"{args.planner}: no path: {result['error']}: {result['message']}")
    return 0
