"""Per-world scenarios: people scripts and obstacles that are *not* in the world's map.

A scenario is a TOML sidecar next to a map YAML (``maps/stock/<name>.scenario.toml``), loaded with
``World.from_yaml(path, scenario=True)`` or ``World.stock(name, scenario=True)``. Its obstacles are
rasterized into the simulated world only, so the robot meets them with its sensors, as source C's
greenhouse robot meets mounds and puddles its global map does not hold, and its local planner bends
around them. The map (``world.grid``) is left untouched.

Format::

    description = "one line"
    [[person]]            # kind: loop | random | step_in | stand
    kind = "loop"
    waypoints = [[x, y], ...]   # loop: walked in order, then back to the first
    at = [x, y]                 # random, step_in, stand: start (step_in: standby point)
    speed = 0.8                 # m/s, 0.5 .. 1.2
    trigger_distance = 1.5      # step_in: robot distance that sets it off (m)
    dwell = 3.0                 # step_in: seconds it stands in front of the robot
    [[mound]]                   # raised soil: an ellipse the lidar sees (solid at scan height)
    center = [x, y]
    radii = [a, b]              # semi-axes along x and y (m)
    [[puddle]]                  # same shape keys as a mound
    center = [x, y]
    radii = [a, b]

Puddles: a 2D lidar sees no water, but the robot must not drive through one, so a puddle is modelled
as a low obstacle the lidar does see (as if the scan plane were low enough, or a depth camera's
obstacles were merged into the scan, as source C does). This keeps one obstacle path through the
sensors and the costmap; the 3D view can still draw them differently (``world.features`` kind).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robot.sim.people import MAX_SPEED, MIN_SPEED

if TYPE_CHECKING:
    from robot.sim.world import World

PERSON_KINDS = ("loop", "random", "step_in", "stand")
OBSTACLE_KINDS = ("mound", "puddle")
ELLIPSE_SEGMENTS = 24


class ScenarioError(ValueError):
    """A scenario file is missing or invalid; the message names the entry and field."""


def sidecar_path(map_yaml: str | Path) -> Path:
    """``maps/stock/greenhouse.yaml`` -> ``maps/stock/greenhouse.scenario.toml``."""
    p = Path(map_yaml)
    return p.with_name(f"{p.stem}.scenario.toml")


def ellipse(center: tuple[float, float], radii: tuple[float, float], segments: int = ELLIPSE_SEGMENTS):
    """An ellipse as an (N, 2) polygon."""
    a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    return np.column_stack((center[0] + radii[0] * np.cos(a), center[1] + radii[1] * np.sin(a)))


@dataclass(frozen=True)
class PersonSpec:
    kind: str
    at: tuple[float, float]
    waypoints: tuple[tuple[float, float], ...] = ()
    speed: float = 0.8
    trigger_distance: float = 1.5
    dwell: float = 3.0


@dataclass(frozen=True)
class ObstacleSpec:
    kind: str
    center: tuple[float, float]
    radii: tuple[float, float]

    @property
    def polygon(self) -> np.ndarray:
        return ellipse(self.center, self.radii)


@dataclass(frozen=True)
class Scenario:
    description: str = ""
    people: tuple[PersonSpec, ...] = ()
    obstacles: tuple[ObstacleSpec, ...] = field(default=())

    def apply(self, world: World, seed: int = 0) -> list[int]:
        """Add the obstacles and people to ``world``; returns the people's ids. ``seed`` drives
        the random walkers."""
        for ob in self.obstacles:
            world.add_polygon(ob.polygon, kind=ob.kind)
        rng = np.random.default_rng(seed)
        ids = []
        crowd = world.people
        for p in self.people:
            if p.kind == "loop":
                ids.append(crowd.add_loop(np.array(p.waypoints), speed=p.speed))
            elif p.kind == "random":
                ids.append(crowd.add_random(p.at[0], p.at[1], rng, speed=p.speed))
            elif p.kind == "step_in":
                ids.append(crowd.add_step_in(p.at[0], p.at[1], p.trigger_distance, p.dwell, p.speed))
            else:
                ids.append(crowd.add(p.at[0], p.at[1], speed=p.speed))
        return ids


def _point(value: Any, where: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ScenarioError(f"{where}: expected [x, y], got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ScenarioError(f"{where}: must be finite, got {value!r}")
    return x, y


def parse_scenario(data: dict[str, Any], source: str = "scenario") -> Scenario:
    """Validate a parsed TOML document into a ``Scenario``."""
    unknown = set(data) - {"description", "person", *OBSTACLE_KINDS}
    if unknown:
        raise ScenarioError(f"{source}: unknown key(s) {', '.join(sorted(unknown))}")
    people = []
    for i, p in enumerate(data.get("person", [])):
        where = f"{source}: person[{i}]"
        kind = p.get("kind", "loop")
        if kind not in PERSON_KINDS:
            raise ScenarioError(f"{where}.kind must be one of {', '.join(PERSON_KINDS)}, got {kind!r}")
        extra = set(p) - {"kind", "at", "waypoints", "speed", "trigger_distance", "dwell"}
        if extra:
            raise ScenarioError(f"{where}: unknown field(s) {', '.join(sorted(extra))}")
        wps = tuple(_point(w, f"{where}.waypoints") for w in p.get("waypoints", []))
        if kind == "loop" and len(wps) < 2:
            raise ScenarioError(f"{where}.waypoints: a loop needs at least 2 points")
        at = wps[0] if kind == "loop" else _point(p.get("at"), f"{where}.at")
        speed = float(p.get("speed", 0.8))
        if not (MIN_SPEED <= speed <= MAX_SPEED):
            raise ScenarioError(f"{where}.speed must be in [{MIN_SPEED}, {MAX_SPEED}] m/s, got {speed}")
        trigger, dwell = float(p.get("trigger_distance", 1.5)), float(p.get("dwell", 3.0))
        if not (trigger > 0 and dwell >= 0):
            raise ScenarioError(f"{where}: trigger_distance must be > 0 and dwell >= 0")
        people.append(PersonSpec(kind, at, wps, speed, trigger, dwell))
    obstacles = []
    for kind in OBSTACLE_KINDS:
        for i, ob in enumerate(data.get(kind, [])):
            where = f"{source}: {kind}[{i}]"
            extra = set(ob) - {"center", "radii"}
            if extra:
                raise ScenarioError(f"{where}: unknown field(s) {', '.join(sorted(extra))}")
            radii = _point(ob.get("radii"), f"{where}.radii")
            if min(radii) <= 0:
                raise ScenarioError(f"{where}.radii must be > 0, got {radii}")
            obstacles.append(ObstacleSpec(kind, _point(ob.get("center"), f"{where}.center"), radii))
    return Scenario(str(data.get("description", "")), tuple(people), tuple(obstacles))


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML; raises ``ScenarioError`` naming the problem."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"no scenario file {path}")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path.name}: {exc}") from None
    return parse_scenario(data, path.name)
