"""Pure numpy: navigation data -> the float32 arrays viser draws (line segments, arrows, points).

Everything is vectorized over points / poses / samples (these run every viewer tick), and rows holding a
non-finite value are dropped rather than sent: the client would draw NaN as lines to infinity.
"""

from __future__ import annotations

import math

import numpy as np

from nav.types import LaserScan, Pose2D


def finite_rows(a: np.ndarray) -> np.ndarray:
    """Rows of ``a`` (first axis) whose every value is finite."""
    return a[np.all(np.isfinite(a.reshape(a.shape[0], -1)), axis=1)]


def yaw_wxyz(theta: float) -> np.ndarray:
    """Quaternion (w, x, y, z) of a rotation by ``theta`` about +z (REP-103 yaw)."""
    return np.array([math.cos(theta / 2.0), 0.0, 0.0, math.sin(theta / 2.0)])


def polyline_segments(xy: np.ndarray, z: float = 0.0) -> np.ndarray:
    """(N, 2+) polyline -> (N-1, 2, 3) segments at height ``z``; non-finite vertices are dropped."""
    xy = np.asarray(xy, dtype=np.float32)
    xy = finite_rows(xy.reshape(xy.shape[0], -1)[:, :2]) if xy.size else xy.reshape(0, 2)
    if xy.shape[0] < 2:
        return np.zeros((0, 2, 3), dtype=np.float32)
    seg = np.empty((xy.shape[0] - 1, 2, 3), dtype=np.float32)
    seg[:, 0, :2] = xy[:-1]
    seg[:, 1, :2] = xy[1:]
    seg[:, :, 2] = z
    return seg


def ring_segments(polygon: np.ndarray, z: float = 0.0) -> np.ndarray:
    """Closed (N, 2) polygon (e.g. a Nav2 footprint) -> (N, 2, 3) segments."""
    ring = np.asarray(polygon, dtype=float).reshape(-1, 2)
    return polyline_segments(np.vstack((ring, ring[:1])), z)


def trajectory_segments(samples: np.ndarray, z: float = 0.0, max_samples: int | None = None) -> np.ndarray:
    """(K, N, 2+) sampled trajectories (DWB/MPPI style) -> (K'*(N-1), 2, 3) segments, every
    ``ceil(K / max_samples)``-th trajectory kept so the browser is not flooded."""
    s = np.asarray(samples, dtype=np.float32)
    if max_samples is not None and s.shape[0] > max_samples:
        s = s[:: math.ceil(s.shape[0] / max_samples)]
    k, n = s.shape[0], s.shape[1]
    if n < 2:
        return np.zeros((0, 2, 3), np.float32)
    seg = np.empty((k, n - 1, 2, 3), np.float32)
    seg[:, :, 0, :2] = s[:, :-1, :2]
    seg[:, :, 1, :2] = s[:, 1:, :2]
    seg[..., 2] = z
    return finite_rows(seg.reshape(-1, 2, 3))


def pose_arrows(poses: np.ndarray, length: float, z: float = 0.0, max_poses: int | None = None) -> np.ndarray:
    """(N, 3+) x, y, theta (extra columns such as weights ignored) -> (N', 2, 3) arrows, like Rviz's
    PoseArray display of the AMCL particle cloud; subsampled to at most ``max_poses``."""
    p = np.asarray(poses, dtype=float)
    p = finite_rows(p.reshape(p.shape[0], -1)[:, :3])
    if max_poses is not None and len(p) > max_poses:
        p = p[:: math.ceil(len(p) / max_poses)]
    seg = np.empty((len(p), 2, 3), np.float32)
    seg[:, 0, 0], seg[:, 0, 1] = p[:, 0], p[:, 1]
    seg[:, 1, 0] = p[:, 0] + length * np.cos(p[:, 2])
    seg[:, 1, 1] = p[:, 1] + length * np.sin(p[:, 2])
    seg[:, :, 2] = z
    return seg


def edge_segments(edges: np.ndarray, z: float = 0.0) -> np.ndarray:
    """(E, 2, 2) pose-graph edges (from xy, to xy) -> (E, 2, 3) segments."""
    e = finite_rows(np.asarray(edges, dtype=np.float32).reshape(-1, 2, 2))
    seg = np.empty((e.shape[0], 2, 3), np.float32)
    seg[:, :, :2] = e
    seg[:, :, 2] = z
    return seg


def scan_points(scan: LaserScan, laser_pose: Pose2D, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Valid returns (inf / nan / out-of-range dropped, REP-117) as (N, 3) float32 points in the frame
    ``laser_pose`` is given in (the map: robot pose composed with the laser's mount), plus their (N,)
    ranges for colouring."""
    mask = scan.valid_mask()
    r = scan.ranges[mask]
    a = scan.angles[mask]
    xy = laser_pose.transform_points(np.column_stack((r * np.cos(a), r * np.sin(a))))
    pts = np.empty((xy.shape[0], 3), np.float32)
    pts[:, :2] = xy
    pts[:, 2] = z
    return pts, r


def disc_segments(discs: np.ndarray, z: float, sides: int = 16) -> np.ndarray:
    """(P, 4) discs (x, y, heading, radius) -> (P * (sides + 1), 2, 3): outlines plus a heading tick."""
    a = np.linspace(0.0, 2.0 * np.pi, sides + 1)
    x, y, th, r = (discs[:, i : i + 1] for i in range(4))
    ring = np.stack((x + r * np.cos(a), y + r * np.sin(a)), axis=-1)  # (P, sides+1, 2)
    seg = np.stack((ring[:, :-1], ring[:, 1:]), axis=2)  # (P, sides, 2, 2)
    centre = np.concatenate((x, y), axis=1)
    nose = np.concatenate((x + r * np.cos(th), y + r * np.sin(th)), axis=1)
    tick = np.stack((centre, nose), axis=1)[:, None]  # (P, 1, 2, 2)
    both = np.concatenate((seg, tick), axis=1).reshape(-1, 2, 2)
    return np.concatenate((both, np.full((*both.shape[:2], 1), z)), axis=-1).astype(np.float32)


def circle_segments(radius: float, z: float = 0.0, sides: int = 32) -> np.ndarray:
    """A circle of ``radius`` about the origin as (sides, 2, 3) segments."""
    a = np.linspace(0.0, 2.0 * np.pi, sides + 1)
    return polyline_segments(np.column_stack((radius * np.cos(a), radius * np.sin(a))), z)


def diamond_segments(xy: np.ndarray, half: float, z: float = 0.0) -> np.ndarray:
    """(K, 2) centres -> (K, 4, 2, 3): a diamond (square on its corner) of half-diagonal ``half`` each."""
    c = np.asarray(xy, dtype=np.float32).reshape(-1, 2)
    corners = np.array([[half, 0.0], [0.0, half], [-half, 0.0], [0.0, -half]], np.float32)
    ring = c[:, None, :] + corners[None]  # (K, 4, 2)
    seg = np.empty((c.shape[0], 4, 2, 3), np.float32)
    seg[:, :, 0, :2] = ring
    seg[:, :, 1, :2] = np.roll(ring, -1, axis=1)
    seg[..., 2] = z
    return seg


def pose_arrow_lines(
    poses: np.ndarray, length: float, z: float = 0.0, head: float = 0.3, max_poses: int | None = None
) -> np.ndarray:
    """(N, 3+) poses -> (N', 3, 2, 3): per pose a shaft along theta and two head strokes (``head`` of the
    length, 30 degrees off the shaft), subsampled like ``pose_arrows``. Line segments, so the browser
    needs no mesh (PBR) shader program to draw them."""
    shaft = pose_arrows(poses, length, z, max_poses)  # (N', 2, 3), non-finite rows dropped
    tip = shaft[:, 1, :2].astype(float)
    theta = np.arctan2(*(shaft[:, 1, :2] - shaft[:, 0, :2]).T[::-1].astype(float))
    out = np.empty((len(shaft), 3, 2, 3), np.float32)
    out[:, 0] = shaft
    for k, side in enumerate((1.0, -1.0), start=1):
        back = theta + np.pi - side * np.pi / 6.0
        out[:, k, 0, :2] = tip
        out[:, k, 1, 0] = tip[:, 0] + head * length * np.cos(back)
        out[:, k, 1, 1] = tip[:, 1] + head * length * np.sin(back)
        out[:, k, :, 2] = z
    return out
