"""Sensor and loop fault detectors run by the session every tick (issue 9 part 3).

Each detector answers "does this fault hold right now?" with a reason, or None. The session turns a
reason into mode FAULT and a zero command in the same tick, and refuses a reset while ``present()``
still names a cause. Everything here is O(beams) numpy per scan or O(1) per tick.

- Lidar: every scan is screened and a broken sensor is told apart from an empty scene. A scan with
  no return within range (+inf everywhere: open space, a hall, a field the robot drove out of) is
  valid data, "nothing within range" (REP-117), and passes. A scan is bad when its beams are mostly
  invalid (NaN, finite negative, finite beyond twice ``range_max``), when it has the wrong number of
  beams for the profile's lidar, when every beam reads exactly 0 (a driver sending an empty buffer),
  or when every beam is closer than ``range_min`` (covered sensor); ``lidar_garbage_scans`` bad
  scans in a row fault, naming the kind seen. A frame repeated bit for bit ``lidar_stuck_scans``
  times with returns in it is a stuck sensor (a real lidar's noise never repeats; the driver resends
  a stale buffer). No scan at all is the session's ``lidar: no scan for N s``. Isolated bad beams are
  sanitized to NaN (REP-117 "invalid") so no consumer sees a negative or absurd range; +inf (no
  return) and -inf (closer than ``range_min``) are legitimate and kept.
- Encoder slip vs IMU: the wheels' yaw rate is compared with the gyro's minus its zero-velocity bias
  estimate, both as the odometry measured them for its update. Wheels reporting straight or standing while
  the gyro turns is the gyro's fault ("imu": a bias jump); wheels turning while the gyro does not is a
  wheel's ("encoder slip": a slipping wheel or an encoder losing counts). Either must hold for most of
  a window (a leaky timer) before it faults, so single noisy ticks and brief wheel spin do not.
- Loop overrun: ``loop_overrun_ticks`` consecutive ticks whose start-to-start period exceeds
  ``loop_overrun_factor`` times the nominal period.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from nav.types import LaserScan
from robot.odometry import OdometryState


@dataclass(frozen=True)
class FaultMonitorOptions:
    lidar_garbage_fraction: float = 0.5  # invalid beams above this fraction: a garbage scan
    lidar_garbage_scans: int = 3  # consecutive bad scans -> FAULT (~0.5 s at 5.5 Hz)
    lidar_stuck_scans: int = 25  # the same frame this many times in a row -> FAULT (~4.5 s); 0 disables
    straight_rate: float = 0.05  # rad/s: encoder yaw rate below this counts as straight / standing
    imu_rate: float = 0.10  # rad/s: gyro turning while the wheels do not -> imu suspect
    slip_rate: float = 0.25  # rad/s: encoder vs gyro disagreement -> slip suspect (odometry's threshold)
    imu_hold_s: float = 0.5  # leaky-timer window before an imu fault
    slip_hold_s: float = 1.0  # leaky-timer window before an encoder slip fault
    loop_overrun_ticks: int = 10  # consecutive late ticks -> FAULT; 0 disables
    loop_overrun_factor: float = 2.0  # a tick is late when its period exceeds this x nominal


@dataclass
class _Leaky:
    """Accumulates dt while a condition holds and drains it while not; full at ``hold`` seconds."""

    hold: float
    level: float = 0.0

    def update(self, cond: bool, dt: float) -> bool:
        self.level = min(self.hold, max(0.0, self.level + (dt if cond else -dt)))
        return self.level >= self.hold - 1e-9

    def clear(self) -> None:
        self.level = 0.0


def classify_scan(
    scan: LaserScan, garbage_fraction: float, expected_beams: int | None = None
) -> tuple[LaserScan, float, str | None]:
    """(sanitized scan, fraction of invalid beams, what is wrong with it or None).

    Invalid: NaN, finite negative, finite beyond twice ``range_max`` (a lidar reads a little past
    its spec, never 1e6 m); those become NaN. +-inf stay (REP-117): a scan of +inf only is an empty
    scene, not a fault. The problem, when there is one, names the kind: wrong beam count, all-zero
    frame, mostly invalid beams, or every beam too close."""
    r = np.asarray(scan.ranges, dtype=float)
    if expected_beams is not None and r.size != expected_beams:
        return scan, 1.0, f"wrong beam count ({r.size} beams, the lidar has {expected_beams})"
    if r.size == 0:
        return scan, 1.0, "empty scan (0 beams)"
    if not r.any():  # exactly 0.0 everywhere: no sensor measures 0 m on every beam
        return scan, 1.0, "all-zero frame"
    finite = np.isfinite(r)
    bad = np.isnan(r) | (finite & ((r < 0.0) | (r > 2.0 * scan.range_max)))
    n_bad = int(np.count_nonzero(bad))
    frac = n_bad / r.size
    problem = None
    if frac > garbage_fraction:
        problem = f"{frac:.0%} invalid beams (NaN, negative or beyond 2 x range_max)"
    elif not (r >= scan.range_min).any():  # the rest (most beams) are -inf or below range_min
        problem = "every beam closer than range_min (sensor covered)"
    if n_bad:
        r = np.where(bad, np.nan, r)
        scan = replace(scan, ranges=r)
    return scan, frac, problem


class FaultMonitor:
    def __init__(
        self, period: float, options: FaultMonitorOptions | None = None, expected_beams: int | None = None
    ) -> None:
        """``expected_beams``: the profile lidar's beam count (drivers bin every rotation to it);
        None accepts any count."""
        self.period = period
        self.options = options or FaultMonitorOptions()
        self.expected_beams = expected_beams
        o = self.options
        self._garbage_run = 0
        self._problem = ""
        self._last_ranges = b""  # the previous frame's ranges, raw bytes
        self._stuck_run = 0
        self._imu = _Leaky(o.imu_hold_s)
        self._slip = _Leaky(o.slip_hold_s)
        self._imu_now = False  # the imu condition held at the latest tick
        self._rates = (0.0, 0.0)  # (encoder, gyro) yaw rates at the latest tick
        self._late_run = 0
        self._late_periods: deque[float] = deque(maxlen=max(1, o.loop_overrun_ticks))
        self.sanitized_beams = 0  # bad beams turned into NaN in scans that were not garbage

    # ------------------------------------------------------------------ lidar
    def check_scan(self, scan: LaserScan) -> tuple[LaserScan | None, str | None]:
        """(scan to use or None when it is bad, fault reason when bad scans persist)."""
        o = self.options
        clean, frac, problem = classify_scan(scan, o.lidar_garbage_fraction, self.expected_beams)
        self._track_repeats(scan.ranges)
        if problem is None:
            self._garbage_run = 0
            self.sanitized_beams += round(frac * clean.ranges.size)
            reason = self.lidar_reason()  # a stuck sensor's stale frame is withheld too
            return (None if reason else clean), reason
        self._garbage_run += 1
        self._problem = problem
        return None, self.lidar_reason()

    def _track_repeats(self, ranges: np.ndarray) -> None:
        """Count frames identical to the previous one that hold at least one finite return (an
        empty scene repeats +inf legitimately)."""
        raw = np.ascontiguousarray(ranges, dtype=np.float64).tobytes()  # bit for bit, NaN included
        same = raw == self._last_ranges and bool(np.isfinite(ranges).any())
        self._stuck_run = self._stuck_run + 1 if same else 0
        self._last_ranges = raw

    def lidar_reason(self) -> str | None:
        o = self.options
        if self._garbage_run >= o.lidar_garbage_scans:
            return f"lidar garbage: {self._garbage_run} scans in a row with {self._problem}"
        if o.lidar_stuck_scans > 0 and self._stuck_run + 1 >= o.lidar_stuck_scans:
            return f"lidar stuck: the same frame {self._stuck_run + 1} times in a row"
        return None

    # ------------------------------------------------------------------ wheels vs gyro
    def check_motion(self, odo: OdometryState) -> str | None:
        """Compare the wheels' and the gyro's yaw rates of one odometry update."""
        enc, gyro, dt = odo.encoder_yaw_rate, odo.gyro_yaw_rate, odo.interval
        if enc is None or gyro is None:
            return None
        self._rates = (enc, gyro)
        o = self.options
        self._imu_now = abs(enc) < o.straight_rate and abs(gyro) > o.imu_rate
        slip_now = not self._imu_now and abs(enc - gyro) > o.slip_rate
        imu_full = self._imu.update(self._imu_now, dt)
        slip_full = self._slip.update(slip_now, dt)
        if imu_full:
            return self._imu_reason()
        if slip_full:
            return f"encoder slip: wheels turn at {enc:+.2f} rad/s, gyro at {gyro:+.2f} rad/s"
        return None

    def _imu_reason(self) -> str:
        enc, gyro = self._rates
        return f"imu: gyro turns at {gyro:+.2f} rad/s while the wheels report {enc:+.2f} rad/s"

    # ------------------------------------------------------------------ loop timing
    def check_period(self, measured: float) -> str | None:
        """Feed one start-to-start tick period (s); a reason once enough consecutive ticks ran late."""
        o = self.options
        if o.loop_overrun_ticks <= 0:
            return None
        if measured > o.loop_overrun_factor * self.period:
            self._late_run += 1
            self._late_periods.append(measured)
        else:
            self._late_run = 0
            self._late_periods.clear()
        return self.loop_reason()

    def loop_reason(self) -> str | None:
        if self.options.loop_overrun_ticks > 0 and self._late_run >= self.options.loop_overrun_ticks:
            mean = sum(self._late_periods) / len(self._late_periods)
            return (
                f"loop overrun: {self._late_run} ticks in a row, period {mean * 1e3:.0f} ms "
                f"(nominal {self.period * 1e3:.0f} ms)"
            )
        return None

    # ------------------------------------------------------------------ reset
    def present(self) -> str | None:
        """A monitored cause that still holds (blocks a reset): garbage scans, a gyro turning on a
        standing robot, a loop still overrunning. Slip cannot be judged standing: it re-faults if it
        persists once the robot drives again."""
        if reason := self.lidar_reason():
            return reason
        if self._imu_now:
            return self._imu_reason()
        return self.loop_reason()

    def on_reset(self) -> None:
        """A reset was accepted: start the wheel/gyro windows afresh."""
        self._imu.clear()
        self._slip.clear()
