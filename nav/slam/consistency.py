"""Map consistency without ground truth: how often a scan sees through a wall of the map it built.

A log whose relations cannot be scored (MIT Killian Court, re-stamped) still tells whether its map
is consistent: every beam says "free up to here, then a surface". Cast at the scan's estimated
pose into the final map, a beam whose measured return lies well beyond the first occupied cell of
the map crossed a wall that another pass put there. A loop that fails to close leaves two copies of
a corridor offset from each other, and the scans of each pass cross the other copy's walls; a
consistent map contradicts only a few beams (range noise at grazing angles, people, glass). This is
the ray-contradiction test of map-consistency checks (e.g. Mazuran et al. 2014, "Map consistency
checking"), reduced to one number: the fraction of beams contradicted.

The map it reads must place each submap's evidence as it is: :meth:`GraphSlam.map`'s "surface
wins" render marks every map cell that touches a surface occupied, which widens each wall by up to
half a cell and, summed over the many submaps that saw it, by more. Beams that pass close by a
corner or meet a wall at a shallow angle then stop at the widened cells: on Killian's first 6000
scans that render took the rate from 5.6 to 8.8 % on the very same poses (docs/slam.md, "MIT
Killian: the see-through rate after stop 27"). :func:`slam_see_through_rate` therefore reads
:meth:`GraphSlam.evidence_map` (plain nearest-neighbour placement).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from nav.raycast import RayCaster
from nav.slam.system import GraphSlam
from nav.types import LaserScan, OccupancyGrid


def see_through_rate(
    grid: OccupancyGrid,
    poses: np.ndarray,
    scans: list[LaserScan],
    max_range: float = 20.0,
    margin: float = 0.3,
    every: int = 5,
) -> float:
    """Fraction (0..1) of the returns (within ``max_range``) of every ``every``-th scan that lie
    more than ``margin`` m beyond the first occupied map cell along their beam, with the scans cast
    from their laser poses ``poses`` ((N, 3) map frame, one per scan)."""
    if len(scans) != len(poses):
        raise ValueError(f"{len(scans)} scans but {len(poses)} poses")
    caster = RayCaster(grid.occupied_mask(), grid.geometry)
    picked = range(0, len(scans), max(every, 1))
    contradicted = total = 0
    # cast in chunks of up to 500 consecutive scans of the same beam count (one compiled walk each)
    for _, group in itertools.groupby(picked, key=lambda q: len(scans[q].ranges)):
        run = list(group)
        for start in range(0, len(run), 500):
            chunk = run[start : start + 500]
            ranges = np.array([scans[q].ranges for q in chunk])
            angles = np.array([scans[q].angles for q in chunk]) + poses[chunk, 2:3]
            valid = np.isfinite(ranges) & (ranges > 0.1) & (ranges <= max_range)
            expected = caster.cast(poses[chunk, :2], angles, max_range + margin)
            contradicted += int(np.count_nonzero(valid & (ranges > expected + margin)))
            total += int(np.count_nonzero(valid))
    return contradicted / total if total else math.nan


def slam_see_through_rate(
    slam: GraphSlam, scans: list[LaserScan], max_range: float = 20.0, margin: float = 0.3, every: int = 5
) -> float:
    """:func:`see_through_rate` of a finished SLAM run: its scans (one per ``add_scan`` call, in
    order) cast from its laser poses into its :meth:`GraphSlam.evidence_map`."""
    poses = slam.trajectory(sensor=True)[:, 1:]
    return see_through_rate(slam.evidence_map(), poses, scans, max_range, margin, every)
