"""Fault switches shared by the emulators: lost and corrupted bytes, a stalled sender."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class LineFaults:
    """Mutable switches an emulator consults on every write (tests and the CLI flip them live).

    ``drop_prob``: each outgoing byte is lost with this probability (a noisy UART losing bytes).
    ``corrupt_prob``: each outgoing byte is replaced by a random byte with this probability.
    ``stall``: the device stops sending (a hung MCU task / a lidar with a stuck motor); input is
    still read.
    """

    drop_prob: float = 0.0
    corrupt_prob: float = 0.0
    stall: bool = False
    seed: int = 0
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def apply(self, data: bytes) -> bytes:
        """What actually leaves the device for ``data`` (vectorized over the bytes)."""
        if self.stall:
            return b""
        if self.drop_prob <= 0.0 and self.corrupt_prob <= 0.0:
            return data
        arr = np.frombuffer(data, dtype=np.uint8).copy()
        if self.corrupt_prob > 0.0:
            hit = self.rng.random(arr.size) < self.corrupt_prob
            arr[hit] = self.rng.integers(0, 256, int(hit.sum()), dtype=np.uint8)
        if self.drop_prob > 0.0:
            arr = arr[self.rng.random(arr.size) >= self.drop_prob]
        return arr.tobytes()
