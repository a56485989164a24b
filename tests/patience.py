"""Watchdogs long enough that emulator and server threads starved on a loaded machine fault nothing,
for tests about something else than the watchdogs.

Seen on CI and under two busy loops: the in-process emulated lidar silent 1.1 s, the emulated base
1.05 s, and a base's command watchdog fired at 2 s (its firmware maximum). A pulled port still faults
at once, and the tests about the watchdogs themselves keep the real limits.
"""

from __future__ import annotations

from robot.serial.emulate import EmulatorPair
from robot.serial.protocol import ParamId

PATIENT_S = 6.0


def patient_url(pair: EmulatorPair, seconds: float = PATIENT_S) -> str:
    """Set the emulated firmware's command watchdog to ``seconds`` (written into its parameters
    directly: a PARAM_SET over the wire is refused above 2 s, as real firmware would) and return the
    robot URL with the host's link and lidar silence limits at ``seconds`` too."""
    pair.base.params[ParamId.CMD_TIMEOUT] = seconds
    sep = "&" if "?" in pair.url() else "?"
    return f"{pair.url()}{sep}link_timeout={seconds}&lidar_timeout={seconds}"
