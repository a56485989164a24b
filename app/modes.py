"""The robot's modes and the one table of transitions between them.

Every mode change goes through ``ModeMachine.request``; a refusal carries the current mode and the
modes allowed from it, which the API turns into 409. E-stop latches: the only way out of ESTOP is an
explicit reset, and FAULT clears only by a reset once its cause is gone.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum


class Mode(StrEnum):
    IDLE = "idle"
    TELEOP = "teleop"
    MAPPING = "mapping"
    LOCALIZING = "localizing"
    NAVIGATING = "navigating"
    RECOVERING = "recovering"
    ESTOP = "estop"
    FAULT = "fault"


# Modes an operator may ask for by name (the others are entered by the system or by dedicated calls).
USER_REQUESTABLE = frozenset({Mode.IDLE, Mode.TELEOP, Mode.MAPPING, Mode.LOCALIZING, Mode.NAVIGATING})

TRANSITIONS: dict[Mode, frozenset[Mode]] = {
    Mode.IDLE: frozenset(
        {Mode.TELEOP, Mode.MAPPING, Mode.LOCALIZING, Mode.NAVIGATING, Mode.ESTOP, Mode.FAULT}
    ),
    Mode.TELEOP: frozenset(
        {Mode.IDLE, Mode.MAPPING, Mode.LOCALIZING, Mode.NAVIGATING, Mode.ESTOP, Mode.FAULT}
    ),
    Mode.MAPPING: frozenset({Mode.IDLE, Mode.TELEOP, Mode.ESTOP, Mode.FAULT}),
    Mode.LOCALIZING: frozenset({Mode.IDLE, Mode.TELEOP, Mode.NAVIGATING, Mode.ESTOP, Mode.FAULT}),
    Mode.NAVIGATING: frozenset(
        {Mode.IDLE, Mode.TELEOP, Mode.LOCALIZING, Mode.RECOVERING, Mode.ESTOP, Mode.FAULT}
    ),
    Mode.RECOVERING: frozenset({Mode.NAVIGATING, Mode.IDLE, Mode.TELEOP, Mode.ESTOP, Mode.FAULT}),
    Mode.ESTOP: frozenset({Mode.IDLE}),  # only through reset
    Mode.FAULT: frozenset({Mode.IDLE, Mode.ESTOP}),  # IDLE only through reset
}

# Transitions that only a specific call may make (not a plain mode request).
RESET_ONLY = frozenset({(Mode.ESTOP, Mode.IDLE), (Mode.FAULT, Mode.IDLE)})

LIDAR_MODES = frozenset({Mode.MAPPING, Mode.LOCALIZING, Mode.NAVIGATING})
"""Modes that need laser scans (SLAM, AMCL, the costmaps' obstacle layer)."""


def no_lidar_reason(what: str) -> str:
    """The refusal for ``what`` (a mode or request) on a robot served without a lidar."""
    return (
        f"this robot has no lidar: {what} needs laser scans"
        " (serve it with serial://BASE?lidar=/dev/LIDAR to map, localize and navigate; teleop works)"
    )


Guard = Callable[[], str | None]  # returns a refusal reason, or None to allow


def driving_hint(mode: Mode) -> str:
    """What an operator does to drive by hand when ``mode`` refuses it (shown with the refusal)."""
    if mode == Mode.ESTOP:
        return "press Reset to release the e-stop, then drive"
    if mode == Mode.FAULT:
        return "remove the fault's cause, press Reset, then drive"
    if mode in (Mode.NAVIGATING, Mode.RECOVERING, Mode.LOCALIZING):
        return f"cancel {mode.value} (Cancel or Idle) to drive by hand"
    return "choose Teleop or Idle, then drive"


@dataclass
class TransitionRefused(Exception):
    current: Mode
    requested: str
    allowed: list[str]
    reason: str

    def __str__(self) -> str:
        return self.reason

    def as_dict(self) -> dict:
        return {
            "detail": self.reason,
            "mode": self.current.value,
            "requested": self.requested,
            "allowed": self.allowed,
        }


class ModeMachine:
    def __init__(self, on_change: Callable[[Mode, Mode, str], None] | None = None) -> None:
        self._mode = Mode.IDLE
        self._lock = threading.RLock()
        self._guards: dict[Mode, Guard] = {}
        self._unavailable: dict[Mode, str] = {}  # modes this robot cannot enter at all, with why
        self._on_change = on_change
        self.reason = ""  # why the current mode was entered (fault text, e-stop source...)

    @property
    def mode(self) -> Mode:
        return self._mode

    def set_guard(self, target: Mode, guard: Guard) -> None:
        """A condition checked before entering ``target`` (e.g. navigation needs localization)."""
        self._guards[target] = guard

    def set_unavailable(self, targets: frozenset[Mode], reason: str) -> None:
        """Modes this robot can never enter (e.g. mapping without a lidar): every request for one is
        refused with ``reason``, and ``allowed`` leaves them out so the dashboard offers none."""
        for target in targets:
            self._unavailable[target] = reason

    def unavailable(self) -> dict[str, str]:
        """``{mode: reason}`` for the modes this robot cannot enter."""
        return {m.value: why for m, why in self._unavailable.items()}

    def allowed(self, mode: Mode | None = None) -> list[str]:
        """Modes an operator may request from ``mode`` (default: the current one)."""
        mode = self._mode if mode is None else mode
        return sorted(
            m.value
            for m in TRANSITIONS[mode]
            if m in USER_REQUESTABLE and (mode, m) not in RESET_ONLY and m not in self._unavailable
        )

    def request(self, target: str | Mode, reason: str = "operator request") -> Mode:
        """An operator's request; raises TransitionRefused."""
        with self._lock:
            try:
                mode = Mode(target)
            except ValueError:
                raise self._refuse(str(target), f"unknown mode {target!r}") from None
            if mode == self._mode:
                return mode
            if mode not in USER_REQUESTABLE:
                raise self._refuse(mode.value, f"mode {mode.value} cannot be requested directly")
            if mode in self._unavailable:
                raise self._refuse(mode.value, self._unavailable[mode])
            if mode not in TRANSITIONS[self._mode] or (self._mode, mode) in RESET_ONLY:
                hint = " (reset first)" if self._mode in (Mode.ESTOP, Mode.FAULT) else ""
                raise self._refuse(mode.value, f"cannot go from {self._mode.value} to {mode.value}{hint}")
            guard = self._guards.get(mode)
            why = guard() if guard else None
            if why:
                raise self._refuse(mode.value, why)
            self._set(mode, reason)
            return mode

    def enter(self, target: Mode, reason: str) -> bool:
        """A system transition (e-stop, fault, navigation finished...). Returns False if not allowed."""
        with self._lock:
            if target == self._mode:
                return True
            if target not in TRANSITIONS[self._mode] or (self._mode, target) in RESET_ONLY:
                return False
            if target in self._unavailable:
                return False
            self._set(target, reason)
            return True

    def reset(self, blocked_by: str | None = None) -> Mode:
        """Leave ESTOP or FAULT for IDLE; ``blocked_by`` names a fault that is still present."""
        with self._lock:
            if self._mode not in (Mode.ESTOP, Mode.FAULT):
                raise self._refuse(
                    "idle",
                    f"nothing to reset in mode {self._mode.value}: Reset releases an e-stop or a fault",
                )
            if blocked_by:
                raise self._refuse("idle", f"cannot reset: {blocked_by}")
            self._set(Mode.IDLE, "reset")
            return self._mode

    def _set(self, mode: Mode, reason: str) -> None:
        old, self._mode, self.reason = self._mode, mode, reason
        if self._on_change:
            self._on_change(old, mode, reason)

    def _refuse(self, requested: str, reason: str) -> TransitionRefused:
        return TransitionRefused(self._mode, requested, self.allowed(), reason)
