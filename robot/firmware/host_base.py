"""``HostFirmwareBase``: the C firmware core, built for the host, running as the robot's base.

``navdeck_fw_host`` (robot/firmware/host/) runs the same core as the STM32 build on a pseudo-terminal
with a simulated motor/encoder plant; this class builds it with ``cc``, starts it for a profile's
geometry and pulls/replugs its cable, so ``SerialDriver`` can be tested against the C code exactly as
it is against the Python emulator (``robot/serial/emulate_base.py``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import tempfile
from pathlib import Path

from robot.firmware.build import build
from robot.profiles import RobotProfile


class FirmwareStartError(RuntimeError):
    """The host firmware did not come up (its stderr is in the message)."""


class HostFirmwareBase:
    """The host build of the firmware core behind ``path`` (a stable symlink to its pty)."""

    def __init__(
        self,
        profile: RobotProfile,
        link_dir: str | os.PathLike[str] | None = None,
        flash: str | os.PathLike[str] | None = None,
        build_dir: Path | None = None,
        extra_args: tuple[str, ...] = (),
    ) -> None:
        self._own_dir = None if link_dir is not None else tempfile.TemporaryDirectory(prefix="navdeck-fw-")
        directory = Path(link_dir if link_dir is not None else self._own_dir.name)  # type: ignore[union-attr]
        directory.mkdir(parents=True, exist_ok=True)
        self.link = directory / "base"
        self.flash = Path(flash) if flash is not None else directory / "flash.bin"
        self.argv = [
            str(build("navdeck_fw_host", build_dir)),
            "--link", str(self.link),
            "--flash", str(self.flash),
            "--kinematics", profile.kinematics,
            "--wheels", str(profile.wheel_count),
            "--wheel-radius", repr(profile.wheel_radius),
            "--track-width", repr(profile.track_width),
            "--wheel-base", repr(profile.wheel_base),
            "--omni-radius", repr(profile.omni_radius),
            "--ticks-per-rev", str(profile.ticks_per_rev),
            "--battery-cutoff", repr(profile.battery_empty_v),
            "--battery", repr(profile.battery_full_v),
            # the motors' full-duty wheel speed: headroom above the profile's top speed
            "--max-wheel-speed", repr(max(20.0, 1.5 * profile.limits.max_vel_x / profile.wheel_radius)),
            *extra_args,
        ]  # fmt: skip
        self.proc: subprocess.Popen[str] | None = None

    @property
    def path(self) -> str:
        return str(self.link)

    def url(self) -> str:
        """The ``--robot`` URL of a base-only robot on this firmware."""
        return f"serial://{self.path}"

    def start(self, timeout: float = 10.0) -> HostFirmwareBase:
        self.proc = subprocess.Popen(
            self.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()  # "ready LINK" once the pty exists
        if not line.startswith("ready"):
            self.close()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise FirmwareStartError(f"navdeck_fw_host did not start: {line.strip()} {err.strip()}")
        return self

    def _signal(self, sig: int) -> None:
        if self.proc is None or self.proc.poll() is not None:
            raise FirmwareStartError("navdeck_fw_host is not running")
        self.proc.send_signal(sig)

    def unplug(self) -> None:
        """Pull the cable: the link vanishes; the firmware keeps running and its watchdog stops the
        motors (a USB-serial adapter unplugged from the host, not a power cut)."""
        self._signal(signal.SIGUSR1)

    def replug(self) -> None:
        self._signal(signal.SIGUSR2)

    def toggle_imu_fault(self) -> None:
        self._signal(signal.SIGHUP)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc is not None:
            for stream in (self.proc.stdout, self.proc.stderr):
                if stream is not None:
                    stream.close()
        if self._own_dir is not None:
            with contextlib.suppress(OSError):
                self._own_dir.cleanup()

    def __enter__(self) -> HostFirmwareBase:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
