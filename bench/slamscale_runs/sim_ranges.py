"""Experiment (issue 18, hypothesis 2): are the simulator's noise-free ranges exact to the world's
surfaces? For one scan in office:4's corridor: every return's end must lie on a cell boundary of
the world grid, with an occupied cell just past it and a free one just before it."""

import numpy as np

from app.commands.explore import load_world
from nav.types import Pose2D
from robot.profiles import load_profile
from robot.sim.lidar import SimLidar

if __name__ == "__main__":
    world = load_world("office:4")
    spec = load_profile("skid4").lidar
    lidar = SimLidar(spec, np.random.default_rng(0), noise=False)
    pose = Pose2D(12.34, 7.39, 0.0)
    scan = lidar.scan(world, pose, 0.0)
    r, a = scan.ranges, scan.angles
    ok = np.isfinite(r)
    ends = np.column_stack((pose.x + r[ok] * np.cos(a[ok]), pose.y + r[ok] * np.sin(a[ok])))
    res = world.geometry.resolution
    frac = ends / res - np.rint(ends / res)
    on_boundary = (np.abs(frac) < 1e-6).any(axis=1)
    direction = np.column_stack((np.cos(a[ok]), np.sin(a[ok])))
    occ = world.static_occupied
    past = np.floor((ends + 1e-6 * direction) / res).astype(int)
    before = np.floor((ends - 1e-6 * direction) / res).astype(int)
    occupied_past = occ[past[:, 1], past[:, 0]]
    free_before = ~occ[before[:, 1], before[:, 0]]
    worst = np.abs(frac).min(axis=1).max() * res
    print(f"returns {ok.sum()}: on a cell boundary {on_boundary.sum()},")
    print(f"occupied just past {occupied_past.sum()},")
    print(f"free just before {free_before.sum()}; max |offset from boundary| {worst:.2e} m")
