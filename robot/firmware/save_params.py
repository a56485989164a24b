"""``python -m robot.firmware.save_params /dev/ttyUSB0``: make the base's parameters survive a reboot.

PARAM_SET (what ``navdeck calibrate --set-firmware`` sends) changes the values in the base's RAM
only; this sends PARAM_SAVE, which writes every parameter now in effect to flash, and waits for the
base's answer: the save ``navdeck calibrate`` offers (``SerialDriver.save_params``), done later. Run
it with the server stopped (it opens the port exclusively, as the server does).
"""

from __future__ import annotations

import argparse
import sys

from robot.clock import RealClock
from robot.serial.driver import BaseLink, SerialOptions
from robot.serial.port import PortUnavailableError, SerialLinkError
from robot.serial.protocol import ParamValue


def save_parameters(port: str, baud: int = 115200, timeout: float = 1.0) -> ParamValue:
    """Send PARAM_SAVE on ``port`` through the server's own base link (``BaseLink.save_params``) and
    return the base's answer; raise ``SerialLinkError`` (one line) when it refuses or does not answer
    within ``timeout`` s."""
    link = BaseLink(SerialOptions(port, baud=baud), RealClock())
    try:
        return link.save_params(timeout)
    finally:
        link.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m robot.firmware.save_params", description=__doc__.split("\n")[0]
    )
    parser.add_argument("port", help="the base's serial port, e.g. /dev/ttyUSB0")
    parser.add_argument("--baud", type=int, default=115200)
    parser.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for the answer")
    args = parser.parse_args(argv)
    try:
        reply = save_parameters(args.port, args.baud, args.timeout)
    except PortUnavailableError as exc:
        print(exc, file=sys.stderr)
        return 2
    except SerialLinkError as exc:
        print(exc, file=sys.stderr)
        return 1
    print(f"saved {int(reply.value)} parameters to flash on {args.port}: they now survive a reboot")
    return 0


if __name__ == "__main__":
    sys.exit(main())
