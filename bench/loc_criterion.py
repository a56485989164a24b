"""Measure the localization criterion: how well the scan fits the map at AMCL's estimate right
after an initial pose (the filter's first update, no motion), for the TRUE pose and for WRONG ones
(a random free pose > 1 m away; the true place turned by 30-180 deg), with walkers about, in the
stock worlds and the generated families. Prints per-family distributions of the current
``quality`` (Gaussian fit) and of the inlier fraction (``scan_inlier_fraction``) at several
tolerances, and the error rates of thresholds.

    python -m bench.loc_criterion [--seeds 6] [--poses 3] [--people 6] [--seed 0] [--json out.json]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math

import numpy as np

from nav.localization import Amcl, AmclOptions
from nav.localization import sensor_models as sm
from nav.types import Pose2D, wrap_angle
from robot.profiles import load_profile
from robot.sim.lidar import SimLidar
from robot.sim.people import PeopleError
from robot.sim.world import World
from robot.sim.worldgen import FAMILIES, generate

TOLERANCES = (0.1, 0.15, 0.2)
INITIAL_COV = np.diag([0.5**2, 0.5**2, (math.pi / 12) ** 2])  # LocalizationOptions' defaults


def _free_points(world: World, clearance: float) -> np.ndarray:
    rows, cols = np.nonzero(world.clearance_map >= clearance)
    return world.geometry.cell_to_world(rows, cols)


def _worlds(seeds: int):
    for name in ("apartment", "office", "greenhouse"):
        yield "stock-" + name, World.stock(name), "skid4"
    for family in FAMILIES:
        for seed in range(seeds):
            gen = generate(family, seed)
            yield family, gen.world(), gen.profile


def measure(seeds: int, poses: int, people: int, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows: list[dict] = []
    for family, world, profile_name in _worlds(seeds):
        profile = load_profile(profile_name)
        lid = profile.lidar
        laser = Pose2D(lid.mount_x, lid.mount_y, lid.mount_yaw)
        opts = AmclOptions(robot_model_type="omnidirectional" if profile.is_omni else "differential")
        amcl = Amcl(opts, world.grid, int(rng.integers(1 << 30)))
        field = amcl._field
        free = _free_points(world, profile.circumscribed_radius + 0.1)
        if free.shape[0] == 0:
            continue
        lidar = SimLidar(lid, rng)
        for _ in range(poses):
            xy = free[int(rng.integers(free.shape[0]))]
            truth = Pose2D(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))
            world.people.clear()
            if people:
                with contextlib.suppress(PeopleError):  # a world without room for them: none
                    world.people.populate(people, rng, avoid=(truth.x, truth.y), min_gap=0.8, clearance=0.4)
                for _ in range(int(rng.integers(0, 20))):
                    world.people.step(0.2, truth)
            scan = lidar.scan(world, truth, 0.0)
            hyps = [("true", truth)]
            far = free[np.hypot(free[:, 0] - truth.x, free[:, 1] - truth.y) > 1.0]
            for _ in range(4):
                if far.shape[0]:
                    p = far[int(rng.integers(far.shape[0]))]
                    hyps.append(
                        ("shift", Pose2D(float(p[0]), float(p[1]), float(rng.uniform(-math.pi, math.pi))))
                    )
            for _ in range(2):
                turn = float(rng.uniform(math.radians(30), math.pi)) * float(rng.choice([-1.0, 1.0]))
                hyps.append(("turn", Pose2D(truth.x, truth.y, float(wrap_angle(truth.theta + turn)))))
            beams = sm.select_beams(scan, opts)
            for kind, h in hyps:
                amcl.set_initial_pose(h, INITIAL_COV)
                amcl.update(Pose2D(), scan, laser)
                mean, cov = amcl.estimate()
                err_xy = math.hypot(mean.x - truth.x, mean.y - truth.y)
                err_a = abs(float(wrap_angle(mean.theta - truth.theta)))
                label = (
                    "right"
                    if err_xy <= 0.5 and err_a <= math.radians(20)
                    else "wrong"
                    if err_xy > 1.0 or err_a > math.radians(30)
                    else "between"
                )
                row = {
                    "family": family,
                    "kind": kind,
                    "label": label,
                    "err_xy": round(err_xy, 3),
                    "err_deg": round(math.degrees(err_a), 1),
                    "spread": round(float(np.sqrt(max(cov[0, 0], cov[1, 1]))), 3),
                    "quality": round(amcl.quality, 3),
                    "people": len(world.people),
                }
                for tol in TOLERANCES:
                    row[f"inl{tol:g}"] = round(sm.scan_inlier_fraction(field, mean, laser, beams, tol), 3)
                rows.append(row)
    return rows


def _groups(rows: list[dict], fam: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    """Fits of initial poses at the truth, and of wrong hypotheses whose estimate stayed wrong."""
    sel = [r for r in rows if fam in ("ALL", r["family"])]
    true = np.array([r[key] for r in sel if r["kind"] == "true"])
    wrong = np.array([r[key] for r in sel if r["kind"] != "true" and r["label"] == "wrong"])
    return true, wrong


def _q(a: np.ndarray) -> str:
    if a.size == 0:
        return "-"
    p5, p50, p95 = np.percentile(a, [5, 50, 95])
    return f"n={a.size} min {a.min():.2f} p5 {p5:.2f} p50 {p50:.2f} p95 {p95:.2f} max {a.max():.2f}"


def _summary(rows: list[dict], key: str) -> None:
    print(f"\n== {key}")
    for fam in [*sorted({r["family"] for r in rows}), "ALL"]:
        true, wrong = _groups(rows, fam, key)
        print(f"{fam:18s} true pose: {_q(true)} | wrong estimate: {_q(wrong)}")


def _rates(rows: list[dict], key: str, thresholds: list[float]) -> None:
    for t in thresholds:
        parts = []
        for fam in [*sorted({r["family"] for r in rows}), "ALL"]:
            true, wrong = _groups(rows, fam, key)
            parts.append(
                f"{fam}: right refused {(true < t).sum()}/{true.size}, "
                f"wrong accepted {(wrong >= t).sum()}/{wrong.size}"
            )
        print(f"{key} >= {t}: " + "; ".join(parts))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--people", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default="")
    a = ap.parse_args()
    rows = measure(a.seeds, a.poses, a.people, a.seed)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f)
    for key in ("quality", *(f"inl{t:g}" for t in TOLERANCES)):
        _summary(rows, key)
    for key in (f"inl{t:g}" for t in TOLERANCES):
        _rates(rows, key, [0.5, 0.6, 0.7, 0.8])
    _rates(rows, "quality", [0.5, 0.7])


if __name__ == "__main__":
    main()
