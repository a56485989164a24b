"""``navdeck emulate base|rplidar``: emulated hardware on pseudo-terminals, driven by the simulator.

``emulate base`` runs the STM32 base *and* an RPLidar A1 on one simulated robot by default (they
must share a world; ``--no-lidar`` for the base alone). ``emulate rplidar`` runs a lidar alone on a
robot that stays at its start pose. Both print the device paths and the ``--robot`` URL, then run
until Ctrl-C (or ``--duration`` seconds). Lines typed on stdin flip fault switches live
(``robot.serial.switches``: unplug, stall, drop/corrupt bytes, lidar health error).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import time

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("emulate", help="emulate the serial base and/or RPLidar on pseudo-terminals")
    p.add_argument("device", choices=("base", "rplidar"), help="base (+ lidar by default) or rplidar alone")
    p.add_argument("--world", default="office", help="stock world (apartment, office, greenhouse) or box")
    p.add_argument("--profile", default="skid4", help="robot profile name or TOML path")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-lidar", action="store_true", help="base only (emulate base)")
    p.add_argument("--link-dir", help="directory for stable device symlinks (default: a new temp dir)")
    p.add_argument(
        "--sample-rate",
        type=float,
        help="lidar samples per second (default: 2000, the A1's, or enough for the profile's beams)",
    )
    p.add_argument("--drop-prob", type=float, default=0.0, help="probability each sent byte is lost")
    p.add_argument("--corrupt-prob", type=float, default=0.0, help="probability each sent byte is garbled")
    p.add_argument("--duration", type=float, help="exit after this many seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robot.profiles import ProfileError, load_profile
    from robot.serial.emulate import EmulatorPair
    from robot.serial.emulate_rplidar import RPLidarEmulator
    from robot.serial.pty import PtyPort
    from robot.serial.simlink import SimPump

    try:
        profile = load_profile(args.profile)
    except ProfileError as exc:
        raise CliError(str(exc)) from exc
    for name in ("drop_prob", "corrupt_prob"):
        if not 0.0 <= getattr(args, name) < 1.0:
            raise CliError(f"--{name.replace('_', '-')} must be in [0, 1)")
    if args.sample_rate is not None and args.sample_rate <= 0:
        raise CliError("--sample-rate must be positive")
    try:
        pump = SimPump.for_world(args.world, profile, seed=args.seed)
    except (KeyError, ValueError, OSError) as exc:  # unknown stock name, unreadable map
        raise CliError(f"cannot load world {args.world!r}: {str(exc).strip(chr(39))}") from exc
    link_dir = args.link_dir
    if args.device == "base":
        dev = EmulatorPair(
            profile, link_dir=link_dir, lidar=not args.no_lidar, sample_rate=args.sample_rate, pump=pump
        )
        emulators = [dev.base] + ([dev.lidar] if dev.lidar is not None else [])
        print(f"base:  {dev.base_path} -> {dev.base.port.slave_name}")
        if dev.lidar is not None:
            print(f"lidar: {dev.lidar_path} -> {dev.lidar.port.slave_name}")
        print(f"robot URL: {dev.url()}", flush=True)
    else:
        from pathlib import Path

        link = Path(link_dir) / "rplidar" if link_dir else None
        lidar = RPLidarEmulator(
            pump, PtyPort(link, name="rplidar"), sample_rate=args.sample_rate, seed=args.seed
        )
        emulators = [lidar]
        dev = None
        print(f"lidar: {lidar.path} -> {lidar.port.slave_name}")
        print(
            "note: this lidar's robot stands still at the start pose; for a lidar that sees the base "
            "drive, run `navdeck emulate base` (it emulates both on one robot)",
            flush=True,
        )
    for e in emulators:
        e.faults.drop_prob = args.drop_prob
        e.faults.corrupt_prob = args.corrupt_prob
    pump.start()
    for e in emulators:
        e.start()
    names = ("base", "lidar") if args.device == "base" else ("lidar",)
    _read_switches(dict(zip(names, emulators, strict=False)))
    previous = _exit_on_sigterm()
    try:
        end = time.monotonic() + args.duration if args.duration else None
        while end is None or time.monotonic() < end:
            time.sleep(0.1)
    finally:
        for e in emulators:
            e.close()  # removes the device links: nothing stale is left for a driver to open
        pump.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


def _exit_on_sigterm() -> signal.Handlers | object | None:
    """``kill`` ends the emulator like Ctrl-C does (through the cleanup); returns the old handler."""

    def handler(signum: int, frame: object) -> None:
        raise SystemExit(0)

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (an embedding caller): leave signals alone
        return None


def _read_switches(devices: dict) -> None:
    """Fault switches typed on stdin, applied as they come (a daemon thread: Ctrl-C still ends)."""
    from robot.serial.switches import HELP, apply_switch

    if sys.stdin is None or not sys.stdin.isatty():
        return  # piped or closed stdin (scripts, tests): no switches
    # a background job (`navdeck emulate base &`) reading the terminal would be stopped by SIGTTIN;
    # ignored, the read fails with EIO instead and only the switches end
    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGTTIN, signal.SIG_IGN)
    try:
        if os.tcgetpgrp(sys.stdin.fileno()) != os.getpgrp():
            return
    except OSError:
        return
    print(HELP, flush=True)

    def loop() -> None:
        try:
            for line in sys.stdin:
                if answer := apply_switch(line, devices):
                    print(answer, flush=True)
        except (OSError, ValueError):
            return

    threading.Thread(target=loop, name="fault-switches", daemon=True).start()
