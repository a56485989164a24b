"""SerialDriver against the C firmware core (robot/firmware/), built for the host with ``cc`` and run
as the base on a pseudo-terminal with a simulated motor/encoder plant (wall time, a few seconds).

The same checks as tests/test_serial_driver.py makes against the Python emulator: drive (the wheel
speed PID reaches the commanded speed), turn (gyro), the command watchdog, unplug -> LOST/FAULT,
replug -> recover, the e-stop latch and re-arming, parameters and PARAM_SAVE across reboots.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import serial
from conftest import drive, last_ticks

from nav.types import Twist2D
from robot.base import LinkState
from robot.firmware.build import CompilerMissingError, build
from robot.firmware.host_base import HostFirmwareBase
from robot.firmware.save_params import main as save_params_main
from robot.profiles import RobotProfile, load_profile
from robot.serial.driver import SerialDriver, SerialOptions, wait_for
from robot.serial.emulate import EmulatorPair
from robot.serial.protocol import (
    PARAM_SAVE_ID,
    ErrorCode,
    ErrorReport,
    EStop,
    Message,
    MessageDecoder,
    ParamGet,
    ParamId,
    ParamSave,
    ParamSet,
    ParamStatus,
    ParamValue,
    Reset,
    ResetMode,
    Sequencer,
    Status,
    Telemetry,
    VelocityCommand,
)
from robot.serial.pty import PtyPort

SKID = load_profile("skid4")
OMNI = load_profile("omni4")


@pytest.fixture(scope="module", autouse=True)
def _built() -> None:
    try:
        build("navdeck_fw_host")
    except CompilerMissingError as exc:
        pytest.skip(f"the host firmware needs a C compiler: {exc}")


def start_base(tmp_path: Path, profile: RobotProfile = SKID) -> HostFirmwareBase:
    return HostFirmwareBase(profile, link_dir=tmp_path / "dev").start()


@pytest.fixture
def fw(tmp_path: Path) -> Iterator[HostFirmwareBase]:
    base = start_base(tmp_path)
    yield base
    base.close()


@pytest.fixture
def driver(fw: HostFirmwareBase) -> Iterator[SerialDriver]:
    """A lenient 1 s link timeout: a starved test thread must not trip it in tests about other
    things (the unplug test uses the 300 ms default)."""
    d = SerialDriver(SerialOptions(fw.path, link_timeout=1.0), SKID)
    yield d
    d.close()


class RawLink:
    """The host side without SerialDriver: raw frames to and from the base's port."""

    def __init__(self, path: str) -> None:
        self.ser = serial.Serial(path, 115200, timeout=0.02)
        self.dec = MessageDecoder()
        self.seq = Sequencer()
        self.log: list[Message] = []

    def send(self, msg: Message) -> None:
        self.ser.write(self.seq.encode(msg))

    def collect(self, seconds: float) -> list[Message]:
        end = time.monotonic() + seconds
        out: list[Message] = []
        while time.monotonic() < end:
            out += self.dec.feed(self.ser.read(4096))
        self.log += out
        return out

    def wait(self, predicate, timeout: float = 2.0) -> Message:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in self.collect(0.02):
                if predicate(m):
                    return m
        raise AssertionError("no matching message from the base")

    def telemetry(self) -> Telemetry:
        """The newest TELEMETRY: drain what is buffered (50 ms), take the last one."""
        fresh = [m for m in self.collect(0.05) if isinstance(m, Telemetry)]
        if fresh:
            return fresh[-1]
        return self.wait(lambda m: isinstance(m, Telemetry))  # type: ignore[return-value]

    def param(self, msg: Message) -> ParamValue:
        self.send(msg)
        return self.wait(lambda m: isinstance(m, ParamValue))  # type: ignore[return-value]

    def close(self) -> None:
        self.ser.close()


def relax_watchdog(link: RawLink) -> None:
    """CMD_TIMEOUT 1 s: a test thread starved for 200 ms on a loaded machine must not trip the
    firmware watchdog in tests about something else (the watchdog has tests of its own)."""
    assert link.param(ParamSet(ParamId.CMD_TIMEOUT, 1.0)).status == ParamStatus.OK


@pytest.fixture
def raw(fw: HostFirmwareBase) -> Iterator[RawLink]:
    link = RawLink(fw.path)
    yield link
    link.close()


def wheel_speed(t0: Telemetry, t1: Telemetry, profile: RobotProfile) -> np.ndarray:
    """Rim speeds (m/s) between two telemetry frames, from the encoders and the MCU clock."""
    dt = ((t1.mcu_us - t0.mcu_us) & 0xFFFFFFFF) * 1e-6
    counts = np.array(t1.enc, dtype=float) - np.array(t0.enc, dtype=float)
    return counts[: profile.wheel_count] / profile.ticks_per_rev * 2 * math.pi * profile.wheel_radius / dt


def test_drives_straight_at_the_commanded_speed(fw: HostFirmwareBase, driver: SerialDriver) -> None:
    frames = drive(driver, Twist2D(0.2, 0.0, 0.0), 1.5)
    assert all(f.link.state is LinkState.OK for f in frames[3:])
    assert all(f.fault is None for f in frames[3:]), [f.fault for f in frames if f.fault]
    counts = last_ticks(frames)
    # 0.2 m/s for ~1.5 s on 65 mm wheels at 1320 ticks/rev: ~1900 ticks minus the ramp
    assert np.all(counts > 1000), counts
    assert np.all(np.abs(counts - counts.mean()) < 0.05 * counts.mean())  # straight: wheels agree
    # the wheel speed PID closes the gap between the feed-forward and the (slower) motors
    t0 = driver.telemetry
    drive(driver, Twist2D(0.2, 0.0, 0.0), 1.0)
    t1 = driver.telemetry
    assert t0 is not None and t1 is not None
    assert wheel_speed(t0, t1, SKID) == pytest.approx(np.full(4, 0.2), abs=0.02)
    assert frames[-1].battery_v == pytest.approx(SKID.battery_full_v, abs=0.01)


def test_turns_in_place_and_the_gyro_reports_the_mean_rate(driver: SerialDriver) -> None:
    frames = drive(driver, Twist2D(0.0, 0.0, 0.8), 1.5)
    gyro = [f.imu.gyro_z for f in frames[-8:] if f.imu is not None]
    assert np.median(gyro) == pytest.approx(0.8, abs=0.08)
    counts = last_ticks(frames)
    assert np.all(counts[:2] < -300) and np.all(counts[2:] > 300), counts  # left back, right forward


def test_omni_base_moves_sideways(tmp_path: Path) -> None:
    with HostFirmwareBase(OMNI, link_dir=tmp_path / "dev") as fw:
        d = SerialDriver(SerialOptions(fw.path, link_timeout=1.0), OMNI)
        try:
            frames = drive(d, Twist2D(0.0, 0.2, 0.0), 1.2)
        finally:
            d.close()
    front, left, rear, right = last_ticks(frames)
    # wheels front, left, rear, right: rim = -sin(a) vx + cos(a) vy + R wz
    assert front > 300 and rear < -300, (front, rear)
    assert abs(left) < 30 and abs(right) < 30, (left, right)
    gyro = [f.imu.gyro_z for f in frames[-8:] if f.imu is not None]
    assert abs(float(np.median(gyro))) < 0.05


def test_firmware_watchdog_stops_motors(raw: RawLink) -> None:
    """A host that sends one command and dies: the base stops CMD_TIMEOUT (200 ms) later on its own."""
    raw.send(VelocityCommand(0.2, 0.0, 0.0))
    t_sent = raw.telemetry().mcu_us
    err = raw.wait(lambda m: isinstance(m, ErrorReport) and m.code == ErrorCode.WATCHDOG, timeout=2.0)
    assert 200 <= err.detail < 400, err  # type: ignore[attr-defined]
    stopped = raw.telemetry()
    assert stopped.status & Status.WATCHDOG_STOP
    assert stopped.enc0 > 20  # it did move before the watchdog fired
    time.sleep(0.3)
    later = raw.telemetry()
    assert np.all(np.abs(np.subtract(later.enc, stopped.enc)) <= 5), (stopped.enc, later.enc)  # braked
    assert later.status & Status.WATCHDOG_STOP
    assert later.mcu_us - t_sent > 200_000
    # a fresh command clears the stop and drives again
    for _ in range(10):
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    moving = raw.telemetry()
    assert not moving.status & Status.WATCHDOG_STOP and moving.enc0 > later.enc0 + 50


def test_heartbeats_alone_do_not_hold_a_command(raw: RawLink) -> None:
    from robot.serial.protocol import Heartbeat

    raw.send(VelocityCommand(0.2, 0.0, 0.0))
    for k in range(10):  # a host that only heartbeats wants no motion: the watchdog still fires
        raw.send(Heartbeat(k))
        raw.collect(0.05)
    assert any(isinstance(m, ErrorReport) and m.code == ErrorCode.WATCHDOG for m in raw.log)


def test_estop_latches_and_reset_moves_nothing_until_a_fresh_command(raw: RawLink) -> None:
    relax_watchdog(raw)
    for _ in range(8):
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    raw.send(EStop())
    latched = raw.wait(lambda m: isinstance(m, Telemetry) and bool(m.status & Status.ESTOP_LATCHED))
    for _ in range(6):  # motion is ignored while latched
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    held = raw.telemetry()
    assert held.status & Status.ESTOP_LATCHED
    assert held.enc0 - latched.enc0 < 40  # braked: only the last coasting counts
    raw.send(Reset(ResetMode.CLEAR_ESTOP))
    raw.wait(lambda m: isinstance(m, Telemetry) and not m.status & Status.ESTOP_LATCHED)
    first = raw.telemetry()
    raw.collect(0.4)
    assert raw.telemetry().enc0 - first.enc0 <= 2  # re-armed but still: the old command is gone
    for _ in range(8):
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    assert raw.telemetry().enc0 > first.enc0 + 100


def test_unplug_lost_then_replug_recovers(fw: HostFirmwareBase) -> None:
    driver = SerialDriver(SerialOptions(fw.path), SKID)  # the default 300 ms link timeout
    try:
        drive(driver, Twist2D(0.15, 0.0, 0.0), 0.5)
        fw.unplug()
        assert wait_for(lambda: driver.read().link.state is LinkState.LOST, timeout=2.0, period=0.005)
        frame = driver.read()
        assert frame.fault is not None and frame.link.reason
        refused = driver.refused_commands
        drive(driver, Twist2D(0.15, 0.0, 0.0), 0.3)
        assert driver.refused_commands > refused  # nothing is sent while LOST
        fw.replug()
        assert wait_for(lambda: driver.read().link.state is LinkState.OK, timeout=5.0)
        # the robot was moving when the cable came out and the host could send nothing since: the
        # firmware's watchdog stopped it on its own, and reconnecting does not start it again
        t0 = driver.telemetry
        time.sleep(0.3)
        t1 = driver.telemetry
        assert t0 is not None and t1 is not None and t1.mcu_us != t0.mcu_us
        assert np.all(np.abs(np.subtract(t1.enc, t0.enc)) <= 2), (t0.enc, t1.enc)
        before = last_ticks(drive(driver, Twist2D(0.15, 0.0, 0.0), 0.1))
        after = last_ticks(drive(driver, Twist2D(0.15, 0.0, 0.0), 0.8))
        assert np.all(after - before > 150), after - before
    finally:
        driver.close()


def test_imu_fault_is_reported_and_clears(fw: HostFirmwareBase, driver: SerialDriver) -> None:
    assert wait_for(lambda: driver.read().link.state is LinkState.OK and driver.telemetry is not None, 3.0)
    assert driver.read().fault is None
    fw.toggle_imu_fault()
    assert wait_for(lambda: "IMU" in (driver.read().fault or ""), timeout=2.0)
    assert wait_for(lambda: bool(driver.telemetry and driver.telemetry.status & Status.IMU_FAULT), 2.0)
    fw.toggle_imu_fault()
    assert wait_for(lambda: driver.read().fault is None, timeout=2.0)


def test_parameters_are_checked_and_take_effect(raw: RawLink) -> None:
    assert raw.param(ParamGet(ParamId.WHEEL_RADIUS)).value == pytest.approx(SKID.wheel_radius)
    assert raw.param(ParamSet(ParamId.CMD_TIMEOUT, 99.0)).status == ParamStatus.OUT_OF_RANGE
    assert raw.param(ParamSet(ParamId.CMD_TIMEOUT, float("nan"))).status == ParamStatus.OUT_OF_RANGE
    assert raw.param(ParamSet(200, 1.0)).status == ParamStatus.UNKNOWN_ID
    assert raw.param(ParamGet(0)).status == ParamStatus.UNKNOWN_ID
    relax_watchdog(raw)
    # a 10 % too large wheel radius makes the firmware drive 10 % too slow (what calibrate measures)
    wrong = raw.param(ParamSet(ParamId.WHEEL_RADIUS, SKID.wheel_radius * 1.1))
    assert wrong.status == ParamStatus.OK
    for _ in range(30):
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    t0 = raw.telemetry()
    for _ in range(10):
        raw.send(VelocityCommand(0.2, 0.0, 0.0))
        raw.collect(0.05)
    t1 = raw.telemetry()
    assert wheel_speed(t0, t1, SKID) == pytest.approx(np.full(4, 0.2 / 1.1), abs=0.015)
    # TELEMETRY_RATE: 20 Hz
    assert raw.param(ParamSet(ParamId.TELEMETRY_RATE, 20.0)).status == ParamStatus.OK
    raw.collect(0.1)
    stamps = [m.mcu_us for m in raw.collect(1.0) if isinstance(m, Telemetry)]
    assert np.median(np.diff(stamps)) == pytest.approx(50_000, rel=0.05)


class PythonBase:
    """The Python emulator behind the same start/reboot interface as the C one (no lidar)."""

    def __init__(self, tmp_path: Path) -> None:
        self.pair = EmulatorPair(SKID, world="box", link_dir=tmp_path / "dev", lidar=False).start()
        self.path = self.pair.base_path

    def power_cycle(self) -> None:
        """The emulator has no process to restart: a reboot through the protocol is its power cycle."""
        self.pair.base._reset(ResetMode.REBOOT)

    def close(self) -> None:
        self.pair.close()


class CBase:
    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.fw = start_base(tmp_path)
        self.path = self.fw.path

    def power_cycle(self) -> None:
        """Kill the process and start a new one on the same flash file."""
        self.fw.close()
        self.fw = start_base(self.tmp_path)

    def close(self) -> None:
        self.fw.close()


@pytest.mark.parametrize("kind", ["c", "python"])
def test_param_set_is_volatile_until_param_save(tmp_path: Path, kind: str) -> None:
    """PARAM_SET lasts until a reboot; PARAM_SAVE writes flash, and the saved values come back after
    a reboot (RESET mode 2) and a power cycle. The C firmware and the Python emulator agree."""
    base = CBase(tmp_path) if kind == "c" else PythonBase(tmp_path)
    link = RawLink(base.path)
    try:
        assert link.telemetry().status & Status.PARAMS_DEFAULT
        assert link.param(ParamSet(ParamId.WHEEL_RADIUS, 0.034)).status == ParamStatus.OK
        link.send(Reset(ResetMode.REBOOT))
        link.collect(0.2)
        assert link.param(ParamGet(ParamId.WHEEL_RADIUS)).value == pytest.approx(SKID.wheel_radius)

        assert link.param(ParamSet(ParamId.WHEEL_RADIUS, 0.034)).status == ParamStatus.OK
        saved = link.param(ParamSave())
        assert saved.param_id == PARAM_SAVE_ID and saved.status == ParamStatus.OK and saved.value == 12
        assert link.param(ParamSet(ParamId.TRACK_WIDTH, 0.25)).status == ParamStatus.OK  # not saved
        link.send(Reset(ResetMode.REBOOT))
        link.collect(0.2)
        assert link.param(ParamGet(ParamId.WHEEL_RADIUS)).value == pytest.approx(0.034)
        assert link.param(ParamGet(ParamId.TRACK_WIDTH)).value == pytest.approx(SKID.track_width)
        assert not link.telemetry().status & Status.PARAMS_DEFAULT
        link.close()
        base.power_cycle()
        link = RawLink(base.path)
        assert link.param(ParamGet(ParamId.WHEEL_RADIUS)).value == pytest.approx(0.034)
    finally:
        link.close()
        base.close()


def test_bad_frames_from_the_host_are_reported_only_above_five_percent(raw: RawLink) -> None:
    from robot.serial.protocol import Heartbeat

    def bad_frame_errors(since: int) -> list[ErrorReport]:
        raw.collect(1.2)  # the base checks once a second
        return [m for m in raw.log[since:] if isinstance(m, ErrorReport) and m.code == ErrorCode.BAD_FRAME]

    raw.collect(1.2)  # past the first report window
    start = len(raw.log)
    # one corrupted frame among ~60 good ones: a glitch, no ERROR
    for k in range(60):
        frame = bytearray(raw.seq.encode(Heartbeat(k)))
        if k == 30:
            frame[3] ^= 0x40
        raw.ser.write(bytes(frame))  # one burst: any report window holds >= 30 of them
    assert not bad_frame_errors(start)
    # a line that garbles a third of the frames: reported, with the count
    start = len(raw.log)
    for k in range(30):
        frame = bytearray(raw.seq.encode(Heartbeat(k)))
        if k % 3 == 0:
            frame[3] ^= 0x40
        raw.ser.write(bytes(frame))
    errors = bad_frame_errors(start)
    assert errors and sum(e.detail for e in errors) == 10, errors


def test_diff_base_drives_two_wheels(tmp_path: Path) -> None:
    """A two-wheel differential base (L, R): a turn in place runs the wheels opposite, the gyro
    reads the commanded rate, the unused encoder slots stay 0."""
    diff = replace(SKID, kinematics="diff")
    assert diff.wheel_count == 2
    with HostFirmwareBase(diff, link_dir=tmp_path / "dev") as fw:
        link = RawLink(fw.path)
        try:
            relax_watchdog(link)
            for _ in range(30):
                link.send(VelocityCommand(0.0, 0.3, 1.0))  # vy is ignored by a diff base
                link.collect(0.05)
            t = link.telemetry()
        finally:
            link.close()
    # in place: -/+ wz * track / 2 per side
    assert t.enc0 < -300 and t.enc1 > 300 and abs(t.enc0 + t.enc1) < 0.05 * t.enc1, t
    assert t.enc2 == 0 and t.enc3 == 0
    assert t.gyro_z == pytest.approx(1.0, abs=0.08)


def test_save_params_tool_persists_what_param_set_changed(
    fw: HostFirmwareBase, capsys: pytest.CaptureFixture[str]
) -> None:
    link = RawLink(fw.path)
    try:
        assert link.param(ParamSet(ParamId.TRACK_WIDTH, 0.23)).status == ParamStatus.OK
    finally:
        link.close()
    assert save_params_main([fw.path]) == 0
    assert "saved 12 parameters" in capsys.readouterr().out
    link = RawLink(fw.path)
    try:
        link.send(Reset(ResetMode.REBOOT))
        link.collect(0.2)
        assert link.param(ParamGet(ParamId.TRACK_WIDTH)).value == pytest.approx(0.23)
    finally:
        link.close()


def test_save_params_tool_says_when_the_base_does_not_answer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    silent = PtyPort(tmp_path / "ttyUSB0")  # a device that never answers (an old firmware, or not the base)
    try:
        assert save_params_main([silent.path, "--timeout", "0.3"]) == 1
    finally:
        silent.close()
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no answer to PARAM_SAVE" in err and silent.path in err, err
    assert save_params_main([str(tmp_path / "missing")]) == 2


def test_ir_obstacle_holds_forward_motion_off_reverse_allowed(tmp_path: Path) -> None:
    with HostFirmwareBase(SKID, link_dir=tmp_path / "dev", extra_args=("--ir-bits", "1")) as fw:
        link = RawLink(fw.path)
        try:
            relax_watchdog(link)
            start = link.telemetry()
            for _ in range(10):
                link.send(VelocityCommand(0.2, 0.0, 0.0))
                link.collect(0.05)
            blocked = link.telemetry()
            assert blocked.status & Status.OBSTACLE_STOP and blocked.ir_bits == 1
            assert blocked.enc == start.enc  # forward is held off
            for _ in range(10):
                link.send(VelocityCommand(-0.1, 0.0, 0.0))
                link.collect(0.05)
            assert np.all(np.array(link.telemetry().enc) < -100)  # backing away is allowed
            assert link.param(ParamSet(ParamId.OBSTACLE_STOP_ENABLE, 0.0)).status == ParamStatus.OK
            before = link.telemetry()
            for _ in range(10):
                link.send(VelocityCommand(0.2, 0.0, 0.0))
                link.collect(0.05)
            after = link.telemetry()
            assert not after.status & Status.OBSTACLE_STOP and after.enc0 > before.enc0 + 100
        finally:
            link.close()
