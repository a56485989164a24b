"""Sensor and loop fault detectors run by the session every tick (issue 9 part 3).

Each detector answers "does this fault hold right now?" with a reason, or None. The session turns a
reason into mode FAULT and a zero command in the same tick, and refuses a reset while ``present()``
still names a cause. Everything here is O(beams) numpy per scan or O(1) per tick.

- Lidar garbage: a scan whose beams are mostly invalid (NaN, finite negative, finite beyond twice
  ``range_max``), or that has no valid return at all (e.g. +inf everywhere), is a garbage scan;
  ``lidar_garbage_scans`` of them in a row fault. Isolated bad beams are sanitized to NaN (REP-117
  "invalid") so no consumer sees a negative or absurd range. REP-117's +inf (no return) and -inf (closer
  than ``range_min``, the simulator's and some drivers' convention) are legitimate and kept.
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
    lidar_garbage_scans: int = 3  # consecutive garbage scans -> FAULT (~0.5 s at 5.5 Hz)
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


def classify_scan(scan: LaserScan, garbage_fraction: float) -> tuple[LaserScan, float, bool]:
    """(sanitized scan, fraction of invalid beams, is a garbage scan). Invalid: NaN, finite negative,
    finite beyond twice ``range_max`` (a lidar reads a little past its spec, never 1e6 m); those become
    NaN. +-inf stay (REP-117), but a scan without a single return in range is garbage."""
    r = np.asarray(scan.ranges, dtype=float)
    if r.size == 0:
        return scan, 1.0, True
    finite = np.isfinite(r)
    bad = np.isnan(r) | (finite & ((r < 0.0) | (r > 2.0 * scan.range_max)))
    n_bad = int(np.count_nonzero(bad))
    valid = finite & (r >= scan.range_min) & (r <= scan.range_max)
    frac = n_bad / r.size
    garbage = frac > garbage_fraction or not bool(valid.any())
    if n_bad:
        r = np.where(bad, np.nan, r)
        scan = replace(scan, ranges=r)
    return scan, frac, garbage


class FaultMonitor:
    def __init__(self, period: float, options: FaultMonitorOptions | None = None) -> None:
        self.period = period
        self.options = options or FaultMonitorOptions()
        o = self.options
        self._garbage_run = 0
        self._garbage_frac = 0.0
        self._imu = _Leaky(o.imu_hold_s)
        self._slip = _Leaky(o.slip_hold_s)
        self._imu_now = False  # the imu condition held at the latest tick
        self._rates = (0.0, 0.0)  # (encoder, gyro) yaw rates at the latest tick
        self._late_run = 0
        self._late_periods: deque[float] = deque(maxlen=max(1, o.loop_overrun_ticks))
        self.sanitized_beams = 0  # bad beams turned into NaN in scans that were not garbage

    # ------------------------------------------------------------------ lidar
    def check_scan(self, scan: LaserScan) -> tuple[LaserScan | None, str | None]:
        """(scan to use or None when it is garbage, fault reason when garbage persists)."""
        clean, frac, garbage = classify_scan(scan, self.options.lidar_garbage_fraction)
        if not garbage:
            self._garbage_run = 0
            self.sanitized_beams += round(frac * clean.ranges.size)
            return clean, None
        self._garbage_run += 1
        self._garbage_frac = frac
        return None, self.lidar_reason()

    def lidar_reason(self) -> str | None:
        if self._garbage_run >= self.options.lidar_garbage_scans:
            return (
                f"lidar garbage: {self._garbage_run} scans in a row with "
                f"{self._garbage_frac:.0%} invalid beams"
            )
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
