"""Velocity sampling over the dynamic window and arc simulation of every sample at once.

Fox, Burgard & Thrun, "The Dynamic Window Approach to Collision Avoidance", IEEE RAM 1997:
the search space is the set of velocities reachable from the current one within one control
period under the acceleration limits (the *dynamic window* V_d), each simulated as a circular arc
(constant (v, w)). The layout is Nav2 DWB's: ``XYThetaIterator`` samples ``vx_samples`` x
``vy_samples`` x ``vtheta_samples`` twists (zero is added on an axis whose window contains it,
like DWB's ``OneDVelocityIterator``), invalid speeds are dropped like ``isValidSpeed``, and poses are
spaced by ``linear_granularity`` / ``angular_granularity`` like ``StandardTrajectoryGenerator``.

All K trajectories share one time grid (the finest any of them needs) so they form one
(K, T, 3) array; the arcs are integrated in closed form rather than with DWB's Euler steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from nav.control.options import DwaOptions
from nav.types import Pose2D, Twist2D


def window_1d(
    v0: float, v_min: float, v_max: float, acc: float, decel: float, dt: float, samples: int
) -> np.ndarray:
    """Velocities sampled in [v0 - decel*dt, v0 + acc*dt] ∩ [v_min, v_max] (Fox's V_d ∩ V_s).

    ``acc`` (>= 0) applies when speeding up, ``|decel|`` when slowing towards zero, as DWB's
    ``projectVelocity``. Zero is added when inside the window so stopping or rotating in place is
    always among the samples.
    """
    acc, dec = abs(acc), abs(decel)
    up = acc if v0 >= 0 else dec  # rate available to increase v
    down = dec if v0 > 0 else acc  # rate available to decrease v
    hi = min(v_max, v0 + up * dt)
    lo = max(v_min, v0 - down * dt)
    if hi < lo:  # current velocity outside the limits: pull it back towards them
        hi = lo = min(max(v0, v_min), v_max)
    # plain floats: ~20 values, where numpy's per-call overhead would cost more than the work
    if samples <= 1 or hi - lo < 1e-12:
        vals = [0.5 * (lo + hi)]
    else:
        step = (hi - lo) / (samples - 1)
        tiny = 1e-12 * max(abs(lo), abs(hi), 1.0)
        vals = [lo + i * step for i in range(samples - 1)] + [hi]
        vals = [0.0 if abs(v) < tiny else v for v in vals]  # round-off near zero
    if lo <= 0.0 <= hi and 0.0 not in vals:
        vals.append(0.0)
        vals.sort()
    return np.array(vals)


def sample_twists(options: DwaOptions, velocity: Twist2D) -> np.ndarray:
    """(K, 3) twists (vx, vy, wz): the grid over the dynamic window, filtered like DWB's
    ``XYThetaIterator::isValidSpeed`` (max_speed_xy, min_speed_xy/min_speed_theta, not all zero)."""
    o = options
    dt = o.sim_period
    vx = window_1d(velocity.vx, o.min_vel_x, o.max_vel_x, o.acc_lim_x, o.decel_lim_x, dt, o.vx_samples)
    if o.holonomic and (o.max_vel_y > o.min_vel_y):
        vy = window_1d(velocity.vy, o.min_vel_y, o.max_vel_y, o.acc_lim_y, o.decel_lim_y, dt, o.vy_samples)
    else:
        vy = np.zeros(1)
    wz = window_1d(
        velocity.wz,
        -o.max_vel_theta,
        o.max_vel_theta,
        o.acc_lim_theta,
        o.decel_lim_theta,
        dt,
        o.vtheta_samples,
    )
    max_sq = o.max_speed_xy**2 + 1e-12 if o.max_speed_xy > 0 else math.inf
    return _grid(vx, vy, wz, o.min_speed_xy**2, o.min_speed_theta, max_sq)


@njit(cache=True, nogil=True)
def _grid(
    vx: np.ndarray, vy: np.ndarray, wz: np.ndarray, min_xy_sq: float, min_theta: float, max_sq: float
) -> np.ndarray:
    """The (vx, vy, wz) grid in C order minus the invalid speeds (``max_sq``: the largest squared
    speed allowed), in one pass, with no (K, 3) temporaries per test."""
    out = np.empty((vx.size * vy.size * wz.size, 3))
    k = 0
    for a in vx:
        for b in vy:
            speed_sq = a**2 + b**2
            for w in wz:
                w_abs = abs(w)
                if speed_sq < min_xy_sq and w_abs < min_theta:
                    continue
                if speed_sq == 0.0 and w_abs == 0.0:
                    continue
                if speed_sq > max_sq:
                    continue
                out[k, 0], out[k, 1], out[k, 2] = a, b, w
                k += 1
    return out[:k]


def time_steps(options: DwaOptions, twists: np.ndarray) -> np.ndarray:
    """Sample times (T,), from 0 to ``sim_time`` inclusive, fine enough for every twist.

    DWB steps every ``linear_granularity`` of travel or ``angular_granularity`` of turn. With
    ``footprint_step`` a turn is measured instead by how far it moves the footprint's farthest point
    (circumscribed radius x angle), added to the travel: the footprint check is heading-binned
    (``footprint_orientation_bins``), so headings finer than a point moving one
    ``linear_granularity`` change nothing it sees, and a 1 rad/s sample needs ~15 poses, not 60.
    """
    o = options
    if o.discretize_by_time:
        n = math.ceil(o.sim_time / o.time_granularity)
    elif o.footprint_step:
        sweep = _max_sweep(np.ascontiguousarray(twists, dtype=np.float64), o.circumscribed_radius)
        n = math.ceil(sweep * o.sim_time / o.linear_granularity)
    else:
        lin = float(np.max(np.hypot(twists[:, 0], twists[:, 1]), initial=0.0)) * o.sim_time
        ang = float(np.max(np.abs(twists[:, 2]), initial=0.0)) * o.sim_time
        n = math.ceil(max(lin / o.linear_granularity, ang / o.angular_granularity))
    return _time_grid(o.sim_time, int(min(max(n, 1), o.max_steps)))


@njit(cache=True, nogil=True)
def _max_sweep(twists: np.ndarray, radius: float) -> float:
    """max(0, max over twists of hypot(vx, vy) + radius * |wz|): how fast any footprint point moves."""
    best = 0.0
    for k in range(twists.shape[0]):
        best = max(best, math.hypot(twists[k, 0], twists[k, 1]) + radius * abs(twists[k, 2]))
    return best


@lru_cache(maxsize=64)
def _time_grid(sim_time: float, n: int) -> np.ndarray:
    """``linspace(0, sim_time, n + 1)``, read-only and shared: the same few grids recur every cycle."""
    t = np.linspace(0.0, sim_time, n + 1)
    t.flags.writeable = False
    return t


@njit(cache=True, nogil=True)
def _arcs(
    x0: float, y0: float, th0: float, twists: np.ndarray, times: np.ndarray, out: np.ndarray, xy32: np.ndarray
) -> None:
    c0, s0 = math.cos(th0), math.sin(th0)
    k_n, t_n = twists.shape[0], times.shape[0]
    # sin(w t) / w and (1 - cos(w t)) / w depend on w only, and a sampled window has ~20 distinct
    # w for ~500 twists: one table row per distinct w (found by a short linear search) cuts the
    # trigonometry ~20x with bit-identical values
    seen = np.empty(k_n)
    tab_s, tab_c = np.empty((k_n, t_n)), np.empty((k_n, t_n))
    n_seen = 0
    for k in range(k_n):
        vx, vy, w = twists[k, 0], twists[k, 1], twists[k, 2]
        row = -1
        for u in range(n_seen):
            if seen[u] == w:
                row = u
                break
        if row < 0:
            row, n_seen = n_seen, n_seen + 1
            seen[row] = w
            straight = abs(w) < 1e-9
            for j in range(t_n):
                t = times[j]
                a = w * t
                if straight:  # the w -> 0 limits
                    tab_s[row, j], tab_c[row, j] = t, 0.5 * a * t
                else:
                    tab_s[row, j], tab_c[row, j] = math.sin(a) / w, (1.0 - math.cos(a)) / w
        for j in range(t_n):
            s, c = tab_s[row, j], tab_c[row, j]
            bx = vx * s - vy * c
            by = vx * c + vy * s
            out[k, j, 0] = x0 + c0 * bx - s0 * by
            out[k, j, 1] = y0 + s0 * bx + c0 * by
            out[k, j, 2] = th0 + w * times[j]
            xy32[k, j, 0], xy32[k, j, 1] = out[k, j, 0], out[k, j, 1]


def simulate_arcs(pose: Pose2D, twists: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(K, T, 3) world poses of constant body twists (K, 3) from ``pose`` at ``times`` (T,).

    Closed form of the holonomic unicycle (source C's kinematics, constant body velocity):
    in the start frame x(t) = (vx sin wt - vy (1 - cos wt)) / w, y(t) = (vx (1 - cos wt) + vy sin wt) / w,
    with the w -> 0 limits (t and w t^2 / 2) for straight-line samples. A compiled loop: one pass
    without the (K, T) temporaries numpy would allocate for each term.
    """
    return _simulate(pose, twists, times)[0]


def _simulate(pose: Pose2D, twists: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``simulate_arcs`` plus the (K, T, 2) float32 positions the debug output carries."""
    tw = np.ascontiguousarray(twists, dtype=np.float64)
    ts = np.ascontiguousarray(times, dtype=np.float64)
    out = np.empty((tw.shape[0], ts.shape[0], 3))
    xy32 = np.empty((tw.shape[0], ts.shape[0], 2), dtype=np.float32)
    _arcs(float(pose.x), float(pose.y), float(pose.theta), tw, ts, out, xy32)
    return out, xy32


@dataclass(frozen=True)
class TrajectorySet:
    """K sampled trajectories: ``twists`` (K, 3), ``times`` (T,), ``poses`` (K, T, 3) in the map
    frame (headings unwrapped: pose.theta + wz * t)."""

    twists: np.ndarray
    times: np.ndarray
    poses: np.ndarray
    xy32: np.ndarray | None = None  # (K, T, 2) float32 positions (the debug output), if made

    def __len__(self) -> int:
        return int(self.twists.shape[0])


def generate(options: DwaOptions, pose: Pose2D, velocity: Twist2D) -> TrajectorySet:
    """Sample the dynamic window around ``velocity`` and simulate every sample from ``pose``."""
    twists = sample_twists(options, velocity)
    times = time_steps(options, twists)
    return TrajectorySet(twists, times, *_simulate(pose, twists, times))
