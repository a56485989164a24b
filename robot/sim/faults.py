"""Fault switches of the simulator: sensor and power failures injected into ``SimDriver`` at run time.

They exist to test what the session, the safety layer and the recovery logic do when hardware
misbehaves (issue 9, part 3): every switch acts where the real fault would, inside the driver, so
everything downstream sees exactly what a faulty base or lidar would send. All switches are off by
default and may be flipped at any moment from any thread (plain attribute writes).

``SimFaults.apply("name=value")`` parses the one-line form used by ``navdeck emulate --fault`` and
by scenario files; ``describe()`` lists the switches that are on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

# What a broken lidar sends: invalid, no-return, negative and absurd ranges (drawn in equal shares).
GARBAGE = np.array([np.nan, np.inf, -1.0, 1e6])


class FaultSpecError(ValueError):
    """A fault specification could not be parsed; the message names the switch and the problem."""


@dataclass
class SimFaults:
    """Mutable fault switches read by ``SimDriver`` every physics substep or scan."""

    lidar_enabled: bool = True
    """False: the lidar stops publishing (no ``scan`` in any frame), like an unplugged or stalled
    RPLidar. The session faults after ``lidar_timeout`` without a scan."""
    lidar_garbage: float = 0.0
    """Fraction (0..1) of the beams of every scan replaced by garbage: NaN, +inf, negative and
    absurdly large ranges in equal shares (a failing sensor or a corrupted serial stream)."""
    slip_wheel: int | None = None
    """Index (profile wheel order) of a wheel whose encoder slips; None: no slip."""
    slip_factor: float = 1.0
    """Ticks counted by ``slip_wheel`` per true wheel rotation (0.5: half the ticks, as a wheel
    spinning on a loose hub or an encoder losing counts; 0: a dead encoder)."""
    gyro_bias_jump: float = 0.0
    """rad/s added to the gyro on top of its normal bias (an MPU6050 after a temperature jump)."""
    battery_sag: float = 0.0
    """Volts subtracted from the battery voltage (a weak cell or a motor stall drawing current)."""
    loop_delay: float = 0.0
    """Seconds every ``read()`` blocks in real time (a stalled USB read, a CPU hog): with a real clock
    the control loop overruns its period. No effect on simulated time."""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ``FaultSpecError`` if a switch holds an impossible value."""
        if not (0.0 <= self.lidar_garbage <= 1.0):
            raise FaultSpecError(f"lidar_garbage must be in [0, 1], got {self.lidar_garbage!r}")
        if not (math.isfinite(self.slip_factor) and self.slip_factor >= 0.0):
            raise FaultSpecError(f"slip_factor must be >= 0, got {self.slip_factor!r}")
        if self.slip_wheel is not None and self.slip_wheel < 0:
            raise FaultSpecError(f"slip_wheel must be a wheel index >= 0, got {self.slip_wheel!r}")
        for name in ("gyro_bias_jump", "battery_sag"):
            if not math.isfinite(getattr(self, name)):
                raise FaultSpecError(f"{name} must be finite, got {getattr(self, name)!r}")
        if not (math.isfinite(self.loop_delay) and 0.0 <= self.loop_delay <= 5.0):
            raise FaultSpecError(f"loop_delay must be in [0, 5] s, got {self.loop_delay!r}")

    def tick_scale(self, wheel_count: int) -> np.ndarray:
        """Per-wheel factor applied to encoder increments (ones when no wheel slips)."""
        scale = np.ones(wheel_count)
        if self.slip_wheel is not None:
            if self.slip_wheel >= wheel_count:
                raise FaultSpecError(f"slip_wheel {self.slip_wheel} but the base has {wheel_count} wheels")
            scale[self.slip_wheel] = self.slip_factor
        return scale

    def corrupt(self, ranges: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Replace ``lidar_garbage`` of the ranges by garbage values (a new array; vectorized)."""
        if self.lidar_garbage <= 0.0:
            return ranges
        out = ranges.copy()
        bad = rng.random(out.shape) < self.lidar_garbage
        out[bad] = GARBAGE[rng.integers(0, GARBAGE.size, int(bad.sum()))]
        return out

    @property
    def active(self) -> bool:
        return bool(self.describe())

    def describe(self) -> list[str]:
        """The switches that are on, as ``name=value`` strings."""
        out = []
        for f in fields(self):
            value = getattr(self, f.name)
            if value != f.default and not (f.name == "slip_factor" and self.slip_wheel is None):
                out.append(f"{f.name}={value}")
        return out

    def clear(self) -> None:
        """Turn every switch off."""
        for f in fields(self):
            setattr(self, f.name, f.default)

    def apply(self, spec: str) -> None:
        """Apply one switch from text: ``lidar_off``, ``lidar_on``, ``lidar_garbage=0.3``,
        ``encoder_slip=WHEEL:FACTOR`` (e.g. ``0:0.5``), ``gyro_bias=0.05``, ``battery_sag=1.5``,
        ``loop_delay=0.12`` (seconds).
        Raises ``FaultSpecError`` naming the switch."""
        name, _, value = spec.strip().partition("=")
        name = name.strip().replace("-", "_")
        try:
            if name in ("lidar_off", "lidar_on") and not value:
                self.lidar_enabled = name == "lidar_on"
            elif name == "lidar_garbage":
                self.lidar_garbage = float(value)
            elif name == "encoder_slip":
                wheel, _, factor = value.partition(":")
                self.slip_wheel, self.slip_factor = int(wheel), float(factor or 0.5)
            elif name in ("gyro_bias", "gyro_bias_jump"):
                self.gyro_bias_jump = float(value)
            elif name == "battery_sag":
                self.battery_sag = float(value)
            elif name == "loop_delay":
                self.loop_delay = float(value)
            else:
                raise FaultSpecError(
                    f"unknown fault {spec!r}: use lidar_off, lidar_garbage=F, encoder_slip=WHEEL:FACTOR, "
                    "gyro_bias=RAD_S, battery_sag=VOLTS or loop_delay=SECONDS"
                )
        except ValueError as exc:
            if isinstance(exc, FaultSpecError):
                raise
            raise FaultSpecError(f"fault {spec!r}: bad value ({exc})") from None
        self.validate()
