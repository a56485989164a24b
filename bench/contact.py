"""Contact benchmarks (issue 16, "never trapped").

- ``contact.escape`` (slow): the tightest spot of each stock world (between the apartment's dining
  chair's legs, an office doorframe's corner, nose into a greenhouse plant row). Each trial drives
  into the spot and keeps pressing with random keys for 15 s, the safety layer overridden (an
  operator's override, or an obstacle the sensors do not see), then an operator presses random keys
  for up to 60 s with the safety layer on: out when the robot is more than ``TightSpot.out_radius``
  from the spot. Reports per world how many got out, the time it took, and the longest time the
  robot did not move at all while keys were held (a trapped robot never moves again).
  ``NAVDECK_ESCAPE_TRIALS`` sets the trials per world (default 20), seeds 0..N-1.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from app.session import Session
from bench.core import Benchmark, Figure
from nav.types import Pose2D, Twist2D
from robot.base import SensorFrame
from robot.clock import VirtualClock
from robot.profiles import load_profile
from robot.safety import SafetyFilter
from robot.sim import SimDriver, World


@dataclass(frozen=True)
class TightSpot:
    """Where a world is tightest for the skid4 base, and how to press into it."""

    start: Pose2D  # the pose to drive in from
    push: Twist2D  # the command that presses into the spot
    centre: tuple[float, float]  # the obstacle the robot is pressed against (m, map frame)
    out_radius: float = 0.45  # m from ``centre``: clear of the spot


TIGHT_SPOTS = {
    # between the dining chair's legs (0.4 m apart, 4 cm square) at (3.8, 1.7)
    "apartment": TightSpot(Pose2D(3.3, 1.72, 0.0), Twist2D(0.2, 0.0, 0.35), (3.8, 1.7)),
    # a doorframe's corner: the door at x 2.05-2.95 in the corridor wall y = 9
    "office": TightSpot(Pose2D(2.3, 9.6, -1.92), Twist2D(0.2, 0.0, 0.0), (2.05, 9.0)),
    # nose into the plant row y 5.0-5.6 from the aisle at y 6.2
    "greenhouse": TightSpot(Pose2D(8.0, 6.2, -1.1), Twist2D(0.2, 0.0, 0.0), (8.25, 5.6)),
}

KEYS = (
    Twist2D(0.2, 0.0, 0.0),  # forward
    Twist2D(-0.15, 0.0, 0.0),  # back
    Twist2D(0.0, 0.0, 0.8),  # turn left
    Twist2D(0.0, 0.0, -0.8),  # turn right
    Twist2D(0.2, 0.0, 0.8),  # forward + left, and so on
    Twist2D(0.2, 0.0, -0.8),
    Twist2D(-0.15, 0.0, 0.8),
    Twist2D(-0.15, 0.0, -0.8),
)
PUSHING_KEYS = (0, 2, 3, 4, 5)  # while pressing in: no backing
STALL_MOVE = (0.002, 0.02)
"""(m, rad): moving less than this since the last motion counts as not moving."""


@dataclass(frozen=True)
class EscapeResult:
    out: bool
    seconds: float  # from the first escape key to out (or the limit)
    longest_stall: float  # s; the longest stretch of held keys without any motion
    stuck: Pose2D  # where the escape began


class _Override:
    """The safety layer overridden: the filter still sees every frame, its verdict is ignored."""

    def __init__(self, f: SafetyFilter) -> None:
        self.filter = f

    def __call__(self, cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, None]:
        self.filter(cmd, frame)
        return cmd, None


def _hold(s: Session, key: Twist2D, seconds: float) -> None:
    for _ in range(max(1, round(seconds / s.period))):
        s.set_teleop(key, "bench")
        s.run_for(s.period)


def escape_trial(world_name: str, seed: int, limit: float = 60.0, press: float = 15.0) -> EscapeResult:
    """One trial of ``contact.escape`` (see the module's doc); seeded by ``seed`` alone."""
    spot = TIGHT_SPOTS[world_name]
    rng = np.random.default_rng(seed)
    clock = VirtualClock()
    world = World.stock(world_name)
    profile = load_profile("skid4")
    driver = SimDriver(world, profile, clock, seed=seed, start_pose=spot.start)
    options = driver.options
    driver.options = dataclasses.replace(options, ir_stop=False)  # the base's IR stop off too
    s = Session(driver, clock=clock, grid=world.grid, start_pose=spot.start)
    safety = SafetyFilter(profile)
    s.request_mode("teleop")
    s.safety = _Override(safety)
    _hold(s, spot.push, 6.0)
    t = 0.0
    while t < press:
        d = float(rng.uniform(0.2, 1.0))
        _hold(s, KEYS[int(rng.choice(PUSHING_KEYS))], d)
        t += d
    s.safety = safety
    driver.options = options
    stuck = anchor = driver.truth_pose
    t0 = clock.now()
    anchor_t, longest = t0, 0.0
    out = False
    while not out and clock.now() - t0 < limit:
        key = KEYS[int(rng.integers(len(KEYS)))]
        for _ in range(max(1, round(float(rng.uniform(0.2, 1.0)) / s.period))):
            s.set_teleop(key, "bench")
            s.run_for(s.period)
            p = driver.truth_pose
            if (
                math.hypot(p.x - anchor.x, p.y - anchor.y) >= STALL_MOVE[0]
                or abs(math.remainder(p.theta - anchor.theta, 2 * math.pi)) >= STALL_MOVE[1]
            ):
                anchor, anchor_t = p, clock.now()
            longest = max(longest, clock.now() - anchor_t)
            if math.hypot(p.x - spot.centre[0], p.y - spot.centre[1]) > spot.out_radius:
                out = True
                break
    s.close()
    return EscapeResult(out, clock.now() - t0, longest, stuck)


def escape_bench() -> list[Figure]:
    trials = int(os.environ.get("NAVDECK_ESCAPE_TRIALS", "20"))
    figs = []
    for name in TIGHT_SPOTS:
        results = [escape_trial(name, seed) for seed in range(trials)]
        out = sum(r.out for r in results)
        times = [r.seconds for r in results if r.out]
        stall = max(r.longest_stall for r in results)
        median = float(np.median(times)) if times else math.nan
        figs += [
            Figure(f"{name}: out within 60 s of random keys", out, f"/{trials}", f"{trials}", out == trials),
            Figure(f"{name}: time to get out, median", median, "s"),
            Figure(f"{name}: longest time not moving while keys were held", stall, "s", "< 5 s", stall < 5.0),
        ]
        for seed, r in enumerate(results):
            if not r.out:
                print(f"  {name} seed {seed}: not out after {r.seconds:.0f} s (stuck at {r.stuck})")
    return figs


BENCHMARKS = [Benchmark(name="contact.escape", run=escape_bench, group="slow")]
