"""Laser sensor models for Monte Carlo localization, vectorized over particles x beams.

* Likelihood field (Thrun et al., *Probabilistic Robotics*, Table 6.3): each beam endpoint is
  scored by its distance ``d`` to the nearest occupied cell, ``p = z_hit N(d; 0, sigma_hit) +
  z_rand / z_max``. The distance field is computed once per map with an exact Euclidean distance
  transform (``scipy.ndimage.distance_transform_edt``), so an update needs no ray casting.
* Beam model (Table 6.1): each beam is compared with the range ray-cast in the map from the
  particle; the mixture has hit (Gaussian), short (exponential), max (point mass) and random
  (uniform) parts.

Combination over beams follows Nav2 ``nav2_amcl/sensors/laser``: ``likelihood_field`` and ``beam``
use ``1 + sum(p_k^3)`` rather than the product of the ``p_k``, a deliberate heuristic that stops
60 correlated beams from making the posterior absurdly peaked (the independence assumption of
the product is false for neighbouring beams); ``likelihood_field_prob`` uses the true product (as a
sum of logs) and optional beam skipping. Nav2 keeps the Gaussian unnormalised (peak ``z_hit``);
so does navdeck, so that ``z_hit`` and ``z_rand`` keep their Nav2 meaning.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from nav.localization.beam_kernel import beam_log_weights
from nav.localization.options import AmclOptions
from nav.localization.sphere_trace import ClearanceTracer
from nav.types import LaserScan, OccupancyGrid, Pose2D, wrap_angle

# ray caster: (occupied (H, W) bool, geometry, origins (P, 2), angles (P, B), max_range) -> (P, B)
RayCaster = Callable[..., np.ndarray]


class SensorModelError(ValueError):
    """A sensor model cannot be built or evaluated (bad map, missing ray caster)."""


@dataclass(frozen=True)
class Beams:
    """The subset of a scan used for one update, in the laser frame.

    ``ranges`` are metres with no-return and too-short readings replaced by ``range_max`` (Nav2's
    convention), ``hit`` marks real returns (``ranges < range_max``)."""

    ranges: np.ndarray  # (B,)
    bearings: np.ndarray  # (B,) radians in the laser frame
    range_max: float

    @property
    def hit(self) -> np.ndarray:
        return self.ranges < self.range_max


def select_beams(scan: LaserScan, options: AmclOptions) -> Beams:
    """Pick ``laser_max_beams`` evenly spaced beams and clamp ranges like Nav2's ``laserReceived``.

    ``laser_max_range`` / ``laser_min_range`` <= 0 mean "use the scan's limits"; readings at or below
    the minimum range and non-returns become ``range_max``; NaN readings are dropped.
    """
    range_max = scan.range_max
    if options.laser_max_range > 0.0:
        range_max = min(range_max, options.laser_max_range)
    range_min = scan.range_min
    if options.laser_min_range > 0.0:
        range_min = max(range_min, options.laser_min_range)
    n = scan.ranges.shape[0]
    step = max((n - 1) // (options.laser_max_beams - 1), 1)
    idx = np.arange(0, n, step)
    r = np.asarray(scan.ranges, dtype=float)[idx]
    bearings = scan.angle_min + scan.angle_increment * idx.astype(float)
    keep = ~np.isnan(r)
    r = r[keep]
    bearings = bearings[keep]
    r = np.where((r <= range_min) | (r >= range_max), range_max, r)
    return Beams(ranges=r, bearings=bearings, range_max=float(range_max))


def _laser_poses(particles: np.ndarray, laser_pose: Pose2D) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Laser origin (x, y) and heading per particle: particle ⊕ laser_pose."""
    c, s = np.cos(particles[:, 2]), np.sin(particles[:, 2])
    lx = particles[:, 0] + c * laser_pose.x - s * laser_pose.y
    ly = particles[:, 1] + s * laser_pose.x + c * laser_pose.y
    lt = particles[:, 2] + laser_pose.theta
    return lx, ly, lt


def beam_endpoints(particles: np.ndarray, laser_pose: Pose2D, beams: Beams) -> tuple[np.ndarray, np.ndarray]:
    """World (map) coordinates of every beam endpoint: two (N, B) arrays.

    Each is one (N, 3) x (3, B) matrix product, ``[cos t, -sin t, x] @ [r cos b; r sin b; 1]``, so
    only N + B trigonometric calls are made and the N x B work runs in BLAS."""
    lx, ly, lt = _laser_poses(particles, laser_pose)
    ct, st = np.cos(lt), np.sin(lt)
    local = np.vstack((beams.ranges * np.cos(beams.bearings), beams.ranges * np.sin(beams.bearings)))
    local = np.vstack((local, np.ones((1, local.shape[1]))))
    ex = np.column_stack((ct, -st, lx)) @ local
    ey = np.column_stack((st, ct, ly)) @ local
    return ex, ey


class LikelihoodField:
    """Distance to the nearest occupied cell, capped at ``max_dist`` (Nav2 ``max_occ_dist``), and
    the hit Gaussian ``exp(-d^2 / 2 sigma_hit^2)`` of it, both precomputed for the whole map.

    The field is padded by one cell of ``max_dist`` all round, so endpoints off the map are
    clipped onto the pad and read ``max_dist`` (Nav2's off-map rule) with a single gather."""

    def __init__(self, grid: OccupancyGrid, max_dist: float, sigma_hit: float) -> None:
        geo = grid.geometry
        occ = grid.occupied_mask()
        if geo.width < 1 or geo.height < 1:
            raise SensorModelError("empty map")
        if occ.any():
            dist = distance_transform_edt(~occ) * geo.resolution
        else:
            dist = np.full(occ.shape, max_dist)
        dist = np.minimum(dist, max_dist)
        self.geometry = geo
        self.max_dist = float(max_dist)
        self.sigma_hit = float(sigma_hit)
        self.distance = np.pad(dist, 1, constant_values=max_dist)
        gauss = np.exp(-(self.distance**2) / (2.0 * sigma_hit * sigma_hit))
        self._gauss_flat = gauss.ravel()
        self._dist_flat = self.distance.ravel()
        self._inv_origin = geo.origin.inverse()
        self._tables: dict[tuple[str, float, float, float], np.ndarray] = {}

    def _flat_index(self, ex: np.ndarray, ey: np.ndarray) -> np.ndarray:
        geo, o = self.geometry, self._inv_origin
        if geo.origin.theta != 0.0:
            c, s = np.cos(o.theta), np.sin(o.theta)
            ex, ey = c * ex - s * ey + o.x, s * ex + c * ey + o.y
            ox = oy = 0.0
        else:
            ox, oy = geo.origin.x, geo.origin.y
        inv_res = 1.0 / geo.resolution
        # +1 for the pad; the cell coordinate is computed in place to keep temporaries few.
        cols = (ex - ox) * inv_res
        np.floor(cols, out=cols)
        cols += 1.0
        np.clip(cols, 0.0, geo.width + 1, out=cols)
        rows = (ey - oy) * inv_res
        np.floor(rows, out=rows)
        rows += 1.0
        np.clip(rows, 0.0, geo.height + 1, out=rows)
        rows *= geo.width + 2
        rows += cols
        return rows.astype(np.intp)

    def table(self, kind: str, z_hit: float, z_rand: float, range_max: float) -> np.ndarray:
        """Flat per-cell table of ``pz = z_hit exp(-d^2 / 2 sigma^2) + z_rand / range_max`` as
        ``log(pz)`` (``kind="log"``) or ``pz^3`` (``kind="cube"``), cached: a scan update then costs
        one gather per beam endpoint instead of an exp / log per endpoint."""
        key = (kind, z_hit, z_rand, range_max)
        t = self._tables.get(key)
        if t is None:
            pz = z_hit * self._gauss_flat + z_rand / range_max
            t = np.log(pz) if kind == "log" else pz * pz * pz
            if len(self._tables) > 8:  # scans with ever-changing range_max: keep the cache small
                self._tables.clear()
            self._tables[key] = t
        return t

    def distance_at(self, ex: np.ndarray, ey: np.ndarray) -> np.ndarray:
        """Capped distance (m) to the nearest obstacle at world points of any shape."""
        return self._dist_flat[self._flat_index(ex, ey)]

    def gauss_at(self, ex: np.ndarray, ey: np.ndarray) -> np.ndarray:
        """``exp(-d^2 / 2 sigma_hit^2)`` at world points of any shape."""
        return self._gauss_flat[self._flat_index(ex, ey)]


def likelihood_field_weights(
    field: LikelihoodField,
    particles: np.ndarray,
    laser_pose: Pose2D,
    beams: Beams,
    options: AmclOptions,
) -> np.ndarray:
    """Nav2 ``LikelihoodFieldModel``: per-particle log of ``1 + sum_k p_k^3`` over beams with a return,
    ``p_k = z_hit exp(-d_k^2 / 2 sigma_hit^2) + z_rand / range_max``. Returns (N,) log weights."""
    hit = beams.hit
    if not hit.any():
        return np.zeros(particles.shape[0])
    sub = Beams(beams.ranges[hit], beams.bearings[hit], beams.range_max)
    ex, ey = beam_endpoints(particles, laser_pose, sub)
    cube = field.table("cube", options.z_hit, options.z_rand, beams.range_max)
    return np.log1p(np.sum(cube[field._flat_index(ex, ey)], axis=1))


def likelihood_field_prob_weights(
    field: LikelihoodField,
    particles: np.ndarray,
    laser_pose: Pose2D,
    beams: Beams,
    options: AmclOptions,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Nav2 ``LikelihoodFieldModelProb``: the product of ``p_k`` (sum of logs), optionally skipping
    beams that fewer than ``beam_skip_threshold`` of the particles explain (endpoint within
    ``beam_skip_distance`` of an obstacle): such beams likely hit something not in the map. If too
    few beams survive (< ``beam_skip_error_threshold``) the filter is probably lost, so all are used.
    With ``weights`` the fraction is weighted by particle weight rather than counted."""
    hit = beams.hit
    if not hit.any():
        return np.zeros(particles.shape[0])
    sub = Beams(beams.ranges[hit], beams.bearings[hit], beams.range_max)
    ex, ey = beam_endpoints(particles, laser_pose, sub)
    idx = field._flat_index(ex, ey)
    logpz = field.table("log", options.z_hit, options.z_rand, beams.range_max)[idx]
    if options.do_beamskip:
        close = field._dist_flat[idx] < options.beam_skip_distance
        if weights is None:
            explained = np.mean(close, axis=0)
        else:  # weighted particle sets (after random injection): fraction of the probability mass
            explained = (weights / weights.sum()) @ close
        keep = explained >= options.beam_skip_threshold
        if keep.mean() >= options.beam_skip_error_threshold:
            logpz = logpz[:, keep]
    return np.sum(logpz, axis=1)


def beam_model_weights(
    occupied: np.ndarray,
    grid: OccupancyGrid,
    cast_rays: RayCaster,
    particles: np.ndarray,
    laser_pose: Pose2D,
    beams: Beams,
    options: AmclOptions,
) -> np.ndarray:
    """Nav2 ``BeamModel`` (Thrun Table 6.1): expected ranges are ray-cast from every particle's laser
    pose; per-beam mixture of hit, short (only if the reading is shorter than expected), max and
    random parts, combined as ``log(1 + sum_k p_k^3)``. Returns (N,) log weights."""
    if beams.ranges.size == 0:
        return np.zeros(particles.shape[0])
    lx, ly, lt = _laser_poses(particles, laser_pose)
    angles = wrap_angle(lt[:, None] + beams.bearings[None, :])
    expected = cast_rays(occupied, grid.geometry, np.column_stack((lx, ly)), angles, beams.range_max)
    expected = np.where(np.isfinite(expected), np.minimum(expected, beams.range_max), beams.range_max)
    obs = beams.ranges[None, :]
    z = obs - expected
    pz = options.z_hit * np.exp(-(z * z) / (2.0 * options.sigma_hit**2))
    short = options.z_short * options.lambda_short * np.exp(-options.lambda_short * obs)
    pz = pz + np.where(z < 0.0, short, 0.0)
    is_max = obs >= beams.range_max
    pz = pz + np.where(is_max, options.z_max, options.z_rand / beams.range_max)
    return np.log1p(np.sum(pz * pz * pz, axis=1))


def beam_model_weights_compiled(
    tracer: ClearanceTracer, particles: np.ndarray, laser_pose: Pose2D, beams: Beams, options: AmclOptions
) -> np.ndarray:
    """``beam_model_weights`` in one compiled pass over particles x beams (``beam_kernel``) on a
    clearance table built once per map; the same log weights."""
    if beams.ranges.size == 0:
        return np.zeros(particles.shape[0])
    lx, ly, lt = _laser_poses(particles, laser_pose)
    return beam_log_weights(
        tracer, np.column_stack((lx, ly)), lt, beams.bearings, beams.ranges, beams.range_max, options
    )


def scan_fit(field: LikelihoodField, pose: Pose2D, laser_pose: Pose2D, beams: Beams) -> float:
    """How well a scan fits the map at ``pose``: the mean over beams with a return of
    ``exp(-d^2 / 2 sigma_hit^2)``, in [0, 1] (1: every endpoint on an obstacle). 0 if no returns."""
    hit = beams.hit
    if not hit.any():
        return 0.0
    sub = Beams(beams.ranges[hit], beams.bearings[hit], beams.range_max)
    ex, ey = beam_endpoints(pose.as_array()[None, :], laser_pose, sub)
    return float(np.mean(field.gauss_at(ex, ey)))


def scan_inlier_fraction(
    field: LikelihoodField, pose: Pose2D, laser_pose: Pose2D, beams: Beams, tolerance: float
) -> float:
    """The fraction of beams with a return whose endpoint at ``pose`` lies within ``tolerance``
    metres of a mapped obstacle, in [0, 1]; 0 if no returns. Unlike ``scan_fit``'s Gaussian, which
    still gives 0.6 to an endpoint 0.2 m off, a near-miss counts nothing here: a wrong pose in a
    room of walls explains few beams to a cell or two, the right one explains all but those on
    things the map lacks (people, moved furniture)."""
    hit = beams.hit
    if not hit.any():
        return 0.0
    sub = Beams(beams.ranges[hit], beams.bearings[hit], beams.range_max)
    ex, ey = beam_endpoints(pose.as_array()[None, :], laser_pose, sub)
    return float(np.mean(field.distance_at(ex, ey) <= tolerance))
