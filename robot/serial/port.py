"""Opening serial ports with one-line typed errors, and a reconnect back-off schedule."""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass

import serial


class SerialLinkError(RuntimeError):
    """Base of the serial driver's errors; the message is one line meant for the operator."""


class PortUnavailableError(SerialLinkError):
    """The port does not exist, is busy or is not accessible."""


def describe_open_error(port: str, exc: BaseException) -> str:
    """A one-line reason why ``port`` could not be opened."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOENT or (not os.path.exists(port) and "No such file" in text):
        return f"serial port {port} not found (is the cable plugged in? see docs/hardware.md)"
    if code == errno.EACCES:
        return f"permission denied on {port} (add your user to the 'dialout' group)"
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "exclusively lock" in text:
        return (
            f"serial port {port} is busy (another program has it open: stop a running"
            " `navdeck serve` or serial monitor first)"
        )
    first = text.splitlines()[0] if text else type(exc).__name__
    return f"cannot open serial port {port}: {first}"


def open_port(port: str, baud: int, timeout: float = 0.02) -> serial.Serial:
    """Open ``port`` exclusively in raw 8N1 mode; raise ``PortUnavailableError`` with a one-line reason."""
    if not os.path.exists(port):
        raise PortUnavailableError(describe_open_error(port, FileNotFoundError(errno.ENOENT, "No such file")))
    try:
        return serial.Serial(port=port, baudrate=baud, timeout=timeout, write_timeout=0.2, exclusive=True)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise PortUnavailableError(describe_open_error(port, exc)) from exc


def describe_crash(thread: str, exc: BaseException) -> str:
    """The one-line fault for a reader thread that died on an unexpected exception: the real cause,
    so the operator is never told a misleading symptom (silence, wrong baud rate) of a dead thread."""
    first = str(exc).splitlines()[0] if str(exc) else ""
    cause = f"{type(exc).__name__}: {first}"
    return f"{thread} stopped on an internal error: {cause} (see the log; restart the server)"


@dataclass
class Backoff:
    """Exponential reconnect delays: ``initial``, doubling up to ``maximum``; ``reset`` on success."""

    initial: float = 0.1
    maximum: float = 2.0
    _next: float = 0.0

    def __post_init__(self) -> None:
        self._next = self.initial

    def next_delay(self) -> float:
        d = self._next
        self._next = min(self._next * 2.0, self.maximum)
        return d

    def reset(self) -> None:
        self._next = self.initial
