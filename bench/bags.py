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

from app.main import create_app
from app.runtime import Runtime
from app.settings import Settings
from bench.core import Benchmark, Figure
from bench.datasets import SLAM_BENCHMARK
from robot.logs.bag_convert import strip_definitions, to_ros2
from robot.logs.reader import load_raw_log

try:  # the test client needs httpx, a dev extra: without it only bags.import cannot run, and
    # `navdeck bench` (which imports every bench module) must still list and run the rest
    from fastapi.testclient import TestClient
except ImportError:
    TestClient = None

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


def read_formats(name: str) -> list[Figure]:
    """The reading alone (what differs between formats; SLAM then gets the same input): CPU time of
    ``load_raw_log`` per format, and whether scans, stamps and odometry are bit-identical to ROS1's."""
    src = SLAM_BENCHMARK / "bags" / BAGS[name]
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        to_ros2(src, t / "db3")
        strip_definitions(t / "db3")
        to_ros2(src, t / "mcap", "mcap")
        c0 = time.process_time()
        ref = load_raw_log(src)
        ref_cpu = time.process_time() - c0
        figs = [Figure(f"{name} ROS1 read CPU ({len(ref.scans)} scans)", ref_cpu, "s")]
        for kind, bag in (("db3 without definitions", t / "db3"), ("mcap", t / "mcap" / "mcap.mcap")):
            c0 = time.process_time()
            raw = load_raw_log(bag)
            cpu = time.process_time() - c0
            same = (
                [str(x) for x in raw.stamps] == [str(x) for x in ref.stamps]
                and all(np.array_equal(a.ranges, b.ranges) for a, b in zip(raw.scans, ref.scans, strict=True))
                and np.array_equal(raw.odom, ref.odom)
                and np.array_equal(raw.t_odom, ref.t_odom)
                and raw.laser == ref.laser
            )
            figs += [
                Figure(f"{name} {kind}: read CPU", cpu, "s"),
                Figure(f"{name} {kind}: SLAM input identical to ROS1's", float(same), "bool", "1", same),
            ]
    return figs


def import_run(name: str = "killian") -> list[Figure]:
    """Import a bag as a run (bag reading, offline SLAM, storing) against ``navdeck slam`` on the same
    bag, then the requests the Runs page makes to open it. Killian: 17480 scans, 29 min."""
    if TestClient is None:
        raise RuntimeError("bags.import needs httpx (pip install 'navdeck[dev]')")
    bag = SLAM_BENCHMARK / "bags" / BAGS[name]
    with tempfile.TemporaryDirectory() as tmp:
        _, _, slam_cpu, _ = slam_cli(bag, Path(tmp) / "out")
        settings = Settings(data_dir=Path(tmp), db_url=f"sqlite:///{tmp}/navdeck.db", viewer=False)
        with TestClient(create_app(Runtime.build(settings))) as client:
            t0 = time.perf_counter()
            with bag.open("rb") as f:
                r = client.post("/api/runs/import", files={"file": (bag.name, f, "application/octet-stream")})
            r.raise_for_status()
            job_id = r.json()["id"]
            while (job := client.get(f"/api/runs/import/{job_id}").json())["state"] not in ("done", "failed"):
                time.sleep(0.5)
            wall = time.perf_counter() - t0
            if job["state"] != "done":
                raise RuntimeError(job["error"])
            cpu = client.app.state.runtime.features["bag_imports"].get(job_id).cpu_s
            rid = job["run_id"]
            t1 = time.perf_counter()
            for url in (
                f"/api/runs/{rid}",
                f"/api/runs/{rid}/trajectory?max_points=3000",
                f"/api/runs/{rid}/map.png",
            ):
                client.get(url).raise_for_status()
            page = time.perf_counter() - t1
    ratio = cpu / slam_cpu
    return [
        Figure(f"{name} navdeck slam CPU (child process)", slam_cpu, "s"),
        Figure(f"{name} import CPU (import worker thread)", cpu, "s"),
        Figure(f"{name} import wall time (upload to run stored)", wall, "s"),
        Figure(f"{name} import / navdeck slam (CPU)", ratio, "x", "< 2x", ratio < 2),
        Figure("Runs page requests to open it (detail, trajectory, map.png)", page, "s", "< 3 s", page < 3),
    ]


BENCHMARKS = [
    *(Benchmark(name=f"bags.{n}", run=lambda n=n: formats(n), group="slow") for n in BAGS),
    *(Benchmark(name=f"bags.read.{n}", run=lambda n=n: read_formats(n), group="slow") for n in BAGS),
    Benchmark(name="bags.import", run=import_run, group="slow"),
    Benchmark(name="bags.import_aces", run=lambda: import_run("aces"), group="slow"),
]
