"""Live fault switches for ``navdeck emulate``: one-line text commands typed on its stdin.

``unplug|replug|stall|resume [base|lidar]``, ``drop|corrupt P [base|lidar]``, ``health CODE|ok``
(the lidar's GET_HEALTH answer), ``help``. Without a device name a command applies to every
emulated device it makes sense for. Each command answers one line.
"""

from __future__ import annotations

from typing import Protocol

from robot.serial.faults import LineFaults

HELP = (
    "fault switches: unplug|replug|stall|resume [base|lidar]; drop|corrupt P [base|lidar]; "
    "health CODE|ok (lidar); help"
)


class Emulated(Protocol):
    faults: LineFaults

    def unplug(self) -> None: ...

    def replug(self) -> None: ...


def apply_switch(line: str, devices: dict[str, Emulated]) -> str:
    """Apply one command to ``devices`` (``{"base": ..., "lidar": ...}``); returns the answer."""
    words = line.split()
    if not words:
        return ""
    cmd, args = words[0].lower(), words[1:]
    if cmd == "help":
        return HELP
    if cmd == "health":
        lidar = devices.get("lidar")
        if lidar is None or len(args) != 1:
            return "usage: health CODE|ok (needs an emulated lidar)"
        if args[0].lower() == "ok":
            lidar.set_health_error(None)  # type: ignore[attr-defined]
            return "lidar health: ok"
        try:
            code = int(args[0], 0)
        except ValueError:
            return f"health: {args[0]!r} is not a number (e.g. 0x8021)"
        if not 0 <= code <= 0xFFFF:
            return "health: the error code is 16 bits (0..0xffff)"
        lidar.set_health_error(code)  # type: ignore[attr-defined]
        return f"lidar health: error 0x{code:04x} (answered to the next GET_HEALTH)"
    prob = None
    if cmd in ("drop", "corrupt"):
        if not args:
            return f"usage: {cmd} P [base|lidar]"
        try:
            prob = float(args[0])
        except ValueError:
            return f"{cmd}: {args[0]!r} is not a probability"
        if not 0.0 <= prob < 1.0:
            return f"{cmd}: the probability must be in [0, 1)"
        args = args[1:]
    elif cmd not in ("unplug", "replug", "stall", "resume"):
        return f"unknown command {cmd!r}; {HELP}"
    names = args or list(devices)
    unknown = [n for n in names if n not in devices]
    if unknown:
        return f"no emulated device {unknown[0]!r} (have: {', '.join(devices)})"
    for name in names:
        dev = devices[name]
        if cmd == "unplug":
            dev.unplug()
        elif cmd == "replug":
            dev.replug()
        elif cmd in ("stall", "resume"):
            dev.faults.stall = cmd == "stall"
        elif cmd == "drop":
            dev.faults.drop_prob = prob  # type: ignore[assignment]
        else:
            dev.faults.corrupt_prob = prob  # type: ignore[assignment]
    what = f"{cmd} {prob:g}" if prob is not None else cmd
    return f"{what}: {', '.join(names)}"
