"""The SLAM benchmark metric of Kümmerle et al. 2009, "On measuring the accuracy of SLAM algorithms".

A relation ``(t1, t2, z)`` is the true pose at ``t2`` in the frame of the pose at ``t1``. With the
estimated poses ``P1, P2`` the error is ``e = z^-1 (P1^-1 P2)``; the metric reports the mean and
std-dev of ``|translation(e)|`` (m) and ``|rotation(e)|`` (deg). Estimated poses are looked up by
nearest timestamp within a tolerance; relations without a match are skipped (and counted).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


class MetricError(ValueError):
    """No relation could be evaluated against the trajectory."""


@dataclass(frozen=True)
class SlamScore:
    n: int
    trans_mean: float
    trans_std: float
    rot_mean_deg: float
    rot_std_deg: float
    skipped: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


def _nearest(t_sorted: np.ndarray, q: np.ndarray) -> np.ndarray:
    k = np.clip(np.searchsorted(t_sorted, q), 1, len(t_sorted) - 1)
    left = t_sorted[k - 1]
    right = t_sorted[k]
    return np.where(np.abs(q - left) <= np.abs(right - q), k - 1, k)


def relative_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a^-1 b for (N, 3) poses."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    th = (b[:, 2] - a[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack((c * dx + s * dy, -s * dx + c * dy, th))


def in_sensor_frame(trajectory: np.ndarray, sensor: np.ndarray) -> np.ndarray:
    """(N, 4) ``t, x, y, theta`` trajectory of a frame fixed on the robot at ``sensor`` = (x, y,
    theta) in the trajectory's frame (e.g. base_link poses -> the laser's poses).

    The Freiburg relations were obtained by aligning the laser scans, so they relate *laser*
    poses; scoring base_link poses of a robot whose laser is mounted off-centre adds an error of
    up to twice the mount offset to every relation with a large heading change."""
    p = trajectory[:, 1:4]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    dx, dy, dth = (float(v) for v in sensor)
    th = (p[:, 2] + dth + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack((trajectory[:, 0], p[:, 0] + c * dx - s * dy, p[:, 1] + s * dx + c * dy, th))


def relation_errors(
    trajectory: np.ndarray, relations: np.ndarray, tolerance: float = 1e-3
) -> tuple[np.ndarray, np.ndarray, int]:
    """Per-relation translational (m) and rotational (rad) errors, and the number skipped.

    ``trajectory`` is (N, 4) ``t, x, y, theta``; ``relations`` is (M, 5) ``t1, t2, x, y, yaw``.
    """
    if trajectory.shape[0] < 2:
        raise MetricError("trajectory has fewer than 2 poses")
    order = np.argsort(trajectory[:, 0], kind="stable")
    t = trajectory[order, 0]
    poses = trajectory[order, 1:4]
    k1 = _nearest(t, relations[:, 0])
    k2 = _nearest(t, relations[:, 1])
    ok = (np.abs(t[k1] - relations[:, 0]) <= tolerance) & (np.abs(t[k2] - relations[:, 1]) <= tolerance)
    if not ok.any():
        raise MetricError("no relation timestamps match the trajectory")
    d = relative_poses(poses[k1[ok]], poses[k2[ok]])
    z = relations[ok][:, 2:5]
    # e = z^-1 d
    e = relative_poses(z, d)
    return np.hypot(e[:, 0], e[:, 1]), np.abs(e[:, 2]), int((~ok).sum())


def score_trajectory(trajectory: np.ndarray, relations: np.ndarray, tolerance: float = 1e-3) -> SlamScore:
    """Kümmerle et al. 2009 absolute errors (mean and std-dev)."""
    et, er, skipped = relation_errors(trajectory, relations, tolerance)
    erd = np.degrees(er)
    return SlamScore(
        int(et.size), float(et.mean()), float(et.std()), float(erd.mean()), float(erd.std()), skipped
    )


def parse_relations(text: str) -> np.ndarray:
    """Parse a ``.relations`` file (``t1 t2 x y z roll pitch yaw``; ``#`` comments) into (M, 5)."""
    rows = []
    for ln in text.splitlines():
        tok = ln.split("#", 1)[0].split()
        if not tok:
            continue
        if len(tok) < 8:
            raise MetricError(f"relation line needs 8 numbers: {ln!r}")
        v = [float(x) for x in tok[:8]]
        rows.append((v[0], v[1], v[2], v[3], v[7]))
    if not rows:
        raise MetricError("no relations found")
    return np.array(rows)


def parse_trajectory(text: str) -> np.ndarray:
    """Parse ``timestamp x y theta`` lines into (N, 4)."""
    rows = [ln.split()[:4] for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise MetricError("empty trajectory")
    try:
        return np.array(rows, dtype=float)
    except ValueError as exc:
        raise MetricError(f"bad trajectory line: {exc}") from exc
