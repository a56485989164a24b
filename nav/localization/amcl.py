"""Augmented Monte Carlo Localization with KLD-adaptive sample size (Nav2 ``amcl`` equivalent).

Algorithm: Thrun, Burgard & Fox, *Probabilistic Robotics* (2005), Table 8.3 (Augmented_MCL):
sample motion (``motion_models``), weight by the laser (``sensor_models``), track the short- and
long-term averages ``w_fast`` / ``w_slow`` of the measurement likelihood and, while the short-term
one falls below the long-term one (the robot was kidnapped, or the map no longer explains the
scans), replace a fraction ``max(0, 1 - w_fast / w_slow)`` of the resampled particles with poses
drawn uniformly over free space. Resampling is low-variance (Table 4.4) and the sample count after
it follows KLD-sampling (Fox 2003, ``kld``). Filter updates are gated on odometry motion
(``update_min_d`` / ``update_min_a``) as in Nav2, and the published estimate is the weighted mean
of the heaviest particle cluster (``clustering``).

Departures from Nav2 (each measured in ``bench/amcl.py``; see docs/localization.md):
* ``w_avg`` is the prior-weighted mean likelihood ``sum_i w_i p_i`` (Thrun), taken per beam
  (geometric mean), not the total divided by the sample count: KLD changes the count between
  updates, and the product over ~60 beams would raise w_fast / w_slow to the 60th power.
* Random poses keep coming while ``w_diff`` exceeds ``recovery_w_diff_min`` (Thrun); Nav2 zeroes
  both averages after any injection, which allows one small injection per kidnapping.
* Each injected slot is ``global_localization_particles / max_particles`` uniform poses of
  matching lower weight (same mixture, denser), and ``global_localization`` starts that dense.
* After a global reset w_slow starts near the likelihood of a good fit (``_EXPECTED_FIT_FRACTION``).
* The estimate is taken from the posterior sample, before the random poses are mixed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from nav.localization import sensor_models as sm
from nav.localization.clustering import best_cluster, weighted_pose_stats
from nav.localization.kld import count_bins, kld_sample_count
from nav.localization.motion_models import MotionAlphas, sample_motion
from nav.localization.options import AmclOptions
from nav.localization.resampling import low_variance_resample
from nav.localization.sphere_trace import ClearanceTracer
from nav.types import LaserScan, OccupancyGrid, Pose2D, wrap_angle

# Nav2 pf_update_converged: converged when every particle is within this distance of the mean.
_CONVERGED_DIST = 0.5
# Per-beam likelihood of a localized filter relative to a perfect fit (z_hit + z_rand / range_max):
# particle spread and range noise keep it near 0.85 (0.50 / 0.583 measured in bench.amcl); a wrong
# place scores 0.5-0.65. Seeds w_slow after a global reset (see ``_weigh``).
_EXPECTED_FIT_FRACTION = 0.8


class LocalizationError(RuntimeError):
    """Base class of the localizer's failures."""


class NoFreeSpaceError(LocalizationError):
    """The map has no free cell to place particles in (global localization is impossible)."""


class InvalidCovarianceError(LocalizationError, ValueError):
    """An initial-pose covariance is not a finite symmetric positive semi-definite 3x3 matrix."""


class NotInitializedError(LocalizationError):
    """A transform was asked for before any odometry pose was associated with the estimate."""


@dataclass(frozen=True)
class AmclStatus:
    """A snapshot for telemetry: what the filter did on its last update."""

    particle_count: int
    bins: int
    w_slow: float
    w_fast: float
    injected: int
    quality: float
    converged: bool


class Amcl:
    """Adaptive Monte Carlo localization on a static occupancy grid.

    ``update`` is called with every scan and the odometry pose at the scan's time; it returns
    whether the filter ran (it runs on the first scan after (re)initialisation and whenever
    odometry moved more than ``update_min_d`` or turned more than ``update_min_a`` since the
    last filter update).
    """

    def __init__(
        self,
        options: AmclOptions,
        grid: OccupancyGrid,
        seed: int | None = None,
        cast_rays: sm.RayCaster | None = None,
    ) -> None:
        """``cast_rays``: the beam model's ray caster; by default a compiled pass that casts and
        scores every beam at once (``beam_kernel``), equal to ``beam_model_weights`` with
        ``nav.raycast.cast_rays``."""
        self.options = options
        self.grid = grid
        self._rng = np.random.default_rng(seed)
        self._alphas = MotionAlphas(
            options.alpha1, options.alpha2, options.alpha3, options.alpha4, options.alpha5
        )
        self._field = sm.LikelihoodField(grid, options.laser_likelihood_max_dist, options.sigma_hit)
        self._occupied = grid.occupied_mask()
        self._cast_rays = cast_rays
        # the beam model's own clearance table, built once per map: uncapped (the likelihood
        # field's distances stop at laser_likelihood_max_dist, which would cap every jump)
        self._caster: ClearanceTracer | None = None
        if options.laser_model_type == "beam" and cast_rays is None:
            self._caster = ClearanceTracer(self._occupied, grid.geometry)
        free_r, free_c = np.nonzero(grid.free_mask())
        self._free_xy = grid.geometry.cell_to_world(free_r, free_c)  # free cell centres, map frame
        self._particles = np.zeros((0, 3))
        self._weights = np.zeros(0)
        self._odom_last: Pose2D | None = None
        self._w_slow = 0.0
        self._w_fast = 0.0
        self._updates = 0
        self._injected = 0
        self._quality = 0.0
        self._mean = np.zeros(3)
        self._cov = np.zeros((3, 3))
        if options.set_initial_pose:
            cov = np.diag([options.initial_cov_xx, options.initial_cov_yy, options.initial_cov_aa])
            self.set_initial_pose(
                Pose2D(options.initial_pose_x, options.initial_pose_y, options.initial_pose_yaw), cov
            )
        else:
            self.global_localization()

    # ----------------------------------------------------------------------------------- state
    @property
    def particles(self) -> np.ndarray:
        """(N, 3) particle poses [x, y, theta] in the map frame (read-only view)."""
        v = self._particles.view()
        v.flags.writeable = False
        return v

    @property
    def weights(self) -> np.ndarray:
        """(N,) normalised particle weights (read-only view)."""
        v = self._weights.view()
        v.flags.writeable = False
        return v

    @property
    def likelihood_field(self) -> sm.LikelihoodField:
        """The map's distance field the sensor model and the scan scores read."""
        return self._field

    @property
    def particle_count(self) -> int:
        return int(self._particles.shape[0])

    @property
    def quality(self) -> float:
        """Fit of the last scan at the estimate, in [0, 1]: mean over returning beams of
        ``exp(-d^2 / 2 sigma_hit^2)`` with ``d`` the endpoint's distance to the nearest obstacle
        (``sensor_models.scan_fit``). Near 1 when localized, near 0 when lost; 0 before any scan."""
        return self._quality

    @property
    def converged(self) -> bool:
        """Nav2's test: every particle within 0.5 m (x and y) of the mean."""
        mean = self._particles[:, :2].mean(axis=0)
        return bool(np.all(np.abs(self._particles[:, :2] - mean) <= _CONVERGED_DIST))

    @property
    def status(self) -> AmclStatus:
        o = self.options
        return AmclStatus(
            particle_count=self.particle_count,
            bins=count_bins(self._particles, o.kld_bin_xy, o.kld_bin_theta),
            w_slow=self._w_slow,
            w_fast=self._w_fast,
            injected=self._injected,
            quality=self._quality,
            converged=self.converged,
        )

    def estimate(self) -> tuple[Pose2D, np.ndarray]:
        """Weighted mean pose of the heaviest cluster and its 3x3 covariance (x, y, theta)."""
        return Pose2D.from_array(self._mean), self._cov.copy()

    def estimate_all(self) -> tuple[Pose2D, np.ndarray]:
        """Weighted mean and covariance of all particles (ignores clustering)."""
        mean, cov = weighted_pose_stats(self._particles, self._weights)
        return Pose2D.from_array(mean), cov

    def map_to_odom(self, odom_pose: Pose2D | None = None) -> Pose2D:
        """The map -> odom transform (REP-105) that places ``base_link`` at the estimate.

        ``odom_pose`` is the odometry pose the estimate refers to. It defaults to the odometry pose
        of the last filter update, which is what the estimate refers to after any update; pass the
        current odometry pose right after ``set_initial_pose`` (before the first update)."""
        ref = odom_pose if odom_pose is not None else self._odom_last
        if ref is None:
            raise NotInitializedError("no odometry pose yet: pass odom_pose or call update() first")
        return Pose2D.from_array(self._mean).compose(ref.inverse())

    def pose_in_map(self, odom_pose: Pose2D) -> Pose2D:
        """The current map pose of ``base_link`` given the current odometry pose: the estimate moved
        by the odometry since the last filter update (what a control loop runs on between updates)."""
        return self.map_to_odom().compose(odom_pose)

    # ------------------------------------------------------------------------- initialisation
    def set_initial_pose(self, pose: Pose2D, cov: np.ndarray) -> None:
        """Reset to ``max_particles`` drawn from N(pose, cov) (Nav2 ``initialPoseReceived``). The next
        ``update`` runs the sensor model without motion and re-anchors odometry."""
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T):
            raise InvalidCovarianceError("initial pose covariance must be a finite symmetric 3x3 matrix")
        evals, evecs = np.linalg.eigh(cov)
        if evals.min() < -1e-12 * max(1.0, float(evals.max())):
            raise InvalidCovarianceError("initial pose covariance is not positive semi-definite")
        if not pose.is_finite():
            raise LocalizationError("initial pose is not finite")
        n = self.options.max_particles
        root = evecs * np.sqrt(np.clip(evals, 0.0, None))
        p = pose.as_array() + self._rng.standard_normal((n, 3)) @ root.T
        p[:, 2] = wrap_angle(p[:, 2])
        self._reset(p)

    def global_localization(self) -> None:
        """Reset to ``global_localization_particles`` poses uniform over the map's free space (Nav2
        service ``reinitialize_global_localization``); the next update's resampling brings the
        count down to at most ``max_particles``."""
        self._reset(self._uniform_free_poses(self.options.global_localization_particles))
        self._expect_fit = True

    def _reset(self, particles: np.ndarray) -> None:
        self._particles = particles
        self._weights = np.full(particles.shape[0], 1.0 / particles.shape[0])
        self._odom_last = None
        self._w_slow = self._w_fast = 0.0
        self._expect_fit = False
        self._injected = 0
        self._updates = 0
        self._set_estimate(self._particles, self._weights)

    def _uniform_free_poses(self, n: int) -> np.ndarray:
        if self._free_xy.shape[0] == 0:
            raise NoFreeSpaceError("the map has no free cell")
        res = self.grid.resolution
        idx = self._rng.integers(0, self._free_xy.shape[0], n)
        out = np.empty((n, 3))
        jitter = self._rng.uniform(-0.5 * res, 0.5 * res, (n, 2))
        # Jitter in the grid's own frame, then rotate into the map frame (grid origin may be rotated).
        c, s = math.cos(self.grid.geometry.origin.theta), math.sin(self.grid.geometry.origin.theta)
        out[:, 0] = self._free_xy[idx, 0] + c * jitter[:, 0] - s * jitter[:, 1]
        out[:, 1] = self._free_xy[idx, 1] + s * jitter[:, 0] + c * jitter[:, 1]
        out[:, 2] = self._rng.uniform(-np.pi, np.pi, n)
        return out

    # ---------------------------------------------------------------------------------- update
    def update(self, odom_pose: Pose2D, scan: LaserScan, laser_pose: Pose2D) -> bool:
        """One AMCL step for ``scan``, taken when odometry read ``odom_pose``; ``laser_pose`` is the
        laser in ``base_link``. Returns True if the filter updated (False: not moved enough)."""
        o = self.options
        if not (odom_pose.is_finite() and laser_pose.is_finite()):
            raise LocalizationError("odometry or laser pose is not finite")
        if self._odom_last is not None:
            prev = self._odom_last
            moved = math.hypot(odom_pose.x - prev.x, odom_pose.y - prev.y)
            turned = abs(float(wrap_angle(odom_pose.theta - prev.theta)))
            if moved < o.update_min_d and turned < o.update_min_a:
                return False
            self._particles = sample_motion(
                o.robot_model_type, self._particles, prev, odom_pose, self._alphas, self._rng
            )
        beams = sm.select_beams(scan, o)
        self._weigh(beams, laser_pose)
        self._updates += 1
        self._injected = 0
        if self._updates % o.resample_interval == 0:
            self._resample()
        else:
            self._set_estimate(self._particles, self._weights)
        self._odom_last = odom_pose
        self._quality = sm.scan_fit(self._field, Pose2D.from_array(self._mean), laser_pose, beams)
        return True

    def log_likelihood(self, particles: np.ndarray, scan: LaserScan, laser_pose: Pose2D) -> np.ndarray:
        """(N,) log measurement likelihoods of arbitrary poses under the configured laser model."""
        return self._log_likelihood(particles, sm.select_beams(scan, self.options), laser_pose)

    def _log_likelihood(self, particles: np.ndarray, beams: sm.Beams, laser_pose: Pose2D) -> np.ndarray:
        o = self.options
        if o.laser_model_type == "likelihood_field":
            return sm.likelihood_field_weights(self._field, particles, laser_pose, beams, o)
        if o.laser_model_type == "likelihood_field_prob":
            w = self._weights if particles is self._particles else None
            return sm.likelihood_field_prob_weights(self._field, particles, laser_pose, beams, o, w)
        if self._caster is not None:
            return sm.beam_model_weights_compiled(self._caster, particles, laser_pose, beams, o)
        assert self._cast_rays is not None
        return sm.beam_model_weights(
            self._occupied, self.grid, self._cast_rays, particles, laser_pose, beams, o
        )

    def _weigh(self, beams: sm.Beams, laser_pose: Pose2D) -> None:
        """Measurement update and the w_slow / w_fast averages (Thrun Table 8.3, lines 4-10)."""
        o = self.options
        logp = self._log_likelihood(self._particles, beams, laser_pose)
        # The robot cannot stand inside a mapped obstacle. Without this prior a particle inside a
        # solid block (e.g. the unseen core of an L-shaped corridor) matches every beam perfectly,
        # since all its endpoints land on occupied cells, and the filter can settle there.
        in_wall = self._in_wall(self._particles)
        if in_wall.any() and not in_wall.all():
            logp = np.where(in_wall, -np.inf, logp)
        logw = np.log(np.maximum(self._weights, 1e-300)) + logp
        total = float(logsumexp(logw))
        self._weights = np.exp(logw - total)
        self._weights /= self._weights.sum()
        # Per-beam geometric mean of the average likelihood: comparable between scans with
        # different numbers of returns, and a ratio w_fast / w_slow that is not raised to the ~60th
        # power (which would turn every small fluctuation into near-total randomisation).
        # Beams that carry information: returns (likelihood field); every beam (beam model).
        n_hit = beams.ranges.size if o.laser_model_type == "beam" else int(np.count_nonzero(beams.hit))
        if n_hit == 0:  # a scan with no returns says nothing about how well the filter fits
            return
        total /= n_hit
        w_avg = math.exp(total) if total < 700.0 else math.inf
        if self._w_slow == 0.0 and self._expect_fit:
            # After a global reset the first scan's average says nothing about how well a
            # localized scan fits: start w_slow near the per-beam likelihood of a good fit, so that
            # settling on a wrong place keeps w_fast / w_slow low and random poses keep coming.
            self._w_slow = _EXPECTED_FIT_FRACTION * (o.z_hit + o.z_rand / beams.range_max)
        elif self._w_slow == 0.0:
            self._w_slow = w_avg
        else:
            self._w_slow += o.recovery_alpha_slow * (w_avg - self._w_slow)
        if self._w_fast == 0.0:
            self._w_fast = w_avg
        else:
            self._w_fast += o.recovery_alpha_fast * (w_avg - self._w_fast)

    def _in_wall(self, particles: np.ndarray) -> np.ndarray:
        """(N,) True where a particle's position is an occupied map cell."""
        rows, cols = self.grid.geometry.world_to_cell(particles[:, :2])
        inside = self.grid.geometry.in_bounds(rows, cols)
        out = np.zeros(particles.shape[0], dtype=bool)
        out[inside] = self._occupied[rows[inside], cols[inside]]
        return out

    def _resample(self) -> None:
        """Low-variance resampling with random-pose injection and a KLD-chosen sample count.

        A fraction ``w_diff = max(0, 1 - w_fast / w_slow)`` of the draws is replaced by uniform poses
        (Thrun Table 8.3, line 13). navdeck draws each such slot as ``f = global_localization_particles
        / max_particles`` uniform poses of weight ``1/f`` each: the same mixture of posterior and
        uniform prior, sampled ``f`` times more densely where it matters (after a kidnapping the true
        pose must be among the random poses); the next update's resampling prunes them again."""
        o = self.options
        w_diff = 0.0
        if self._w_slow > 0.0 and math.isfinite(self._w_slow):
            w_diff = max(0.0, 1.0 - self._w_fast / self._w_slow)
        if w_diff < o.recovery_w_diff_min:
            w_diff = 0.0
        m = o.max_particles
        idx = low_variance_resample(self._weights, m, self._rng)
        new = self._particles[idx]
        new = new[self._rng.permutation(m)]  # random order, so any prefix is a fair subsample
        inject = self._rng.random(m) < w_diff
        n_inject = int(np.count_nonzero(inject))
        if n_inject:
            new[inject] = self._uniform_free_poses(n_inject)
        n = kld_sample_count(
            new, o.pf_err, o.pf_z, o.min_particles, o.max_particles, o.kld_bin_xy, o.kld_bin_theta
        )
        keep, inject = new[:n], inject[:n]
        k = int(np.count_nonzero(inject))
        factor = max(1, o.global_localization_particles // o.max_particles)
        # The estimate is the posterior sample, before the random poses meant for the next cycle.
        self._set_estimate(keep[~inject], np.full(n - k, 1.0 / max(n - k, 1)))
        if k and factor > 1:
            dense = self._uniform_free_poses(k * factor)
            self._particles = np.vstack((keep[~inject], dense))
            weights = np.concatenate((np.ones(n - k), np.full(k * factor, 1.0 / factor)))
            self._weights = weights / weights.sum()
        else:
            self._particles = keep
            self._weights = np.full(n, 1.0 / n)
        self._injected = k * factor

    def _set_estimate(self, particles: np.ndarray, weights: np.ndarray) -> None:
        o = self.options
        if particles.shape[0] == 0:  # every slot was injected: keep the previous estimate
            return
        c = best_cluster(particles, weights, o.kld_bin_xy, o.kld_bin_theta)
        self._mean, self._cov = c.mean, c.cov
