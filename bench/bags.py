"""Bag formats (group "slow"): ``navdeck slam`` on each shared benchmark bag as recorded (ROS1) and
after conversion with ``rosbags`` to a ROS 2 ``.db3`` without message definitions (as Foxy/Humble
wrote them) and to ``.mcap``: the trajectories must agree within 1 mm and the speed within 10 %.
``bags.import`` imports MIT Killian Court (29 min) as a run and compares with ``navdeck slam``."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.core import Benchmark, Figure
from bench.datasets import SLAM_BENCHMARK

BAGS = {
    "intel": "intel.orig.bag",
    "aces": "aces.orig.bag",
    "fr079": "fr079.orig.bag",
    "killian": "mit-killian.clf2bag.bag",
}
ENV = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")


def slam_cli(bag: Path, out: Path) -> tuple[np.ndarray, list[str], float, str]:
    """Run ``navdeck slam`` in a child: (x y theta rows, stamp texts, child CPU s, stderr)."""
    before = os.times()
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "slam", str(bag), "--out", str(out), "--quiet"],
        env=ENV,
        capture_output=True,
        text=True,
        check=True,
    )
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    rows = [ln.split() for ln in (out / "trajectory.txt").read_text().splitlines() if ln.strip()]
    return np.array([[float(v) for v in r[1:]] for r in rows]), [r[0] for r in rows], cpu, proc.stderr


def formats(name: str) -> list[Figure]:
    from robot.logs.bag_convert import strip_definitions, to_ros2

    src = SLAM_BENCHMARK / "bags" / BAGS[name]
    figs: list[Figure] = []
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        to_ros2(src, t / "db3")
        strip_definitions(t / "db3")
        to_ros2(src, t / "mcap", "mcap")
        ref, ref_stamps, ref_cpu, _ = slam_cli(src, t / "out_ros1")
        figs.append(Figure(f"{name} ROS1 navdeck slam CPU", ref_cpu, "s"))
        for kind, bag in (("db3 without definitions", t / "db3"), ("mcap", t / "mcap" / "mcap.mcap")):
            traj, stamps, cpu, err = slam_cli(bag, t / f"out_{bag.name}")
            same_stamps = stamps == ref_stamps
            dxy = float(np.max(np.hypot(*(traj[:, :2] - ref[:, :2]).T))) if same_stamps else float("inf")
            dth = float(np.max(np.abs(traj[:, 2] - ref[:, 2]))) if same_stamps else float("inf")
            ratio = cpu / ref_cpu
            figs += [
                Figure(f"{name} {kind}: max position difference", 1e3 * dxy, "mm", "<= 1 mm", dxy <= 1e-3),
                Figure(f"{name} {kind}: max heading difference", np.degrees(dth), "deg"),
                Figure(f"{name} {kind}: CPU time / ROS1's", ratio, "x", "0.9-1.1", 0.9 <= ratio <= 1.1),
            ]
            if "decoded with" in err:
                figs.append(Figure(f"{name} {kind}: typestore fallback used", 1.0, "yes"))
    return figs


def import_run() -> list[Figure]:
    """Killian (17480 scans, 29 min): import as a run (bag reading, offline SLAM, storing) against
    ``navdeck slam`` on the same bag, then the Runs page's requests for it."""
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.settings import Settings

    bag = SLAM_BENCHMARK / "bags" / BAGS["killian"]
    with tempfile.TemporaryDirectory() as tmp:
        _, _, slam_cpu, _ = slam_cli(bag, Path(tmp) / "out")
        app = create_app(Settings(database_url=f"sqlite:///{tmp}/nav.db", sim=True))
        with TestClient(app) as client:
            t0, c0 = time.perf_counter(), time.process_time()
            with bag.open("rb") as f:
                r = client.post("/api/runs/import", files={"file": (bag.name, f, "application/octet-stream")})
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            r.raise_for_status()
            run_id = r.json()["run"]["id"]
            t1 = time.perf_counter()
            for url in (
                f"/api/runs/{run_id}",
                f"/api/runs/{run_id}/trajectory?max_points=2000",
                f"/api/runs/{run_id}/map.png",
            ):
                client.get(url).raise_for_status()
            page = time.perf_counter() - t1
    ratio = cpu / slam_cpu
    return [
        Figure("killian navdeck slam CPU", slam_cpu, "s"),
        Figure("killian import CPU (server process)", cpu, "s"),
        Figure("killian import wall time", wall, "s"),
        Figure("import / navdeck slam (CPU)", ratio, "x", "< 2x", ratio < 2),
        Figure("Runs page requests for it (detail, trajectory, map.png)", page, "s", "< 3 s", page < 3),
    ]


BENCHMARKS = [Benchmark(name=f"bags.{n}", run=lambda n=n: formats(n), group="slow") for n in BAGS] + [
    Benchmark(name="bags.import", run=import_run, group="slow")
]
