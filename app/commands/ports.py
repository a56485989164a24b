"""``navdeck ports``: list the serial devices (USB vendor:product, serial number, /dev/serial/by-id
links) and probe each, read-only, for the navdeck base protocol and an RPLidar (``robot.serial.probe``),
so an integrator knows which port to put in ``--robot serial://BASE?lidar=LIDAR``."""

from __future__ import annotations

import argparse
import json

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ports", help="list serial ports and find the base and the lidar (read-only probe, no motion)"
    )
    p.add_argument(
        "paths",
        nargs="*",
        metavar="PATH",
        help="probe these devices only (e.g. a pty: /dev/pts/3); default: every serial device found",
    )
    p.add_argument("--baud", type=int, default=115200, help="baud rate to probe at (base and A1: 115200)")
    p.add_argument("--listen", type=float, default=0.5, help="seconds to listen for base telemetry per port")
    p.add_argument("--no-probe", action="store_true", help="only list the devices, open none")
    p.add_argument("--json", action="store_true", help="one JSON document on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robot.serial.probe import list_devices, probe, report

    if args.baud <= 0 or args.listen <= 0:
        raise CliError("--baud and --listen must be positive")
    devices = list_devices(args.paths or None)
    results = [None if args.no_probe else probe(d.device, args.baud, args.listen) for d in devices]
    rows = [report(d, r) for d, r in zip(devices, results, strict=True)]
    if args.json:
        print(json.dumps({"ports": rows}, indent=2))
        return 0
    if not rows:
        print("no serial devices found (is the USB cable plugged in? see docs/hardware.md)")
        return 0
    for row in rows:
        usb = f"USB {row['vid_pid']}" if row["vid_pid"] else "not USB"
        if row["serial_number"]:
            usb += f" serial {row['serial_number']}"
        desc = f" ({row['description']})" if row["description"] else ""
        print(f"{row['device']}: {usb}{desc}")
        for link in row["by_id"]:
            print(f"    {link}")
        if row["probe"] is not None:
            print(f"    -> {row['probe']['kind']}: {row['probe']['detail']}")
    return 0
