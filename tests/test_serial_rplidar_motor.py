"""RPLidar A1 motor on/off through DTR, as the A1's USB adapter wires it (DTR asserted = stopped).

A Linux pseudo-terminal has no modem lines (TIOCMBIS/TIOCMBIC answer ENOTTY), so the emulator cannot
see DTR. What is tested instead: the driver's calls on the pyserial object of the real pty the
emulator serves, in order with the bytes it writes (motor on before SCAN, off after the final
STOP), that the missing line is detected and reported, that closing leaves DTR asserted (HUPCL
cleared: the pty shares its termios with the emulator's end), and the polarity on a pyserial port
that does carry DTR (``loop://``).
"""

from __future__ import annotations

import termios

import serial
import serial.serialposix

from robot.profiles import load_profile
from robot.serial.driver import wait_for
from robot.serial.emulate_rplidar import RPLidarEmulator
from robot.serial.pty import PtyPort
from robot.serial.rplidar import Cmd, RPLidar, request, set_motor
from robot.serial.simlink import SimPump

PROFILE = load_profile("skid4")


def test_motor_polarity_on_a_port_with_a_dtr_line() -> None:
    port = serial.serial_for_url("loop://", timeout=0.01)
    try:
        assert set_motor(port, True) and port.dtr is False  # DTR cleared: the A1 motor spins
        assert set_motor(port, False) and port.dtr is True  # DTR asserted: stopped
    finally:
        port.close()


def test_driver_switches_the_motor_around_scanning(tmp_path, monkeypatch) -> None:
    events: list[tuple[str, object]] = []
    original_dtr = serial.serialposix.Serial._update_dtr_state
    original_write = RPLidar._write

    def record_dtr(self: serial.Serial) -> None:
        if self.port == lidar_port.slave_name or self.port == lidar_port.path:
            events.append(("dtr", self._dtr_state))
        original_dtr(self)  # the real ioctl on the pty (raises ENOTTY: no modem lines)

    def record_write(self: RPLidar, ser: serial.Serial, data: bytes) -> None:
        events.append(("write", data))
        original_write(self, ser, data)

    monkeypatch.setattr(serial.serialposix.Serial, "_update_dtr_state", record_dtr)
    monkeypatch.setattr(RPLidar, "_write", record_write)

    pump = SimPump.for_world("box", PROFILE, seed=0)
    lidar_port = PtyPort(tmp_path / "rplidar", name="rplidar")
    # a USB serial port's usual default: drop DTR (-> the A1 motor spins) on the last close
    attrs = termios.tcgetattr(lidar_port._slave)
    attrs[2] |= termios.HUPCL
    termios.tcsetattr(lidar_port._slave, termios.TCSANOW, attrs)
    emu = RPLidarEmulator(pump, lidar_port)
    pump.start()
    emu.start()
    try:
        lidar = RPLidar(lidar_port.path, PROFILE.lidar)
        try:
            assert wait_for(lambda: lidar.scans > 0, timeout=5.0), lidar.fault
            assert lidar.motor_on is True
            assert lidar.motor_line is False  # the pty refused DTR, and the driver knows it
        finally:
            lidar.close()
        assert not termios.tcgetattr(lidar_port._slave)[2] & termios.HUPCL  # DTR held after close
    finally:
        emu.close()
        pump.close()

    scan_at = events.index(("write", request(Cmd.SCAN)))
    motor_on = [i for i, e in enumerate(events) if e == ("dtr", False)]
    assert motor_on and motor_on[0] < scan_at, events[: scan_at + 1]
    # closing: STOP the scan, then assert DTR (motor off) as the last word on the line
    assert events[-1] == ("dtr", True), events[-4:]
    assert events[-2] == ("write", request(Cmd.STOP)), events[-4:]
    assert lidar.motor_on is False
    # the bytes around the motor calls really reached the device
    assert Cmd.SCAN in emu.requests and emu.requests[-1] == Cmd.STOP
