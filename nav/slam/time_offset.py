"""Odometry-to-laser time offset, estimated from the data.

Logs stamp odometry and laser on different clocks or with different latencies (FR079's odometry,
interpolated at the scan stamps, lags the laser by ~0.1 s; ACES by ~0.09 s; Intel by 0). In fast
turns that puts the odometry prediction several degrees off, beyond what a small matching window can
absorb. Like the temporal calibration of Furgale et al. 2013 (Kalibr) in its simplest form, the lag
is the shift that best aligns the odometry heading increments with the scan-matched ones: the front
end's node headings between consecutive nodes against odometry interpolated at ``t - lag``, a
robust least-squares cost evaluated for all candidate lags at once, refined by a parabola.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.types import wrap_angle


def interpolate_poses(t_query: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Linearly interpolate (N, 3) poses (angles unwrapped first) at ``t_query``; held at the ends."""
    order = np.argsort(t, kind="stable")
    t, poses = t[order], poses[order]
    th = np.unwrap(poses[:, 2])
    out = np.column_stack(
        (np.interp(t_query, t, poses[:, 0]), np.interp(t_query, t, poses[:, 1]), np.interp(t_query, t, th))
    )
    out[:, 2] = wrap_angle(out[:, 2])
    return out


@dataclass(frozen=True)
class LagEstimate:
    """``lag`` (s): odometry at ``t_scan - lag`` matches the laser at ``t_scan`` (lag > 0: the laser
    is stamped late against odometry, or odometry early); ``cost`` and
    ``cost_at_zero`` are the robust mean squared heading-increment residuals (rad^2)."""

    lag: float
    cost: float
    cost_at_zero: float
    pairs: int


def estimate_odometry_lag(
    stamps: np.ndarray,
    headings: np.ndarray,
    t_odom: np.ndarray,
    odom_theta: np.ndarray,
    max_lag: float = 0.3,
    step: float = 0.005,
    outlier: float = np.radians(5.0),
) -> LagEstimate:
    """Lag of odometry behind the laser from scan-matched ``headings`` at ``stamps`` (front-end
    nodes, sorted by time) and odometry headings ``odom_theta`` at ``t_odom``.

    The residual of each consecutive pair is capped at ``outlier`` (a bad match or a slip must not
    pick the lag), and ``max_lag`` bounds the search on both sides."""
    stamps = np.asarray(stamps, float)
    if stamps.size < 3:
        return LagEstimate(0.0, float("nan"), float("nan"), 0)
    order = np.argsort(t_odom, kind="stable")
    to = np.asarray(t_odom, float)[order]
    th_o = np.unwrap(np.asarray(odom_theta, float)[order])
    d_scan = np.diff(np.unwrap(np.asarray(headings, float)))
    k = round(max_lag / step)
    lags = step * np.arange(-k, k + 1)
    # all candidate lags at once: (L, N) query times, one interp call
    q = np.interp((stamps[None, :] - lags[:, None]).ravel(), to, th_o).reshape(lags.size, -1)
    r = np.diff(q, axis=1) - d_scan[None, :]
    cost = np.minimum(r * r, outlier * outlier).mean(axis=1)
    best = int(np.lexsort((np.abs(lags), cost))[0])  # ties (no turning at all): the smallest lag
    lag = float(lags[best])
    if 0 < best < lags.size - 1:  # parabola through the minimum and its neighbours
        c0, c1, c2 = cost[best - 1], cost[best], cost[best + 1]
        den = c0 - 2 * c1 + c2
        if den > 0:
            lag += step * float(np.clip(0.5 * (c0 - c2) / den, -0.5, 0.5))
    return LagEstimate(lag, float(cost[best]), float(cost[k]), int(d_scan.size))
