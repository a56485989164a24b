"""SLAM benchmarks: front-end time per 360-beam scan, 2000-pose graph optimization, and (slow group)
the Freiburg benchmark logs scored with the Kümmerle et al. 2009 metric, the simulated 1-hour
drives through seeded large buildings (``slam.building``) scored the same way against the
simulator's truth, and MIT Killian Court's map consistency (``slam.killian``)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.core import Benchmark, Figure
from bench.datasets import SLAM_BENCHMARK

DATA = SLAM_BENCHMARK
# published GMapping numbers (Kümmerle et al. 2009) and our targets
TARGETS = {"intel": (0.05, 1.5), "aces": (0.060, None), "fr079": (0.061, None)}


def front_end() -> list[Figure]:
    from nav.slam.synthetic import LOOP_WAYPOINTS, box_world, cast_scan, loop_trajectory
    from nav.slam.system import GraphSlam, SlamOptions
    from nav.types import Pose2D

    grid, res = box_world()
    truth = loop_trajectory(LOOP_WAYPOINTS, 0.1)[:200]
    scans = [cast_scan(grid, res, Pose2D.from_array(p), 360, stamp=0.2 * k) for k, p in enumerate(truth)]
    slam = GraphSlam(SlamOptions())
    times = []
    for k, scan in enumerate(scans):
        t0 = time.process_time()
        slam.add_scan(scan, Pose2D.from_array(truth[k]))
        times.append(time.process_time() - t0)
    ms = 1e3 * float(np.mean(times[10:]))
    p95 = 1e3 * float(np.percentile(times[10:], 95))
    return [
        Figure("front-end per scan (360 beams, mean)", ms, "ms", "< 30 ms", ms < 30),
        Figure("front-end per scan (p95)", p95, "ms", "", None),
    ]


def optimize_2000() -> list[Figure]:
    from nav.slam.pose_graph import EdgeSet, optimize_pose_graph

    rng = np.random.default_rng(0)
    n = 2000
    t = np.linspace(0, 8 * np.pi, n)
    truth = np.column_stack((10 * np.cos(t), 10 * np.sin(t), (t + 1.5 * np.pi) % (2 * np.pi) - np.pi))

    def rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
        dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        return np.column_stack(
            (c * dx + s * dy, -s * dx + c * dy, (b[:, 2] - a[:, 2] + np.pi) % (2 * np.pi) - np.pi)
        )

    i = np.arange(n - 1)
    z = rel(truth[i], truth[i + 1]) + rng.normal(0, [0.02, 0.02, 0.005], (n - 1, 3))
    li = np.arange(0, n - n // 4, 5)
    lj = li + n // 4
    edges = EdgeSet(
        np.concatenate((i, li)),
        np.concatenate((i + 1, lj)),
        np.vstack((z, rel(truth[li], truth[lj]))),
        np.tile([50.0, 50.0, 100.0], (n - 1 + len(li), 1)),
        np.concatenate((np.zeros(n - 1, bool), np.ones(len(li), bool))),
    )
    x0 = truth + rng.normal(0, [0.3, 0.3, 0.05], truth.shape)
    # the first optimization in a process loads the compiled solver (numba's cache): once per
    # process, so timed apart on a 10-pose chain
    head = EdgeSet(
        np.arange(9), np.arange(1, 10), z[:9], np.tile([50.0, 50.0, 100.0], (9, 1)), np.zeros(9, bool)
    )
    t0 = time.process_time()
    optimize_pose_graph(x0[:10], head)
    first = time.process_time() - t0
    t0 = time.process_time()
    optimize_pose_graph(x0, edges)
    s = time.process_time() - t0
    return [
        Figure("optimize 2000 poses", s, "s", "< 0.5 s", s < 0.5),
        Figure("first optimization in the process (loads the compiled solver)", first, "s"),
    ]


def _log(name: str) -> list[Figure]:
    """``navdeck slam`` on the whole log in a child process (as a user runs it): accuracy of its
    trajectory.txt (base_link) moved to the laser's frame, which the relations refer to (they come
    from aligning the laser scans; only FR079's laser is off the base's origin, 0.04 m ahead; the
    base_link figure is reported beside it), speed = log duration / the child's CPU time (bag
    decoding included, one thread: BLAS pinned to one core), and the child's peak resident memory
    (``ru_maxrss``)."""
    import os
    import re
    import resource
    import subprocess
    import sys
    import tempfile

    from nav.slam.metric import in_sensor_frame, parse_relations, parse_trajectory, score_trajectory
    from robot.logs.reader import load_raw_log

    bag = DATA / "bags" / f"{name}.orig.bag"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as out:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        # The child reports its own peak RSS: RUSAGE_CHILDREN's ru_maxrss is the largest of all
        # children so far, so a second log would inherit the first one's figure.
        cli = (
            "import resource, sys; from app.cli import main; rc = main(); "
            "print(f'peak rss {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss} KiB', file=sys.stderr); "
            "sys.exit(rc)"
        )
        proc = subprocess.run(
            [sys.executable, "-c", cli, "slam", str(bag), "--out", out, "--quiet"],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        traj = parse_trajectory((Path(out) / "trajectory.txt").read_text())
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    rss_mb = int(re.search(r"peak rss (\d+) KiB", proc.stderr).group(1)) / 1024  # Linux: KiB
    relations = parse_relations((DATA / "relations" / f"{name}.relations").read_text())
    laser = load_raw_log(bag, max_scans=1).laser.as_array()  # the log's /tf_static mount
    score = score_trajectory(in_sensor_frame(traj, laser), relations)
    base = score_trajectory(traj, relations)
    rate = (traj[-1, 0] - traj[0, 0]) / cpu
    lag = re.search(r"odometry lag (-?\d+) ms", proc.stderr)
    lag_ms = float(lag.group(1)) if lag else float("nan")
    t_goal, r_goal = TARGETS[name]
    return [
        Figure(
            f"{name} translational error", score.trans_mean, "m", f"<= {t_goal}", score.trans_mean <= t_goal
        ),
        Figure(f"{name} translational std", score.trans_std, "m"),
        Figure(f"{name} base_link error (laser {laser[0]:.2f} m ahead)", base.trans_mean, "m"),
        Figure(
            f"{name} rotational error",
            score.rot_mean_deg,
            "deg",
            f"<= {r_goal}" if r_goal else "",
            score.rot_mean_deg <= r_goal if r_goal else None,
        ),
        Figure(f"{name} speed vs recording (1 core, CLI CPU time)", rate, "x", ">= 10x", rate >= 10),
        Figure(f"{name} peak resident memory (navdeck slam)", rss_mb, "MB", "< 1024 MB", rss_mb < 1024),
        Figure(f"{name} odometry lag estimated (restart if >= 20 ms)", lag_ms, "ms"),
    ]


BUILDING_SEEDS = (1, 2, 3)
"""The simulated family: one seeded building and drive per seed."""


def building_family(
    seeds: tuple[int, ...] = BUILDING_SEEDS, duration: float = 3600.0, global_search_drift: float = 0.0
) -> list[Figure]:
    """Per seed: a >= 100 x 60 m building (:func:`nav.slam.building.large_building`), a ``duration``
    s drive at 2 Hz with a 181-beam 180 deg laser (30 m) and drifting odometry, SLAM over it as
    ``navdeck slam`` runs it (:func:`nav.slam.offline.run_offline`, defaults), scored with the
    relations metric on revisit relations (poses < 2 m apart, >= 300 s apart in time) and local
    ones (5 s apart). Speed = drive duration / SLAM CPU time (process time, all threads)."""
    from nav.slam.building import large_building, long_drive, truth_relations
    from nav.slam.metric import relation_errors
    from nav.slam.offline import run_offline
    from nav.slam.system import SlamOptions
    from nav.types import Pose2D

    figs: list[Figure] = []
    means, worst, rates = [], [], []
    for seed in seeds:
        building = large_building(seed)
        drive = long_drive(building, seed, duration=duration)
        far, local = truth_relations(drive.stamps, drive.truth, seed)
        records = [
            (s.stamp, s, Pose2D.from_array(o)) for s, o in zip(drive.scans, drive.odometry, strict=True)
        ]
        t0 = time.process_time()
        slam = run_offline(records, Pose2D(), SlamOptions(global_search_drift=global_search_drift))
        cpu = time.process_time() - t0
        traj = slam.trajectory()
        odo = np.column_stack((drive.stamps, drive.odometry))
        # a drive too short to revisit anything has no revisit relations
        e_far = relation_errors(traj, far)[0] if len(far) else np.full(1, np.nan)
        e_odo = relation_errors(odo, far)[0] if len(far) else np.full(1, np.nan)
        e_all, r_all, _ = relation_errors(traj, np.vstack((far, local)))
        rate = float(drive.stamps[-1]) / cpu
        w, h = building.size
        tag = f"building {seed} ({w:.0f} x {h:.0f} m, {len(drive.scans)} scans)"
        figs += [
            Figure(
                f"{tag}: error, all relations", float(e_all.mean()), "m", "<= 0.05 m", e_all.mean() <= 0.05
            ),
            Figure(f"{tag}: worst relation", float(e_all.max()), "m", "<= 1 m", e_all.max() <= 1.0),
            Figure(
                f"{tag}: revisit relations error (odometry alone)",
                float(e_far.mean()),
                "m",
                f"odometry {e_odo.mean():.2f} m",
            ),
            Figure(f"{tag}: rotational error", float(np.degrees(r_all).mean()), "deg"),
            Figure(
                f"{tag}: loop closures (global)",
                float(slam.num_loop_closures),
                "",
                f"global {slam.global_closures}, rejected {slam.rejected_global}",
            ),
            Figure(f"{tag}: speed vs the drive", rate, "x", ">= 20x", rate >= 20),
        ]
        means.append(float(e_all.mean()))
        worst.append(float(e_all.max()))
        rates.append(rate)
    figs += [
        Figure(
            "building family: mean error", float(np.mean(means)), "m", "<= 0.05 m", np.mean(means) <= 0.05
        ),
        Figure("building family: worst relation", float(np.max(worst)), "m", "<= 1 m", np.max(worst) <= 1.0),
        Figure("building family: slowest speed", float(np.min(rates)), "x", ">= 20x", np.min(rates) >= 20),
    ]
    return figs


def killian() -> list[Figure]:
    """MIT Killian Court (17480 scans, re-stamped so its relations cannot be scored): ``navdeck
    slam``'s pipeline in process (:func:`nav.slam.offline.run_offline` with the log's odometry),
    then the map's consistency: the fraction of returns (<= 20 m, every 5th scan) that see more
    than 0.3 m through a wall of the submaps placed at the final poses
    (:func:`nav.slam.consistency.slam_see_through_rate`; the same against the saved map's "surface
    wins" render beside it: that render widens walls, so it counts more), for the defaults and
    with the global loop search on; speed = log duration / CPU time."""
    from nav.slam.consistency import see_through_rate, slam_see_through_rate
    from nav.slam.offline import run_offline
    from nav.slam.system import SlamOptions
    from robot.logs.reader import load_raw_log

    raw = load_raw_log(DATA / "bags" / "mit-killian.clf2bag.bag")
    records = raw.records()
    scans = [r[1] for r in records]
    duration = float(records[-1][0]) - float(records[0][0])
    figs: list[Figure] = []
    for label, options in (
        (" (defaults)", SlamOptions()),
        (" with the global search (drift 0.03)", SlamOptions(global_search_drift=0.03)),
    ):
        t0 = time.process_time()
        slam = run_offline(records, raw.laser, options, odometry=(raw.t_odom, raw.odom))
        cpu = time.process_time() - t0
        rate = duration / cpu
        rate_see = slam_see_through_rate(slam, scans)
        rate_render = see_through_rate(slam.map(), slam.trajectory(sensor=True)[:, 1:], scans)
        figs += [
            Figure(f"killian{label}: returns seeing through a mapped wall", 100 * rate_see, "%"),
            Figure(f"killian{label}: same, against the saved map's render", 100 * rate_render, "%"),
            Figure(
                f"killian{label}: loop closures (global, rejected)",
                float(slam.num_loop_closures),
                "",
                f"{slam.global_closures}, {slam.rejected_global}",
            ),
            Figure(f"killian{label}: speed vs recording", rate, "x", ">= 20x", rate >= 20),
        ]
    return figs


BENCHMARKS = [
    Benchmark(name="slam.front_end", run=front_end),
    Benchmark(name="slam.optimize_2000", run=optimize_2000),
    Benchmark(name="slam.intel", run=lambda: _log("intel"), group="slow"),
    Benchmark(name="slam.aces", run=lambda: _log("aces"), group="slow"),
    Benchmark(name="slam.fr079", run=lambda: _log("fr079"), group="slow"),
    Benchmark(name="slam.building", run=building_family, group="slow"),
    Benchmark(
        name="slam.building_global", run=lambda: building_family(global_search_drift=0.03), group="slow"
    ),
    Benchmark(name="slam.killian", run=killian, group="slow"),
]
