"""What a single reference scan observed: the scan-to-scan counterpart of ``Submap.observed``.

The SLAM front end leaves out of a match the points that land where its submap has observed
nothing (``SlamOptions.match_unobserved_points``): such a point sees a surface the map has no
counterpart of, and the likelihood field pulls it onto the nearest mapped surface, biasing the
match. Matched against one scan instead of a submap, a point is observed when it lies no farther
than the reference measured along its bearing: beyond that range (behind the surface the beam hit),
outside the scan's field of view or along a beam with no return, the reference saw nothing. The
neighbouring beams count too (a point between two beams at a depth edge is kept if either reaches
it), and ``margin`` keeps points on the surface itself (range noise, the match's own error).
Bearings are taken from ``angle_min`` round the circle, so a scan that goes all round (an RPLidar's
0 .. 2 pi) wraps, and points behind a scan that does not are not observed.
"""

from __future__ import annotations

import math

import numpy as np

from nav.slam import kernels
from nav.types import LaserScan, Pose2D

_IDENTITY = Pose2D()


def observed_by_scan(
    scan: LaserScan, range_limit: float, points: np.ndarray, margin: float, pose: Pose2D = _IDENTITY
) -> np.ndarray:
    """(N,) bool: the (N, 2) points, ``pose`` taking them into ``scan``'s frame, lie in space
    ``scan`` observed, within ``margin`` (m) of its returns; a beam with no valid return (not finite,
    below ``range_min``, beyond ``range_limit``) observed nothing. Compiled, in one pass
    (:func:`observed_by_scan_reference` in numpy)."""
    return kernels.observed_by_scan(
        np.ascontiguousarray(scan.ranges, dtype=np.float64),
        float(scan.range_min),
        float(range_limit),
        float(scan.angle_min),
        float(scan.angle_increment),
        np.ascontiguousarray(points, dtype=np.float64),
        np.array([pose.x, pose.y, math.cos(pose.theta), math.sin(pose.theta)]),
        float(margin),
    )


def observed_by_scan_reference(
    scan: LaserScan, range_limit: float, points: np.ndarray, margin: float, pose: Pose2D = _IDENTITY
) -> np.ndarray:
    """Pure-numpy reference of :func:`observed_by_scan` (the tests compare the two)."""
    r = scan.ranges
    reach = np.where((r >= scan.range_min) & (r <= range_limit), r, 0.0)
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    x = c * points[:, 0] - s * points[:, 1] + pose.x
    y = s * points[:, 0] + c * points[:, 1] + pose.y
    n, inc = reach.shape[0], float(scan.angle_increment)
    bearing = np.arctan2(y, x) - scan.angle_min
    bearing = np.where(bearing < 0.0, bearing + 2.0 * np.pi, bearing)
    bearing = np.where(bearing >= 2.0 * np.pi, bearing - 2.0 * np.pi, bearing)
    k = np.floor(bearing / inc + 0.5)
    full_circle = n * inc >= 2.0 * np.pi - 0.5 * inc
    inside = np.full(k.shape, True) if full_circle else k <= n - 1
    k[k > n - 1] = 0.0  # a full circle's last half-beam is its first beam's (else not inside)
    j = k.astype(np.int64)
    neighbours = np.maximum(reach[np.maximum(j - 1, 0)], reach[np.minimum(j + 1, n - 1)])
    reach_m = np.maximum(reach[j], neighbours) + margin
    return inside & (x * x + y * y <= reach_m * reach_m)


def observed_subset(points: np.ndarray, observed: np.ndarray) -> np.ndarray | None:
    """The ``observed`` ones of ``points`` to match instead of all of them, or None when every point
    is observed or fewer than 3 are (too few to match: all are matched then), as the SLAM front end
    chooses for a submap and the scan-to-scan match for a reference scan."""
    kept = int(np.count_nonzero(observed))
    # np.compress: the same rows as points[observed], without boolean indexing's set-up (~half)
    return np.compress(observed, points, axis=0) if 3 <= kept < len(observed) else None
