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

import numpy as np

from nav.slam import kernels
from nav.types import LaserScan


def beam_reach(scan: LaserScan, range_limit: float) -> np.ndarray:
    """Per beam, the range up to which ``scan`` observed space: its return, or 0 where it has none
    (not finite, below ``range_min`` or beyond ``range_limit``)."""
    r = scan.ranges
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= range_limit)
    return np.where(ok, r, 0.0).astype(np.float64)


def observed_by_scan(scan: LaserScan, range_limit: float, points: np.ndarray, margin: float) -> np.ndarray:
    """(N,) bool: the (N, 2) points (in ``scan``'s frame) lie in space ``scan`` observed, within
    ``margin`` (m) of its returns (compiled; :func:`observed_by_scan_reference` in numpy)."""
    return kernels.observed_by_scan(
        beam_reach(scan, range_limit),
        float(scan.angle_min),
        float(scan.angle_increment),
        np.ascontiguousarray(points, dtype=np.float64),
        float(margin),
    )


def observed_by_scan_reference(
    scan: LaserScan, range_limit: float, points: np.ndarray, margin: float
) -> np.ndarray:
    """Pure-numpy reference of :func:`observed_by_scan` (the tests compare the two)."""
    reach = beam_reach(scan, range_limit)
    n, inc = reach.shape[0], float(scan.angle_increment)
    bearing = np.mod(np.arctan2(points[:, 1], points[:, 0]) - scan.angle_min, 2.0 * np.pi)
    k = np.rint(bearing / inc)
    full_circle = n * inc >= 2.0 * np.pi - 0.5 * inc
    inside = np.full(k.shape, True) if full_circle else k <= n - 1
    k[k > n - 1] = 0.0  # a full circle's last half-beam is its first beam's (else not inside)
    j = k.astype(np.int64)
    neighbours = np.maximum(reach[np.maximum(j - 1, 0)], reach[np.minimum(j + 1, n - 1)])
    return inside & (np.hypot(points[:, 0], points[:, 1]) <= np.maximum(reach[j], neighbours) + margin)
