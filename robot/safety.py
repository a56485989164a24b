"""The safety layer below every planner: a velocity filter from the close-range sensors.

The analogue of source A's ObstacleTask + IR interrupt (the STM32 stops the motors before the host
reacts) and of Nav2's ``collision_monitor``: whatever the teleop, controller or behaviour asks, the
last word before ``driver.command`` belongs to ``SafetyFilter``. It works on raw sensor data (the
IR sensors and the nearest lidar returns, in base_link), not on the map or the costmap, so it holds
even when localization or mapping has not caught up.

Three zones, as collision_monitor's polygons, all derived from the robot's footprint:

- **stop** (footprint + ``stop_margin``): at least ``min_points`` readings inside block every
  component of the commanded motion *toward* them (the outward normal of the footprint at the
  nearest point). Turning and backing or sliding away stay allowed, so the robot can free itself;
  collision_monitor's stop zeroes everything, which would leave a robot pinned at a wall.
- **slowdown** (footprint + ``slowdown_margin``): readings there that the motion approaches scale
  the whole twist by ``slowdown_ratio``.
- **approach**: the footprint is moved along the commanded twist (exact SE(2) arcs) every
  ``simulation_time_step`` (finer when turning would move a footprint point more than
  ``SWEEP_STEP`` between two poses: the swept footprint of a turn, not just its ends) up to
  ``time_before_collision``; if ``min_points`` readings would have entered it by time t_c
  (counted over the area swept so far: a corner clipping a post or a person holds a sliver of its
  returns at any one pose), the twist is scaled by t_c / time_before_collision so that the
  collision is never nearer than that horizon (collision_monitor's ``approach`` action). A reading
  already inside the footprint counts once the motion takes it ``DEEPEN_TOL`` deeper (the
  simulator's contact rule: leave, never press in).

Readings: the latest lidar scan (a frame often carries none: the lidar runs at 5.5-10 Hz, the loop
at 20 Hz) moved into the current base frame by the filter's own output twists since the scan's stamp
(``base_shift_correction``), plus the IR sensors' returns, each counting as ``min_points`` readings
(a dedicated proximity switch is trusted alone). Invalid ranges (NaN, +-inf, negative, beyond
``range_max``) are ignored: REP-117's ``-inf`` (closer than ``range_min``) cannot be placed; the IR
sensors cover that blind spot in front. A scan older than ``source_timeout``, or one with more than
``max_invalid_fraction`` garbage beams (NaN, negative, absurd), stops the robot; a robot without a
lidar (``lidar=False``, teleop only) is filtered on its IR sensors alone.
Everything per call is a few vectorized numpy operations over the readings near the robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav.types import ZERO_TWIST, Pose2D, Twist2D
from nav.walkers import PERSON_MAX_SPEED, WalkerTracker, scan_clusters
from robot.base import SensorFrame
from robot.kinematics import integrate_twist, se2_exp
from robot.profiles import RobotProfile

SWEEP_STEP = 0.02
"""m; by turning, no footprint point moves farther than this between two simulated poses of the
approach check (a
0.51 x 0.43 m base turning at 1.8 rad/s moves a corner 6 cm per 0.1 s ``simulation_time_step``,
enough to pass a post's few readings between two checked poses)."""

DEEPEN_TOL = 0.001
"""m; a reading already inside the footprint blocks a motion that takes it deeper than this (the
simulator's ``contact_skin`` is 2 mm: a motion it refuses must not be offered as free)."""

EXTENT_SAMPLES = 4096
"""Bearings at which the footprint's radial extent is tabulated for the turn sweep (0.09 deg: the
table's max over a bearing interval overstates the extent by < 0.5 mm at a 0.16 m corner)."""

COMMAND_GAP = 0.25
"""s; a longer pause between calls means the robot was stopped without the filter (see ``_ingest``)."""


class SafetyConfigError(ValueError):
    """Safety options are out of range; the message names the field."""


@dataclass(frozen=True)
class SafetyOptions:
    """Options of ``SafetyFilter`` (names and defaults after Nav2's collision_monitor)."""

    stop_enabled: bool = True
    """Use the stop zone. Default True."""
    stop_margin: float = 0.05
    """m; the stop zone is the footprint padded by this much (collision_monitor's PolygonStop is
    drawn a few cm outside the footprint). Default 0.05."""
    slowdown_enabled: bool = True
    """Use the slow-down zone. Default True."""
    slowdown_margin: float = 0.25
    """m; the slow-down zone is the footprint padded by this much. Default 0.25."""
    slowdown_ratio: float = 0.3
    """Factor applied to the twist when the slow-down zone triggers (collision_monitor default 0.3)."""
    approach_enabled: bool = True
    """Use the time-to-collision check. Default True."""
    time_before_collision: float = 1.2
    """s; the approach horizon: collisions predicted sooner slow the robot (collision_monitor
    default 1.2)."""
    simulation_time_step: float = 0.1
    """s; step of the approach simulation (collision_monitor default 0.1)."""
    min_points: int = 4
    """Readings inside a zone needed to trigger it (collision_monitor ``min_points`` default 4); an
    IR return counts as ``min_points`` by itself."""
    source_timeout: float = 2.0
    """s; a scan older than this is stale and the robot is stopped (collision_monitor default 2.0)."""
    max_invalid_fraction: float = 0.25
    """Largest fraction of a scan's beams that may be garbage (NaN, a finite negative range, or more
    than twice ``range_max``) before the scan is distrusted and the robot stopped; no-return (+inf)
    and too-close (-inf) readings are legitimate (REP-117) and do not count. Default 0.25."""
    ir_timeout: float = 0.5
    """s; an IR reading older than this is dropped (the sensors report at 20 Hz). Default 0.5."""
    use_ir: bool = True
    """Use the IR sensors as an observation source. Default True."""
    base_shift_correction: bool = True
    """Move readings by the robot's motion since they were taken (collision_monitor default True)."""

    def __post_init__(self) -> None:
        for name in ("stop_margin", "slowdown_margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise SafetyConfigError(f"SafetyOptions.{name} must be >= 0 m, got {v!r}")
        if self.slowdown_margin < self.stop_margin:
            raise SafetyConfigError("SafetyOptions.slowdown_margin must be >= stop_margin")
        if not (0.0 <= self.max_invalid_fraction <= 1.0):
            raise SafetyConfigError(
                f"SafetyOptions.max_invalid_fraction must be in [0, 1], got {self.max_invalid_fraction}"
            )
        if not (0.0 <= self.slowdown_ratio <= 1.0):
            raise SafetyConfigError(
                f"SafetyOptions.slowdown_ratio must be in [0, 1], got {self.slowdown_ratio}"
            )
        for name in ("time_before_collision", "simulation_time_step", "source_timeout", "ir_timeout"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise SafetyConfigError(f"SafetyOptions.{name} must be > 0 s, got {v!r}")
        if self.simulation_time_step > self.time_before_collision:
            raise SafetyConfigError("SafetyOptions.simulation_time_step must be <= time_before_collision")
        if int(self.min_points) != self.min_points or self.min_points < 1:
            raise SafetyConfigError(
                f"SafetyOptions.min_points must be an integer >= 1, got {self.min_points}"
            )


@dataclass(frozen=True)
class SafetyStatus:
    """What the filter did on its last call (for telemetry and the recovery policy)."""

    action: str | None  # "stop", "slowdown", "approach" or None
    reason: str | None
    nearest: float  # m from the footprint to the nearest reading (inf if none)
    source: str | None  # "lidar" or "ir<k>"


def _polygon_geometry(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge starts a (E, 2), edge vectors e (E, 2) and 1 / |e|^2 (E,) of a closed polygon."""
    a = np.asarray(poly, dtype=float)
    e = np.roll(a, -1, axis=0) - a
    return a, e, 1.0 / np.maximum((e * e).sum(axis=1), 1e-18)


def _inside(points: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon for (..., 2) points (any leading shape)."""
    px, py = points[..., 0:1], points[..., 1:2]
    y0, y1 = a[:, 1], a[:, 1] + e[:, 1]
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[:, 0] + (py - y0) * e[:, 0] / e[:, 1]
    return np.count_nonzero(straddle & (px < x_cross), axis=-1) % 2 == 1


def _boundary_distance(points: np.ndarray, a: np.ndarray, e: np.ndarray, inv: np.ndarray):
    """Distance (N,) from (N, 2) points to the polygon's boundary and the nearest boundary points."""
    d = points[:, None, :] - a[None, :, :]
    t = np.clip((d * e[None]).sum(axis=2) * inv[None], 0.0, 1.0)
    closest = a[None] + t[..., None] * e[None]
    dist2 = ((points[:, None, :] - closest) ** 2).sum(axis=2)
    k = dist2.argmin(axis=1)
    rows = np.arange(points.shape[0])
    return np.sqrt(dist2[rows, k]), closest[rows, k]


def _radial_extent(a: np.ndarray, e: np.ndarray, samples: int) -> np.ndarray:
    """(samples,): the polygon's farthest boundary point from base_link along each of ``samples``
    bearings 2 pi k / samples (0 where a ray meets no edge). A turn in place sweeps a reading at
    (rho, phi) iff the extent at some bearing the reading passes through is >= rho."""
    psi = 2.0 * math.pi * np.arange(samples) / samples
    ux, uy = np.cos(psi)[:, None], np.sin(psi)[:, None]
    det = uy * e[None, :, 0] - ux * e[None, :, 1]  # ray s * u meets edge a + t * e
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (a[None, :, 1] * e[None, :, 0] - a[None, :, 0] * e[None, :, 1]) / det
        t = (ux * a[None, :, 1] - uy * a[None, :, 0]) / det
    ok = (np.abs(det) > 1e-12) & (t >= 0.0) & (t <= 1.0) & (s > 0.0)
    return np.where(ok, s, 0.0).max(axis=1)


def _into_frames(th: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """(K, N, 2): the (K, N) offsets ``dx``, ``dy`` from K poses rotated into those poses' frames
    (headings ``th``, (K,))."""
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    return np.stack((c * dx + s * dy, -s * dx + c * dy), axis=-1)


class SafetyFilter:
    """``filter(cmd, frame) -> (cmd', reason | None)``: the session's ``safety`` hook."""

    def __init__(
        self, profile: RobotProfile, options: SafetyOptions | None = None, lidar: bool = True
    ) -> None:
        self.profile = profile
        self.options = options or SafetyOptions()
        # False: a base served without a lidar (teleop only): no scan is expected, so its absence does
        # not stop the robot; the IR sensors (and the base's own obstacle stop) are the readings left.
        self.lidar = lidar
        o = self.options
        self._a, self._e, self._inv = _polygon_geometry(profile.footprint_polygon(32))
        self._reach_fp = float(np.max(np.hypot(self._a[:, 0], self._a[:, 1])))
        self._extent = _radial_extent(self._a, self._e, EXTENT_SAMPLES)
        self._extent_max: dict[int, np.ndarray] = {}  # window (samples) -> max extent from each bearing
        # a round robot (no footprint polygon): exact circle tests, K x N instead of K x N x edges
        self._circle = profile.robot_radius if not profile.footprint and profile.robot_radius > 0 else None
        lim = profile.limits
        vmax = max(abs(lim.max_vel_x), abs(lim.min_vel_x), abs(lim.max_vel_y) if profile.is_omni else 0.0)
        # no reading farther than this from base_link can matter within the approach horizon
        self._reach = self._reach_fp + max(o.slowdown_margin, vmax * o.time_before_collision) + 0.05
        self._turn_reach = self._reach_fp + o.slowdown_margin
        spec = profile.lidar
        self._mount = Pose2D(spec.mount_x, spec.mount_y, spec.mount_yaw)
        # ranges kept from a scan: also what the robot may drive into reach before the next scan
        # (0.5 s: scans come at 2 Hz or faster)
        self._scan_reach = self._reach + vmax * 0.5 + math.hypot(spec.mount_x, spec.mount_y)
        ir = profile.ir
        self._ir_xy = np.array([[s.x, s.y] for s in ir], dtype=float).reshape(-1, 2)
        self._ir_dir = np.array([[math.cos(s.yaw), math.sin(s.yaw)] for s in ir], dtype=float).reshape(-1, 2)
        self._ir_range = np.array([s.range for s in ir], dtype=float)
        # state between frames
        # the latest scan's readings (base_link at the scan's stamp) and each one's predicted velocity
        # (same frame), swapped as one tuple: the telemetry thread reads them while a reflex command
        # from the teleop thread may be ingesting a new scan
        # and whether each belongs to a solid object (see ``_solid``)
        self._scan_readings: tuple[np.ndarray, np.ndarray, np.ndarray] = (
            np.zeros((0, 2)),
            np.zeros((0, 2)),
            np.zeros(0, dtype=bool),
        )
        # walkers between scans (base frame at each scan's stamp)
        self.walkers = WalkerTracker()
        # walkers are followed this far: within the approach horizon they can reach the footprint
        self._track_reach = self._reach + PERSON_MAX_SPEED * o.time_before_collision
        self._scan_stamp = -math.inf
        self._scan_shift = Pose2D()  # base at scan time -> base now
        self._garbage = 0.0  # fraction of garbage beams in the latest scan
        # triggered IR readings (base frame) and the sensor index of each, one tuple like the scan's
        self._ir_readings: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 2)), np.zeros(0, dtype=np.intp))
        self._ir_stamp = -math.inf
        self._ir_shift = Pose2D()
        self._last_stamp: float | None = None
        self._last_out = ZERO_TWIST
        self.status = SafetyStatus(None, None, math.inf, None)

    # ---------------------------------------------------------------------------------- inputs
    def _ingest(self, frame: SensorFrame) -> None:
        o = self.options
        now = frame.stamp
        if self._last_stamp is not None and now - self._last_stamp > COMMAND_GAP:
            # the session skips the filter only while it stops the robot (e-stop, fault): after such
            # a gap the robot stands, and the last output must not be integrated as phantom motion
            self._last_out = ZERO_TWIST
        if self._last_stamp is not None and o.base_shift_correction:
            dt = now - self._last_stamp
            if dt > 0 and not self._last_out.is_zero():
                step = integrate_twist(Pose2D(), self._last_out, dt)
                self._scan_shift = self._scan_shift.compose(step)
                self._ir_shift = self._ir_shift.compose(step)
        self._last_stamp = now
        scan = frame.scan
        if scan is not None:
            r = np.asarray(scan.ranges, dtype=float)
            finite = np.isfinite(r)
            with np.errstate(invalid="ignore"):
                garbage = np.isnan(r) | (finite & ((r < 0.0) | (r > 2.0 * scan.range_max)))
                ok = finite & (r >= scan.range_min) & (r <= scan.range_max)
            self._garbage = float(garbage.mean()) if r.size else 0.0
            ok &= r <= max(self._scan_reach, self._track_reach)
            ang = scan.angles[ok]
            pts = np.column_stack((r[ok] * np.cos(ang), r[ok] * np.sin(ang)))
            pts = self._mount.transform_points(pts) if pts.size else np.zeros((0, 2))
            vel = self.walkers.update(pts, scan.stamp, self._scan_shift.inverse())
            solid = self._solid(pts)
            keep = (np.hypot(pts[:, 0], pts[:, 1]) <= self._scan_reach) | vel.any(axis=1)
            self._scan_readings = (pts[keep], vel[keep], solid[keep])
            self._scan_stamp = scan.stamp
            self._scan_shift = Pose2D()
            lag = now - scan.stamp
            if o.base_shift_correction and lag > 0 and not self._last_out.is_zero():
                self._scan_shift = integrate_twist(Pose2D(), self._last_out, lag)
        ir = frame.ir
        if o.use_ir and ir is not None and self._ir_xy.shape[0]:
            trig = np.asarray(ir.triggered, dtype=bool)
            rng = np.asarray(ir.ranges, dtype=float)
            rng = np.where(np.isfinite(rng), rng, self._ir_range)  # a digital switch: at its range
            k = np.flatnonzero(trig)
            self._ir_readings = (self._ir_xy[k] + self._ir_dir[k] * rng[k, None], k)
            self._ir_stamp = ir.stamp
            self._ir_shift = Pose2D()

    def _solid(self, pts: np.ndarray) -> np.ndarray:
        """Per return (scan order): whether it is one of >= ``min_points`` consecutive returns less
        than ``CLUSTER_GAP`` apart, i.e. of an object the scan really saw, not a stray return."""
        if pts.shape[0] == 0:
            return np.zeros(0, dtype=bool)
        label = scan_clusters(pts)
        return np.bincount(label)[label] >= self.options.min_points

    def _approach_weights(self, w: np.ndarray, solid: np.ndarray) -> np.ndarray:
        """The approach check's weights: a return of a solid object counts ``min_points`` alone. A
        corner swept into an object meets its returns one by one, so counting ``min_points`` of
        them let it in by several millimetres (a walker clipped so, greenhouse TEB trial 6); the
        noise filter stays for stray returns."""
        return np.where(solid, float(self.options.min_points), w)

    def _readings(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Readings in the current base frame near the robot: points (N, 2), weights (N,), source
        index (N,: -1 lidar, k >= 0 IR sensor k), predicted velocities (N, 2) and whether each is of
        a solid object (N,), with each walker's readings moved on to ``now``."""
        parts, weights, srcs, vels, solids = [], [], [], [], []
        scan_pts, scan_vel, scan_solid = self._scan_readings
        if scan_pts.shape[0]:
            back = self._scan_shift.inverse()
            c, s = math.cos(back.theta), math.sin(back.theta)
            vel = scan_vel @ np.array([[c, s], [-s, c]])
            pts = back.transform_points(scan_pts) + vel * max(now - self._scan_stamp, 0.0)
            parts.append(pts)
            weights.append(np.ones(pts.shape[0]))
            srcs.append(np.full(pts.shape[0], -1))
            vels.append(vel)
            solids.append(scan_solid)
        ir_pts, ir_src = self._ir_readings
        if ir_pts.shape[0] and now - self._ir_stamp <= self.options.ir_timeout:
            parts.append(self._ir_shift.inverse().transform_points(ir_pts))
            weights.append(np.full(ir_pts.shape[0], float(self.options.min_points)))
            srcs.append(ir_src)
            vels.append(np.zeros((ir_pts.shape[0], 2)))
            solids.append(np.ones(ir_pts.shape[0], dtype=bool))  # weighs min_points already
        if not parts:
            empty = np.zeros(0)
            return np.zeros((0, 2)), empty, empty.astype(np.intp), np.zeros((0, 2)), empty.astype(bool)
        pts, vel = np.concatenate(parts), np.concatenate(vels)
        speed = np.hypot(vel[:, 0], vel[:, 1])
        near = np.hypot(pts[:, 0], pts[:, 1]) <= self._reach + speed * self.options.time_before_collision
        w, src, solid = np.concatenate(weights), np.concatenate(srcs), np.concatenate(solids)
        return pts[near], w[near], src[near], vel[near], solid[near]

    # ---------------------------------------------------------------------------------- filter
    def __call__(self, cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, str | None]:
        out, reason = self._filter(cmd, frame)
        self._last_out = out
        return out, reason

    def _name(self, src: int) -> str:
        return "lidar" if src < 0 else f"IR {src}"

    def _filter(self, cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, str | None]:
        o = self.options
        self._ingest(frame)
        now = frame.stamp
        age = now - self._scan_stamp
        if self.lidar and age > o.source_timeout:
            if cmd.is_zero():
                self.status = SafetyStatus(None, None, math.inf, None)
                return cmd, None
            what = "no lidar scan yet" if not math.isfinite(age) else f"lidar scan {age:.1f} s old"
            self.status = SafetyStatus("stop", f"stop: {what}", math.inf, "lidar")
            return ZERO_TWIST, self.status.reason
        if self._garbage > o.max_invalid_fraction and not cmd.is_zero():
            what = f"lidar returns garbage ({self._garbage:.0%} of beams invalid)"
            self.status = SafetyStatus("stop", f"stop: {what}", math.inf, "lidar")
            return ZERO_TWIST, self.status.reason
        pts, w, src, vel, solid = self._readings(now)
        if cmd.is_zero() or pts.shape[0] == 0:
            self.status = SafetyStatus(None, None, math.inf, None)
            return cmd, None
        inside, dist, normal = self._placement(pts)
        i_near = int(dist.argmin())
        nearest, near_src = float(dist[i_near]), self._name(int(src[i_near]))
        v = np.array([cmd.vx, cmd.vy])
        action, reason = None, None

        if o.stop_enabled:
            zone = dist <= o.stop_margin
            if w[zone].sum() >= o.min_points:
                v_new = self._block(v, pts[zone], w[zone], normal[zone])
                if not np.array_equal(v_new, v):
                    j = np.flatnonzero(zone)[dist[zone].argmin()]
                    action = "stop"
                    reason = f"stop: {self._name(int(src[j]))} obstacle {dist[j]:.2f} m from the footprint"
                    v = v_new
        twist = Twist2D(float(v[0]), float(v[1]), cmd.wz)
        if twist.is_zero():
            self.status = SafetyStatus(action, reason, nearest, near_src)
            return ZERO_TWIST, reason

        if o.slowdown_enabled and action is None and v.any():
            zone = (dist <= o.slowdown_margin) & self._in_path(v, pts)
            if w[zone].sum() >= o.min_points:
                j = np.flatnonzero(zone)[dist[zone].argmin()]
                r = o.slowdown_ratio
                twist = Twist2D(twist.vx * r, twist.vy * r, twist.wz * r)
                action = "slowdown"
                reason = f"slowdown: {self._name(int(src[j]))} obstacle {dist[j]:.2f} m from the footprint"

        if o.approach_enabled:
            t_c, j = self._time_to_collision(twist, pts, self._approach_weights(w, solid), inside, vel)
            if t_c is not None and t_c < o.time_before_collision:
                ratio = t_c / o.time_before_collision
                twist = Twist2D(twist.vx * ratio, twist.vy * ratio, twist.wz * ratio)
                action = "approach" if action is None else action
                reason = (
                    f"approach: collision in {t_c:.1f} s with {self._name(int(src[j]))} obstacle "
                    f"{dist[j]:.2f} m from the footprint" + (f" ({reason})" if reason else "")
                )
        self.status = SafetyStatus(action, reason, nearest, near_src)
        return twist, reason

    def _turn_sweeps(self, before: np.ndarray, turn: float) -> np.ndarray:
        """(K, N): whether turning by ``turn`` rad from each checked pose sweeps the footprint over
        each reading (``before``: (K, N, 2), the readings in the frame of the pose before each step).
        Between two checked poses a corner moves up to ``SWEEP_STEP`` along its arc: a reading a
        millimetre inside that arc is inside neither pose's footprint (a walker standing just
        within the corners' circle was clipped so, greenhouse TEB trial 6), but the footprint's
        radial extent over the bearings the reading passes through reaches it."""
        n = EXTENT_SAMPLES
        step = 2.0 * math.pi / n
        window = math.ceil(abs(turn) / step) + 2
        table = self._extent_max.get(window)
        if table is None:
            wrapped = np.concatenate((self._extent, self._extent[: window - 1]))
            table = np.lib.stride_tricks.sliding_window_view(wrapped, window).max(axis=1)
            self._extent_max[window] = table
        rho = np.hypot(before[..., 0], before[..., 1])
        # turning by `turn` moves a reading's bearing in the body frame by -turn
        low = np.arctan2(before[..., 1], before[..., 0]) - max(turn, 0.0)
        first = np.floor(low / step).astype(np.int64) % n
        return table[first] >= rho

    FREE_PROBES = (
        ("forward", 1.0, 0.0),
        ("back", -1.0, 0.0),
        ("turn left", 0.0, 1.0),
        ("turn right", 0.0, -1.0),
    )
    """(name, vx sign, wz sign) of the motions :meth:`free_motions` probes."""

    def nearest_reading(self, now: float) -> float:
        """Distance (m) from the footprint to the nearest of the latest readings (0 inside it, inf
        with none near), whatever the last command was."""
        pts = self._readings(now)[0]
        if pts.shape[0] == 0:
            return math.inf
        _, dist, _ = self._placement(pts)
        return float(dist.min())

    def free_motions(self, now: float, distance: float = 0.05) -> dict[str, bool]:
        """Per elementary motion (forward, back, turn left, turn right): whether the latest readings
        leave room for it: the moved footprint takes in no reading within ``distance`` metres of
        travel (a turn: the same arc length at the footprint's farthest point). What the dashboard
        tells an operator whose robot is in contact."""
        pts, w, _, vel, solid = self._readings(now)
        if pts.shape[0] == 0:
            return {name: True for name, _, _ in self.FREE_PROBES}
        out = {}
        inside, _, _ = self._placement(pts)
        horizon = self.options.time_before_collision
        for name, sv, sw in self.FREE_PROBES:
            v = distance / horizon
            twist = Twist2D(sv * v, 0.0, sw * v / max(self._reach_fp, 1e-3))
            t_c, _ = self._time_to_collision(twist, pts, self._approach_weights(w, solid), inside, vel)
            out[name] = t_c is None
        return out

    def _placement(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per reading (N, 2, base frame): whether it is inside the footprint, its distance (m) from
        the outline (0 inside) and the unit outward direction from the footprint to it (from
        base_link when inside)."""
        if self._circle is not None:
            rad = np.hypot(pts[:, 0], pts[:, 1])
            normal = pts / np.maximum(rad, 1e-9)[:, None]
            return rad <= self._circle, np.maximum(rad - self._circle, 0.0), normal
        inside = _inside(pts, self._a, self._e)
        dist, closest = _boundary_distance(pts, self._a, self._e, self._inv)
        normal = np.where(inside[:, None], pts, pts - closest)
        normal /= np.maximum(np.hypot(normal[:, 0], normal[:, 1]), 1e-9)[:, None]
        return inside, np.where(inside, 0.0, dist), normal

    def _in_path(self, v: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """Per reading: whether a straight translation along ``v`` sweeps the footprint into it (it
        lies ahead, within the band the footprint covers across the direction of motion). A wall
        alongside is not in the path, so driving or sliding along it is never blocked."""
        speed = math.hypot(v[0], v[1])
        if speed < 1e-9:
            return np.zeros(pts.shape[0], dtype=bool)
        u = v / speed
        perp = np.array([-u[1], u[0]])
        lat = pts @ perp
        span = self._a @ perp  # footprint vertices across the motion
        return (pts @ u > 0.0) & (lat >= span.min() - 1e-9) & (lat <= span.max() + 1e-9)

    def _block(self, v: np.ndarray, pts: np.ndarray, w: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Remove the motion toward the stop-zone readings ``pts``: unchanged when none is in the
        path; for omni bases, slide along the obstacle (``v`` minus its component along the nearest
        blocking reading's outward normal) when that clears the path and keeps at least a quarter
        of the speed (pushing head-on into a wall must not turn into a sideways drift); else no
        translation."""
        mp = self.options.min_points
        hit = self._in_path(v, pts)
        if w[hit].sum() < mp:
            return v
        if self.profile.is_omni:
            d = np.hypot(pts[hit, 0], pts[hit, 1])
            n = normals[hit][int(d.argmin())]
            along = n @ v
            if along > 0:
                v2 = v - along * n
                if np.hypot(*v2) >= 0.25 * np.hypot(*v) and w[self._in_path(v2, pts)].sum() < mp:
                    return v2
        return np.zeros(2)

    def _time_to_collision(
        self,
        twist: Twist2D,
        pts: np.ndarray,
        w: np.ndarray,
        inside_now: np.ndarray,
        vel: np.ndarray,
    ) -> tuple[float | None, int]:
        """First simulated time by which >= min_points readings have fallen inside the moved
        footprint (the area it swept since now; walkers' readings move on at their predicted velocity
        ``vel``), and the index of one inside it then. A reading already inside counts only once
        the motion takes it deeper than now by more than ``DEEPEN_TOL``, the simulator's rule for a
        body in contact: a turn or a backing away that frees the footprint passes, one that presses
        a touching leg in does not."""
        o = self.options
        speed = math.hypot(twist.vx, twist.vy)
        reach = self._reach_fp + speed * o.time_before_collision + 1e-6
        r = np.hypot(pts[:, 0], pts[:, 1]) - np.hypot(vel[:, 0], vel[:, 1]) * o.time_before_collision
        cand = r <= (reach if speed > 0 else self._turn_reach)
        if w[cand].sum() < o.min_points:
            return None, -1
        p, wc, pv = pts[cand], w[cand], vel[cand]
        # the turn moves the footprint's corners (a circle does not change by turning)
        sweep = abs(twist.wz) * (0.0 if self._circle is not None else self._reach_fp)
        dt = o.simulation_time_step
        if sweep * dt > SWEEP_STEP:
            dt = SWEEP_STEP / sweep
        t = np.arange(1, math.ceil(o.time_before_collision / dt - 1e-9) + 1) * dt
        ex, ey, th = se2_exp(twist.vx * t, twist.vy * t, twist.wz * t)  # future poses in base now
        px = p[None, :, 0] + pv[None, :, 0] * t[:, None]  # (K, N) readings at time t
        py = p[None, :, 1] + pv[None, :, 1] * t[:, None]
        dx, dy = px - ex[:, None], py - ey[:, None]
        if self._circle is not None:  # rotation does not move a circle
            hit = dx * dx + dy * dy <= self._circle**2  # (K, N)
        else:
            frames = _into_frames(th, dx, dy)  # (K, N, 2)
            hit = _inside(frames, self._a, self._e)  # (K, N)
            if twist.wz != 0.0:
                hit |= self._turn_sweeps(np.concatenate((p[None], frames[:-1])), twist.wz * dt)
        was_in = inside_now[cand]
        if was_in.any():
            # depth of the readings inside now, at rest and along the robot's motion (their own
            # predicted motion left out: a walker stepping in must not pin the robot)
            q = p[was_in]
            qx, qy = q[None, :, 0] - ex[:, None], q[None, :, 1] - ey[:, None]
            if self._circle is not None:
                deeper = (
                    self._circle - np.hypot(qx, qy) > self._circle - np.hypot(q[:, 0], q[:, 1]) + DEEPEN_TOL
                )
            else:
                moved = _into_frames(th, qx, qy)
                depth0, _ = _boundary_distance(q, self._a, self._e, self._inv)
                depth, _ = _boundary_distance(moved.reshape(-1, 2), self._a, self._e, self._inv)
                inside = _inside(moved, self._a, self._e)
                deeper = inside & (depth.reshape(inside.shape) > depth0[None, :] + DEEPEN_TOL)
            hit[:, was_in] = deeper
        # the readings the footprint has swept over so far, not those inside it at one pose: a corner
        # clipping a person or a post overlaps it by a sliver holding one or two returns at any
        # single pose, never min_points, yet the sweep passes through many of them
        swept = np.logical_or.accumulate(hit, axis=0)
        count = (swept * wc[None, :]).sum(axis=1)
        k = np.flatnonzero(count >= o.min_points)
        if k.size == 0:
            return None, -1
        first = int(k[0])
        j = np.flatnonzero(cand)[int(np.argmax(hit[first]))]
        return float(t[first]), int(j)
