"""Find the robot's serial ports: list the serial devices and tell, read-only, which one is the base
(navdeck serial protocol) and which the RPLidar (``navdeck ports``, docs/hardware.md).

Probing never makes anything move. Per port, in this order:

1. listen for ``listen`` s: a base streams ``Telemetry`` by itself (nothing is sent);
2. RPLidar ``GET_HEALTH`` and ``GET_INFO`` (``A5 52`` / ``A5 50``): answers, no SCAN; DTR is held
   asserted, also after the close, which on the A1's USB adapter keeps the motor stopped;
3. a base ``PARAM_GET`` (a read of one parameter) for a base that is silent until spoken to.

A base's COBS decoder drops the lidar requests as one bad frame (ended by a 0x00 sent before the
PARAM_GET); the ``PARAM_GET`` frame is checked
not to contain an RPLidar SCAN / FORCE_SCAN / RESET request (``A5 20`` / ``A5 21`` / ``A5 40``), so a
lidar cannot read it as one.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import serial
from serial.tools import list_ports

from robot.serial.port import PortUnavailableError, open_port
from robot.serial.protocol import MessageDecoder, ParamGet, ParamId, ParamValue, Telemetry, encode
from robot.serial.rplidar import (
    Cmd,
    DeviceInfo,
    Health,
    HealthStatus,
    StreamParser,
    hold_dtr_after_close,
    request,
    set_motor,
)

BY_ID_DIR = Path("/dev/serial/by-id")
LIDAR_MOTION_REQUESTS = (Cmd.SCAN, Cmd.FORCE_SCAN, Cmd.RESET)


@dataclass
class SerialDevice:
    """One serial device: where it is and what USB says about it (None off USB, e.g. a pty)."""

    device: str
    vid_pid: str | None = None  # "10c4:ea60"
    serial_number: str | None = None
    description: str | None = None
    by_id: list[str] = field(default_factory=list)  # /dev/serial/by-id links to it


@dataclass
class ProbeResult:
    """What answered on a port: ``kind`` is "base", "rplidar", "unknown" or "unavailable"."""

    kind: str
    detail: str


def by_id_links(by_id_dir: Path | None = None) -> dict[str, list[str]]:
    """``{/dev/ttyUSB0: [/dev/serial/by-id/usb-Silicon_Labs_CP2102_...-port0]}``: udev's stable names."""
    by_id_dir = BY_ID_DIR if by_id_dir is None else by_id_dir
    links: dict[str, list[str]] = {}
    if not by_id_dir.is_dir():
        return links
    for link in sorted(by_id_dir.iterdir()):
        links.setdefault(os.path.realpath(link), []).append(str(link))
    return links


def list_devices(paths: list[str] | None = None) -> list[SerialDevice]:
    """The serial devices pyserial finds, or exactly ``paths`` (a pty or a by-id link; its USB data
    are filled in when pyserial knows the device it resolves to)."""
    links = by_id_links()
    known = {os.path.realpath(p.device): p for p in list_ports.comports()}
    wanted = [os.path.realpath(p) for p in paths] if paths else sorted(known)
    shown = list(paths) if paths else wanted
    out = []
    for name, real in zip(shown, wanted, strict=True):
        info = known.get(real)
        vid_pid = f"{info.vid:04x}:{info.pid:04x}" if info is not None and info.vid is not None else None
        desc = info.description if info is not None and info.description not in (None, "n/a") else None
        out.append(
            SerialDevice(name, vid_pid, info.serial_number if info else None, desc, links.get(real, []))
        )
    return out


def _param_get_frame() -> bytes:
    """A PARAM_GET frame that holds no RPLidar request able to start its motor or a scan."""
    for seq in range(256):
        frame = encode(ParamGet(int(ParamId.TELEMETRY_RATE)), seq)
        if not any(request(c) in frame for c in LIDAR_MOTION_REQUESTS):
            return frame
    raise RuntimeError("no safe PARAM_GET frame")  # unreachable: the sequence byte changes the CRC


def _read_for(
    ser: serial.Serial, seconds: float, feed: Callable[[bytes], object], done: Callable[[], bool]
) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not done():
        data = ser.read(max(1, ser.in_waiting))
        if data:
            feed(data)


def _listen_base(ser: serial.Serial, listen: float) -> ProbeResult | None:
    decoder = MessageDecoder()
    telemetry: list[Telemetry] = []
    t0 = time.monotonic()
    _read_for(
        ser,
        listen,
        lambda d: telemetry.extend(m for m in decoder.feed(d) if isinstance(m, Telemetry)),
        lambda: len(telemetry) >= 10,
    )
    if not telemetry:
        return None
    rate = len(telemetry) / max(time.monotonic() - t0, 1e-3)
    last = telemetry[-1]
    return ProbeResult(
        "base",
        f"navdeck base: telemetry ~{rate:.0f} Hz, battery {last.battery_mv / 1000:.1f} V,"
        f" status 0x{last.status:02x}",
    )


def _ask_lidar(ser: serial.Serial, timeout: float) -> ProbeResult | None:
    parser = StreamParser()
    got: list[DeviceInfo | Health] = []
    for cmd in (Cmd.GET_HEALTH, Cmd.GET_INFO):
        ser.write(request(cmd))
        _read_for(ser, timeout, lambda d: got.extend(parser.feed(d)[0]), lambda c=cmd: _has(got, c))
    health = next((r for r in got if isinstance(r, Health)), None)
    info = next((r for r in got if isinstance(r, DeviceInfo)), None)
    if health is None and info is None:
        return None
    parts = ["RPLidar"]
    if info is not None:
        parts.append(
            f"model 0x{info.model:02x}, firmware {info.firmware[0]}.{info.firmware[1]:02d},"
            f" hardware {info.hardware}, serial {info.serial_number}"
        )
    if health is not None:
        try:
            status = HealthStatus(health.status).name
        except ValueError:
            status = f"status {health.status}"
        parts.append(f"health {status}" + (f" (code 0x{health.error_code:04x})" if health.error_code else ""))
    return ProbeResult("rplidar", ": ".join([parts[0], ", ".join(parts[1:])]))


def _has(got: list[DeviceInfo | Health], cmd: Cmd) -> bool:
    want = Health if cmd == Cmd.GET_HEALTH else DeviceInfo
    return any(isinstance(r, want) for r in got)


def _ask_base(ser: serial.Serial, timeout: float) -> ProbeResult | None:
    decoder = MessageDecoder()
    answers: list[ParamValue] = []
    ser.write(b"\x00" + _param_get_frame())  # the delimiter ends the lidar requests' bytes as a frame
    _read_for(
        ser,
        timeout,
        lambda d: answers.extend(m for m in decoder.feed(d) if isinstance(m, ParamValue)),
        lambda: bool(answers),
    )
    if not answers:
        return None
    return ProbeResult("base", f"navdeck base: answered PARAM_GET (telemetry rate {answers[0].value:g} Hz)")


def probe(device: str, baud: int = 115200, listen: float = 0.5, timeout: float = 0.3) -> ProbeResult:
    """What answers on ``device`` (read-only: see the module docstring); ``listen`` 0 skips step 1."""
    try:
        ser = open_port(device, baud, timeout=0.02)
    except PortUnavailableError as exc:
        return ProbeResult("unavailable", str(exc))
    try:
        # An A1's motor runs while DTR is low: keep it asserted (motor stopped), also after the close,
        # which would otherwise drop DTR (HUPCL) and set a lidar spinning that was at rest.
        set_motor(ser, False)
        hold_dtr_after_close(ser)
        ser.reset_input_buffer()
        found = _listen_base(ser, listen)
        if found is None:
            ser.reset_input_buffer()
            found = _ask_lidar(ser, timeout)
        if found is None:
            ser.reset_input_buffer()
            found = _ask_base(ser, timeout)
        return found or ProbeResult(
            "unknown", f"no navdeck telemetry, RPLidar or PARAM_VALUE answer at {baud} baud"
        )
    except (serial.SerialException, OSError) as exc:
        return ProbeResult("unavailable", f"{device}: {str(exc).splitlines()[0] if str(exc) else exc}")
    finally:
        ser.close()


def report(device: SerialDevice, result: ProbeResult | None) -> dict:
    """One JSON row of ``navdeck ports --json``."""
    row = asdict(device)
    row["probe"] = asdict(result) if result is not None else None
    return row
