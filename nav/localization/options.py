"""Options for Augmented MCL, with Nav2 ``amcl``'s parameter names, units and defaults.

Source: Nav2 ``nav2_amcl`` parameter reference (docs.nav2.org/configuration/packages/configuring-amcl.html).
Where navdeck departs from a Nav2 default the field says so and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

ROBOT_MODEL_TYPES = ("differential", "omnidirectional")
LASER_MODEL_TYPES = ("likelihood_field", "likelihood_field_prob", "beam")


class AmclConfigError(ValueError):
    """An ``AmclOptions`` value is out of range or inconsistent."""


@dataclass(frozen=True)
class AmclOptions:
    """Every tunable of the localizer. Frozen: build a new one with ``dataclasses.replace``."""

    # --- particle filter -------------------------------------------------------------------------
    min_particles: int = 500
    """Lower bound of the KLD-adaptive particle count."""
    max_particles: int = 2000
    """Upper bound of the particle count; also the count after (re)initialisation."""
    pf_err: float = 0.05
    """KLD epsilon: bound on the K-L distance between the sample set and the true posterior."""
    pf_z: float = 0.99
    """Upper standard-normal quantile z_(1-delta) of the KLD bound (Fox 2003, eq. 11). Nav2's
    default 0.99 is used, as in Nav2's ``pf_resample_limit``, directly as the quantile ``z``."""
    resample_interval: int = 1
    """Number of filter updates between resamplings."""
    recovery_alpha_slow: float = 0.001
    """Decay rate of the slow average weight w_slow (Thrun et al. Table 8.3). Nav2's default is 0.0
    (recovery off); navdeck turns it on with the values Probabilistic Robotics / ROS 1 suggest."""
    recovery_alpha_fast: float = 0.1
    """Decay rate of the fast average weight w_fast. Nav2 default 0.0 (off), see above."""
    recovery_w_diff_min: float = 0.2
    """navdeck extension: random poses are injected only while ``1 - w_fast / w_slow`` exceeds this
    dead band. Without it the ordinary jitter of the likelihood while tracking (a few percent)
    injects random poses on every update, as Nav2 does whenever recovery is enabled."""
    global_localization_particles: int = 50000
    """navdeck extension (no Nav2 equivalent): particles drawn uniformly over free space by
    ``global_localization``. The first scan weighs them and resampling cuts them to at most
    ``max_particles``: a sampling-importance-resampling start that covers a whole office densely
    enough (~0.5 m, 10 deg) for the true pose to be sampled, at the cost of one slower update.
    Set it to ``max_particles`` for Nav2's behaviour."""
    kld_bin_xy: float = 0.5
    """Histogram bin size in metres for KLD sampling and clustering (Nav2 pf kd-tree: 0.5 m)."""
    kld_bin_theta: float = math.radians(10.0)
    """Histogram bin size in radians for KLD sampling and clustering (Nav2: 10 deg)."""

    # --- update gating ---------------------------------------------------------------------------
    update_min_d: float = 0.25
    """Translation in metres (odometry) needed before a filter update."""
    update_min_a: float = 0.2
    """Rotation in radians (odometry) needed before a filter update."""

    # --- motion model ----------------------------------------------------------------------------
    robot_model_type: str = "differential"
    """``differential`` (rot1-trans-rot2, Thrun Table 5.6) or ``omnidirectional`` (adds strafe)."""
    alpha1: float = 0.2
    """Expected rotation noise from rotation."""
    alpha2: float = 0.2
    """Expected rotation noise from translation."""
    alpha3: float = 0.2
    """Expected translation noise from translation."""
    alpha4: float = 0.2
    """Expected translation noise from rotation."""
    alpha5: float = 0.2
    """Omnidirectional only: expected strafe (sideways) noise from translation."""

    # --- sensor model ----------------------------------------------------------------------------
    laser_model_type: str = "likelihood_field_prob"
    """``likelihood_field_prob`` (product of beam likelihoods, optional beam skipping),
    ``likelihood_field`` (Nav2's default: ad-hoc ``1 + sum p^3``) or ``beam`` (ray-cast beam model).
    navdeck's default departs from Nav2's: in docs/localization.md the ``likelihood_field``
    combination is too flat to track better than ~10 cm or to localize globally in an office."""
    laser_max_beams: int = 60
    """Number of evenly spaced beams of each scan used in the update."""
    laser_max_range: float = 100.0
    """Maximum range in metres; -1.0 uses the scan's ``range_max``."""
    laser_min_range: float = -1.0
    """Minimum range in metres; -1.0 uses the scan's ``range_min``."""
    laser_likelihood_max_dist: float = 2.0
    """Maximum distance in metres to which the obstacle distance field is computed."""
    z_hit: float = 0.5
    """Mixture weight of the Gaussian hit component."""
    z_short: float = 0.05
    """Mixture weight of the short (unexpected object) component (beam model)."""
    z_max: float = 0.05
    """Mixture weight of the max-range component (beam model)."""
    z_rand: float = 0.5
    """Mixture weight of the uniform random component."""
    sigma_hit: float = 0.2
    """Standard deviation in metres of the hit Gaussian."""
    lambda_short: float = 0.1
    """Exponential decay rate (1/m) of the short component (beam model)."""
    do_beamskip: bool = False
    """``likelihood_field_prob`` only: ignore beams that most particles fail to explain."""
    beam_skip_distance: float = 0.5
    """A beam endpoint this close (m) to an obstacle counts as explained by that particle."""
    beam_skip_threshold: float = 0.3
    """Fraction of particles that must explain a beam for it to be kept."""
    beam_skip_error_threshold: float = 0.9
    """If fewer than this fraction of beams would be kept, keep them all (the filter has lost track)."""

    # --- initial pose ----------------------------------------------------------------------------
    set_initial_pose: bool = False
    """Initialise the filter at ``initial_pose`` on construction (else uniform over free space)."""
    initial_pose_x: float = 0.0
    """Initial x in metres (map frame)."""
    initial_pose_y: float = 0.0
    """Initial y in metres (map frame)."""
    initial_pose_yaw: float = 0.0
    """Initial heading in radians (map frame)."""
    initial_cov_xx: float = 0.5 * 0.5
    """Initial variance of x in m^2 (ROS 1 amcl ``initial_cov_xx``)."""
    initial_cov_yy: float = 0.5 * 0.5
    """Initial variance of y in m^2 (ROS 1 amcl ``initial_cov_yy``)."""
    initial_cov_aa: float = (math.pi / 12.0) ** 2
    """Initial variance of yaw in rad^2 (ROS 1 amcl ``initial_cov_aa``)."""

    def __post_init__(self) -> None:
        if not 0 < self.min_particles <= self.max_particles:
            raise AmclConfigError("need 0 < min_particles <= max_particles")
        if self.robot_model_type not in ROBOT_MODEL_TYPES:
            raise AmclConfigError(f"robot_model_type must be one of {ROBOT_MODEL_TYPES}")
        if self.laser_model_type not in LASER_MODEL_TYPES:
            raise AmclConfigError(f"laser_model_type must be one of {LASER_MODEL_TYPES}")
        if self.laser_max_beams < 2:
            raise AmclConfigError("laser_max_beams must be >= 2")
        if self.global_localization_particles < self.max_particles:
            raise AmclConfigError("global_localization_particles must be >= max_particles")
        if self.resample_interval < 1:
            raise AmclConfigError("resample_interval must be >= 1")
        if not (0.0 < self.pf_err < 1.0 and self.pf_z > 0.0):
            raise AmclConfigError("need 0 < pf_err < 1 and pf_z > 0")
        if self.sigma_hit <= 0.0 or self.laser_likelihood_max_dist <= 0.0:
            raise AmclConfigError("sigma_hit and laser_likelihood_max_dist must be > 0")
        if min(self.alpha1, self.alpha2, self.alpha3, self.alpha4, self.alpha5) < 0.0:
            raise AmclConfigError("alpha1..alpha5 must be >= 0")
        if min(self.z_hit, self.z_short, self.z_max, self.z_rand) < 0.0:
            raise AmclConfigError("z_hit, z_short, z_max, z_rand must be >= 0")
        if not 0.0 <= self.recovery_w_diff_min < 1.0:
            raise AmclConfigError("recovery_w_diff_min must be in [0, 1)")
        if not (0.0 <= self.recovery_alpha_slow <= 1.0 and 0.0 <= self.recovery_alpha_fast <= 1.0):
            raise AmclConfigError("recovery alphas must be in [0, 1]")
        if self.kld_bin_xy <= 0.0 or self.kld_bin_theta <= 0.0:
            raise AmclConfigError("KLD bin sizes must be > 0")

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> AmclOptions:
        """Build from a Nav2-style parameter dict (e.g. a profile's ``[amcl]`` table). Unknown keys
        raise, so a typo in a configuration file is not silently ignored. Nav2's plugin names
        (``nav2_amcl::DifferentialMotionModel``) are accepted for ``robot_model_type``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise AmclConfigError(f"unknown amcl parameter(s): {', '.join(unknown)}")
        v = dict(values)
        rmt = str(v.get("robot_model_type", "differential"))
        if "Omni" in rmt:
            v["robot_model_type"] = "omnidirectional"
        elif "Differential" in rmt:
            v["robot_model_type"] = "differential"
        return cls(**v)
