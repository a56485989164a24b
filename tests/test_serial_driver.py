"""SerialDriver against the emulators over real pseudo-terminals (wall time, a few seconds).

Motion is driven until it happened (``drive_until``), never for a fixed time followed by a distance or
count check: a starved emulator thread on a loaded machine only makes a test take longer."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
import serial
from conftest import drive, last_ticks

from nav.types import Pose2D, Twist2D
from robot.base import Driver, LinkState, SensorFrame
from robot.clock import RealClock
from robot.profiles import load_profile
from robot.serial.driver import (
    BaseLink,
    SerialDriver,
    SerialOptions,
    SerialUrlError,
    _ClockSync,
    _TickUnwrapper,
    parse_serial_url,
    wait_for,
)
from robot.serial.emulate import EmulatorPair
from robot.serial.port import PortUnavailableError
from robot.serial.protocol import (
    MessageDecoder,
    ParamId,
    ParamSet,
    ParamStatus,
    Status,
    Telemetry,
    VelocityCommand,
)
from robot.serial.protocol import encode as encode_msg
from robot.serial.pty import PtyPort

PROFILE = load_profile("skid4")


@pytest.fixture
def pair(tmp_path) -> Iterator[EmulatorPair]:
    p = EmulatorPair(PROFILE, world="box", link_dir=tmp_path, seed=1)
    p.start()
    yield p
    p.close()


@pytest.fixture
def driver(pair: EmulatorPair) -> Iterator[SerialDriver]:
    """A driver with a lenient link timeout: on a loaded CI machine a starved thread must not trip
    the watchdog in tests about something else. The 300 ms default is tested on its own."""
    d = SerialDriver(SerialOptions(pair.base_path, pair.lidar_path, link_timeout=1.0), PROFILE)
    yield d
    d.close()


@pytest.fixture
def strict_driver(pair: EmulatorPair) -> Iterator[SerialDriver]:
    """The default options: 300 ms link timeout."""
    d = SerialDriver.from_url(pair.url(), PROFILE)
    assert d.options.link_timeout == 0.3
    yield d
    d.close()


def drive_until(
    d: SerialDriver, cmd: Twist2D, done, timeout: float = 30.0, period: float = 0.05
) -> list[SensorFrame]:
    """Run a 20 Hz control loop until ``done(frames so far)`` (or ``timeout`` s, then fail)."""
    frames: list[SensorFrame] = []
    end = time.monotonic() + timeout
    while True:
        d.command(cmd)
        frames.append(d.read())
        if done(frames):
            return frames
        assert time.monotonic() < end, f"not done after {timeout} s: {frames[-1]}"
        time.sleep(period)


def ticks_beyond(limit: float, sign: float = 1.0):
    """A ``drive_until`` condition: every wheel's count past ``sign * limit``."""

    def done(frames: list[SensorFrame]) -> bool:
        ticks = [f.ticks.counts for f in frames if f.ticks is not None]
        return bool(ticks) and bool(np.all(sign * ticks[-1] > limit))

    return done


def still(pair: EmulatorPair, d: SerialDriver) -> np.ndarray:
    """Hold a zero command until the emulated robot stands still and its counts stop changing; the
    counts then."""
    seen: list[np.ndarray] = []

    def settled(frames: list[SensorFrame]) -> bool:
        if frames[-1].ticks is not None:
            seen.append(frames[-1].ticks.counts)
        return (
            pair.pump.sim.truth_velocity.is_zero() and len(seen) >= 3 and bool(np.all(seen[-1] == seen[-3]))
        )

    drive_until(d, Twist2D(), settled)
    return seen[-1]


# ---------------------------------------------------------------------------------------- URL parsing
def test_parse_url() -> None:
    o = parse_serial_url("serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1&baud=230400")
    assert o == SerialOptions(port="/dev/ttyUSB0", lidar_port="/dev/ttyUSB1", baud=230400)
    assert parse_serial_url("serial://ttyACM0").port == "/dev/ttyACM0"
    assert parse_serial_url("serial:///dev/ttyUSB0?link_timeout=0.5").link_timeout == 0.5
    assert parse_serial_url("serial:///dev/ttyUSB0?lidar_timeout=3").lidar_timeout == 3.0
    # a base without a lidar: no lidar= at all, or said explicitly
    assert parse_serial_url("serial:///dev/ttyUSB0").lidar_port is None
    assert parse_serial_url("serial:///dev/ttyUSB0?lidar=none").lidar_port is None
    for bad in (
        "tcp://x",
        "serial://",
        "serial:///dev/x?bogus=1",
        "serial:///dev/x?baud=fast",
        "serial:///d?baud=-1",
    ):
        with pytest.raises(SerialUrlError):
            parse_serial_url(bad)


# ---------------------------------------------------------------------------------------- pure helpers
def test_tick_unwrap_across_int32_wrap_and_reboot() -> None:
    u = _TickUnwrapper(2)
    u.update((2**31 - 10, -5), rebased=False)
    got = u.update((-(2**31) + 5, -15), rebased=False)  # +15 through the wrap, -10
    assert got.tolist() == [15, -10]
    got = u.update((0, 0), rebased=True)  # MCU rebooted: no phantom motion
    assert got.tolist() == [15, -10]
    assert u.update((3, 1), rebased=False).tolist() == [18, -9]


def test_clock_sync_takes_least_delayed_sample_and_unwraps() -> None:
    s = _ClockSync()
    assert s.stamp(1_000_000, 101.010) == pytest.approx(101.010)
    assert s.stamp(1_020_000, 101.025) == pytest.approx(101.025)  # less delay: offset 100.005
    rise = _ClockSync.MAX_DRIFT * 0.020  # what the offset may rise in 20 ms of MCU time
    assert s.stamp(1_040_000, 101.060) == pytest.approx(101.045 + rise)  # more delay: offset kept
    wrap = s.stamp((1_060_000 + 2**32) & 0xFFFFFFFF, 101.070)
    assert wrap == pytest.approx(101.065 + 2 * rise)


def test_clock_sync_keeps_mcu_intervals_through_a_starved_host() -> None:
    """The host reads nothing for 1 s, then reads every frame 1 s late for 5 s (longer than any
    window of recent samples): the stamps keep the MCU's 20 ms intervals (within the clocks' drift)
    instead of jumping 1 s ahead, which turned the gyro-fused heading by radians (CI, stop 31)."""
    s = _ClockSync()
    stamps = [s.stamp(k * 20_000, 100.0 + k * 0.02 + 0.002) for k in range(100)]
    stamps += [s.stamp(k * 20_000, 100.0 + k * 0.02 + 1.0) for k in range(100, 400)]
    steps = np.diff(stamps)
    assert steps.min() > 0.0 and steps.max() < 0.02 * (1 + _ClockSync.MAX_DRIFT) + 1e-9
    assert stamps[-1] == pytest.approx(100.002 + 399 * 0.02, abs=0.07)
    # a clock that really drifts (the MCU 0.5 % slow) is followed
    t = _ClockSync()
    last = [t.stamp(k * 20_000, 100.0 + k * 0.02 * 1.005) for k in range(1000)][-1]
    assert last == pytest.approx(100.0 + 999 * 0.02 * 1.005, abs=1e-3)


# ---------------------------------------------------------------------------------------- start-up errors
def test_missing_port_is_one_line_error(tmp_path) -> None:
    with pytest.raises(PortUnavailableError) as exc:
        SerialDriver(str(tmp_path / "ttyUSB9"), PROFILE)
    assert "not found" in str(exc.value) and "\n" not in str(exc.value)


def test_busy_port_is_one_line_error(pair: EmulatorPair, driver: SerialDriver) -> None:
    with pytest.raises(PortUnavailableError) as exc:
        SerialDriver(pair.base_path, PROFILE)
    assert "busy" in str(exc.value)


# ---------------------------------------------------------------------------------------- behaviour
def test_implements_driver_protocol(driver: SerialDriver) -> None:
    assert isinstance(driver, Driver)


def test_drives_ticks_advance_scans_arrive(pair: EmulatorPair, driver: SerialDriver) -> None:
    advanced = ticks_beyond(700)  # ~0.11 m on 65 mm wheels at 1320 ticks/rev

    def done(frames: list[SensorFrame]) -> bool:
        return advanced(frames) and sum(f.scan is not None for f in frames) >= 3

    frames = drive_until(driver, Twist2D(0.2, 0.0, 0.0), done)
    assert all(f.link.state is not LinkState.LOST for f in frames)  # link_timeout 1 s in this fixture
    counts = still(pair, driver)
    assert np.all(np.abs(counts - counts.mean()) < 0.05 * counts.mean())  # straight: wheels agree
    # the counts measure the distance the robot really drove (2 pi r per ticks_per_rev)
    travelled = pair.pump.truth_pose.x - pair.pump.sim.world.start_pose.x
    metres = counts.mean() * 2 * math.pi * PROFILE.wheel_radius / PROFILE.ticks_per_rev
    assert metres == pytest.approx(travelled, rel=0.03), (metres, travelled)
    scans = [f.scan for f in frames if f.scan is not None]
    s = scans[-1]
    assert s.ranges.shape == (PROFILE.lidar.beams,)
    # in the 6 x 4 m box the robot sees walls all round: most beams measured and finite
    assert np.isfinite(s.ranges).mean() > 0.7
    imu = [f.imu.gyro_z for f in frames if f.imu is not None]
    assert abs(np.mean(imu)) < 0.05
    assert frames[-1].battery_v == pytest.approx(PROFILE.battery_full_v, abs=0.2)


def test_turn_gyro_and_scan_rotate_consistently(pair: EmulatorPair, driver: SerialDriver) -> None:
    turning: list[tuple[float, float]] = []  # (stamp, gyro) once the robot turns at the commanded rate

    def eight_at_speed(frames: list[SensorFrame]) -> bool:
        imu = frames[-1].imu
        if imu is not None and pair.pump.sim.truth_velocity.wz == pytest.approx(0.8):
            turning.append((imu.stamp, imu.gyro_z))
        return len(turning) >= 9

    frames = drive_until(driver, Twist2D(0.0, 0.0, 0.8), eight_at_speed)
    # each reading is the mean rate since the previous one: weighted by those intervals (a starved
    # emulator sends a stalled frame's 0 and then the catch-up), it is the steady rate
    stamps, gyro = np.array(turning).T
    assert np.sum(gyro[1:] * np.diff(stamps)) / (stamps[-1] - stamps[0]) == pytest.approx(0.8, abs=0.1)
    counts = last_ticks(frames)
    assert counts[0] < 0 < counts[2]  # left wheels back, right wheels forward (CCW)


def test_lidar_scan_matches_world(pair: EmulatorPair, driver: SerialDriver) -> None:
    """The A1's clockwise nodes come back as a CCW scan matching the simulator's own ray cast."""
    frames = drive(driver, Twist2D(), 0.8)
    scan = next(f.scan for f in reversed(frames) if f.scan is not None)
    truth = pair.pump.sim.lidar.true_ranges(pair.pump.sim.world, pair.pump.truth_pose)
    ok = np.isfinite(scan.ranges) & np.isfinite(truth)
    assert ok.mean() > 0.7
    assert np.median(np.abs(scan.ranges[ok] - truth[ok])) < 0.05
    # left (+90 deg) and right (-90 deg) walls of the box: 2 m each side of the start
    left = scan.ranges[round((math.pi / 2 - scan.angle_min) / scan.angle_increment)]
    assert left == pytest.approx(1.9, abs=0.1)


def estop_reported(d: SerialDriver) -> bool:
    return d.telemetry is not None and bool(d.telemetry.status & Status.ESTOP_LATCHED)


def test_estop_latches_until_reset(pair: EmulatorPair, driver: SerialDriver) -> None:
    drive_until(driver, Twist2D(0.2, 0.0, 0.0), ticks_beyond(200))
    driver.estop()
    assert wait_for(lambda: pair.base.estopped, timeout=10.0)
    drive_until(driver, Twist2D(0.2, 0.0, 0.0), lambda fs: estop_reported(driver))
    before = still(pair, driver)
    # commands keep coming while latched; the base ignores them
    frames = drive(driver, Twist2D(0.2, 0.0, 0.0), 0.6)
    assert pair.base.last_command is not None and pair.base.last_command.vx == pytest.approx(0.2)
    after = last_ticks(frames) if any(f.ticks is not None for f in frames) else before
    assert np.all(np.abs(after - before) <= 2), (before, after)
    assert pair.pump.sim.truth_velocity.is_zero()
    driver.reset()
    drive_until(driver, Twist2D(0.2, 0.0, 0.0), ticks_beyond(200 + after.max()))


def test_unplug_lost_within_300ms_then_recovers(pair: EmulatorPair, strict_driver: SerialDriver) -> None:
    driver = strict_driver
    drive(driver, Twist2D(0.15, 0.0, 0.0), 0.4)
    sent_before = pair.base.last_command
    assert sent_before is not None and sent_before.vx == pytest.approx(0.15)
    pair.base.unplug()
    t0 = time.monotonic()
    assert wait_for(lambda: driver.read().link.state is LinkState.LOST, timeout=1.0, period=0.005)
    lost_after = time.monotonic() - t0
    assert lost_after < 0.45, lost_after  # 300 ms watchdog + scheduling slack
    frame = driver.read()
    assert frame.link.state is LinkState.LOST and frame.link.reason
    assert frame.fault is not None
    refused = driver.refused_commands
    drive(driver, Twist2D(0.15, 0.0, 0.0), 0.3)
    assert driver.refused_commands > refused  # the driver commands nothing while LOST
    pair.base.last_command = None
    pair.base.replug()
    assert wait_for(lambda: driver.read().link.state is LinkState.OK, timeout=4.0)
    # After recovery the held command was zeroed: the base got no motion until a new command.
    time.sleep(0.2)
    assert pair.base.last_command is None or pair.base.last_command.vx == 0.0
    before = last_ticks(drive_until(driver, Twist2D(0.15, 0.0, 0.0), ticks_beyond(-1e12)))
    drive_until(driver, Twist2D(0.15, 0.0, 0.0), ticks_beyond(150 + before.max()))


def test_stall_is_lost_and_recovers_without_reconnect(
    pair: EmulatorPair, strict_driver: SerialDriver
) -> None:
    driver = strict_driver
    drive(driver, Twist2D(0.1, 0.0, 0.0), 0.3)
    pair.base.faults.stall = True  # the base still listens but sends nothing
    t0 = time.monotonic()
    assert wait_for(lambda: driver.read().link.state is LinkState.LOST, timeout=5.0, period=0.005)
    assert time.monotonic() - t0 > 0.25  # the 300 ms watchdog, not earlier (later only on a loaded machine)
    # the stop reaches the base (its emulator thread may be starved for a while on a loaded machine)
    stopped = lambda: pair.base.last_command is not None and pair.base.last_command.vx == 0.0  # noqa: E731
    assert wait_for(stopped, timeout=5.0)
    pair.base.last_command = None
    drive(driver, Twist2D(0.1, 0.0, 0.0), 0.3)
    assert pair.base.last_command is None  # while LOST the driver sends no velocity at all
    assert "no telemetry" in driver.read().link.reason
    pair.base.faults.stall = False
    assert wait_for(lambda: driver.read().link.state is LinkState.OK, timeout=1.0)


def test_firmware_watchdog_stops_motors(pair: EmulatorPair) -> None:
    """A host that sends one command and dies: the base stops 200 ms later on its own."""
    ser = serial.Serial(pair.base_path, 115200, timeout=0.05)
    try:
        ser.write(encode_msg(VelocityCommand(0.2, 0.0, 0.0), 0))
        time.sleep(0.1)
        assert pair.pump.sim._cmd.vx > 0
        assert wait_for(lambda: pair.base.watchdog_fired, timeout=0.5)
        assert pair.pump.sim._cmd.is_zero()
        dec = MessageDecoder()
        time.sleep(0.1)
        msgs = dec.feed(ser.read(4096))
        telem = [m for m in msgs if isinstance(m, Telemetry)]
        assert telem and telem[-1].status & Status.WATCHDOG_STOP
    finally:
        ser.close()


def test_keepalive_holds_command_between_slow_ticks(pair: EmulatorPair, driver: SerialDriver) -> None:
    """A 5 Hz control loop (slower than the 200 ms firmware watchdog) still drives: between its
    commands the reader thread resends the held velocity (every 50 ms), so more VELOCITY frames reach
    the base than the loop wrote, all of them the held command."""
    sent_before = len(driver.sent_log)
    frames = drive_until(driver, Twist2D(0.2, 0.0, 0.0), ticks_beyond(700), period=0.2)
    received = [m for _, m in pair.base.message_log if isinstance(m, VelocityCommand)]
    sent = [m for _, m in list(driver.sent_log)[sent_before:] if isinstance(m, VelocityCommand)]
    assert len(sent) > len(frames) and len(received) >= len(frames)
    assert all(m.vx == pytest.approx(0.2) for m in sent)


def test_dead_control_loop_lets_the_base_stop(pair: EmulatorPair, driver: SerialDriver) -> None:
    driver.command(Twist2D(0.2, 0.0, 0.0))
    time.sleep(0.3)
    assert pair.pump.sim._cmd.vx > 0
    # no more command() calls: keep-alive ends after command_hold (0.5 s), the firmware 0.2 s later
    assert wait_for(lambda: pair.base.watchdog_fired, timeout=1.5)
    assert driver.read().link.state is LinkState.OK  # heartbeats keep the link itself alive


def test_obstacle_stop_reported(tmp_path) -> None:
    start = Pose2D(5.6, 2.0, 0.0)  # front IR sensors 0.18 m from the east wall of the box
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path, start_pose=start, lidar=False) as pair:
        d = SerialDriver(pair.base_path, PROFILE)
        try:
            drive_until(d, Twist2D(0.2, 0.0, 0.0), lambda fs: fs[-1].base_stopped_by_obstacle)
            # the IR readings that stopped it arrive in their own frame, which a loaded host may read
            # a tick after the status flag (CI with two busy loops): they show both sensors triggered
            drive_until(
                d,
                Twist2D(0.2, 0.0, 0.0),
                lambda fs: fs[-1].ir is not None and fs[-1].ir.triggered.all(),
                timeout=5.0,
            )
            frames = drive(d, Twist2D(0.2, 0.0, 0.0), 0.5)  # pushing on: still held
            assert all(f.base_stopped_by_obstacle for f in frames if f.ticks is not None)  # new telemetry
            assert np.all(np.abs(last_ticks(frames)) < 30)
            # reversing away is allowed: the interrupt only blocks forward motion
            drive_until(d, Twist2D(-0.1, 0.0, 0.0), ticks_beyond(50, sign=-1.0))
        finally:
            d.close()


def test_parameters_get_set(pair: EmulatorPair, driver: SerialDriver) -> None:
    base = driver._base
    base.send(ParamSet(ParamId.WHEEL_RADIUS, 0.0350))
    base.send(ParamSet(ParamId.CMD_TIMEOUT, 99.0))
    base.send(ParamSet(200, 1.0))
    assert wait_for(lambda: len(base.params) >= 3, timeout=1.0)
    assert base.params[ParamId.WHEEL_RADIUS].value == pytest.approx(0.035)
    assert base.params[ParamId.CMD_TIMEOUT].status == ParamStatus.OUT_OF_RANGE
    assert base.params[200].status == ParamStatus.UNKNOWN_ID
    assert pair.base.params[ParamId.WHEEL_RADIUS] == pytest.approx(0.035)


def test_noisy_line_counts_bad_frames_and_keeps_driving(pair: EmulatorPair, driver: SerialDriver) -> None:
    pair.base.faults.corrupt_prob = 0.003
    pair.base.faults.drop_prob = 0.003
    advanced = ticks_beyond(600)
    frames = drive_until(
        driver, Twist2D(0.2, 0.0, 0.0), lambda fs: advanced(fs) and fs[-1].link.bad_frames > 0
    )
    assert all(f.link.state is not LinkState.LOST for f in frames)


def test_lidar_health_error_becomes_fault(tmp_path) -> None:
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path) as pair:
        assert pair.lidar is not None
        pair.lidar.set_health_error(0x8002)
        d = SerialDriver.from_url(pair.url(), PROFILE)
        try:
            assert wait_for(lambda: "health error" in (d.read().fault or ""), timeout=2.0)
            pair.lidar.set_health_error(None)
            assert wait_for(lambda: d.read().scan is not None, timeout=5.0)
        finally:
            d.close()


def test_lidar_unplug_fault_and_recovery(pair: EmulatorPair, driver: SerialDriver) -> None:
    assert wait_for(lambda: driver.read().scan is not None, timeout=2.0)
    assert pair.lidar is not None
    pair.lidar.unplug()
    assert wait_for(lambda: "lidar" in (driver.read().fault or ""), timeout=2.0)
    pair.lidar.replug()
    assert wait_for(lambda: driver.read().scan is not None, timeout=5.0)


def test_lidar_stall_restarts_scan(pair: EmulatorPair, driver: SerialDriver) -> None:
    assert wait_for(lambda: driver.read().scan is not None, timeout=2.0)
    assert pair.lidar is not None
    requests_before = list(pair.lidar.requests)
    pair.lidar.faults.stall = True
    assert wait_for(lambda: "silent" in (driver.read().fault or ""), timeout=2.5)
    pair.lidar.faults.stall = False
    assert wait_for(lambda: driver.read().scan is not None, timeout=4.0)
    new = pair.lidar.requests[len(requests_before) :]
    assert 0x25 in new and 0x20 in new  # STOP then SCAN again


def test_wrong_device_on_the_base_port_is_diagnosed(pair: EmulatorPair) -> None:
    """The lidar's port given as the base: bytes arrive but no telemetry, and the reason says so."""
    assert pair.lidar_path is not None
    # make the "lidar" stream something: ask it to scan through a raw port, then close that port
    with serial.Serial(pair.lidar_path, 115200, timeout=0.05) as ser:
        ser.write(b"\xa5\x20")
    d = SerialDriver(pair.lidar_path, PROFILE)
    try:
        seen = []  # judge the state of the very read that gave the diagnosis (a later read on a busy
        # host may already say "telemetry read late": DEGRADED)

        def diagnosed() -> bool:
            seen.append(d.read().link)
            return "wrong port or baud" in seen[-1].reason

        assert wait_for(diagnosed, timeout=5.0)
        assert seen[-1].state is LinkState.LOST
    finally:
        d.close()


# ---------------------------------------------------------------------------------------- wheel counts
@pytest.mark.parametrize("kinematics", ["diff", "skid", "omni"])
def test_each_kinematics_reads_its_wheels_from_the_four_wire_channels(tmp_path, kinematics: str) -> None:
    """Issue 23 item 1: Telemetry always carries four counters; a 2-wheel diff base fills L, R and the
    host must take two of them (it used to crash the reader thread on a (2,) vs (4,) broadcast)."""
    profile = replace(PROFILE, kinematics=kinematics)
    with EmulatorPair(profile, world="box", link_dir=tmp_path, seed=2, lidar=False) as pair:
        d = SerialDriver(SerialOptions(pair.base_path, link_timeout=1.0), profile)
        try:
            counts: list[np.ndarray] = []

            def turned_a_wheel() -> bool:
                d.command(Twist2D(0.0, 0.0, 0.6))
                frame = d.read()
                assert frame.fault is None, frame.fault
                if frame.ticks is not None:
                    counts.append(frame.ticks.counts)
                return bool(counts) and np.abs(counts[-1]).max() > 100

            assert wait_for(turned_a_wheel, timeout=10.0, period=0.05)
            assert counts[-1].shape == (profile.wheel_count,)
            # a CCW turn on the spot: left/right (or all four omni) wheels as the kinematics say
            if kinematics == "omni":
                assert np.all(counts[-1] > 0), counts[-1]
            else:
                left, right = counts[-1][: profile.wheel_count // 2], counts[-1][profile.wheel_count // 2 :]
                assert np.all(left < 0) and np.all(right > 0), counts[-1]
        finally:
            d.close()


# ---------------------------------------------------------------------------------------- dead threads
def _raise(exc: Exception):
    def fail(*args: object) -> None:
        raise exc

    return fail


def test_a_crashed_base_reader_is_a_fault_with_its_cause(pair: EmulatorPair, driver: SerialDriver) -> None:
    """A bug in the reader thread is reported as what it is, never as silence or a wrong baud rate."""
    assert wait_for(lambda: driver.read().link.state is LinkState.OK, timeout=5.0)
    driver._base._handle = _raise(ValueError("operands could not be broadcast"))  # type: ignore[method-assign]
    seen: list[SensorFrame] = []

    def faulted() -> bool:
        seen.append(driver.read())
        return seen[-1].fault is not None

    assert wait_for(faulted, timeout=5.0)
    frame = seen[-1]
    assert frame.link.state is LinkState.LOST
    assert "base reader thread" in frame.fault
    assert "ValueError: operands could not be broadcast" in frame.fault
    assert "something else" not in frame.fault and "no telemetry" not in frame.fault
    # it stays that way (nothing can clear it) and nothing is commanded any more
    time.sleep(0.2)
    assert "ValueError" in (driver.read().fault or "")
    refused = driver.refused_commands
    driver.command(Twist2D(0.2, 0.0, 0.0))
    assert driver.refused_commands == refused + 1
    assert pair.base.last_command is not None and pair.base.last_command.vx == 0.0  # the stop went out


def test_a_crashed_lidar_reader_is_a_fault_with_its_cause(pair: EmulatorPair, driver: SerialDriver) -> None:
    assert wait_for(lambda: driver.read().scan is not None, timeout=5.0)
    assert driver._lidar is not None
    driver._lidar._on_nodes = _raise(IndexError("bin out of range"))  # type: ignore[method-assign]
    assert wait_for(lambda: "IndexError: bin out of range" in (driver.read().fault or ""), timeout=5.0)
    assert "lidar reader thread" in (driver.read().fault or "")


def test_gyro_mean_weights_each_frame_by_its_period(tmp_path) -> None:
    """A base starved for 200 ms sends one frame whose gyro_z is the mean over those 200 ms, then
    catches up with frames 0.1 ms apart: the rate the odometry integrates is the time-weighted mean
    (0.2 rad over 0.2 s), not the plain mean of four frames (which lost 3/4 of the turn)."""
    port = PtyPort(tmp_path / "silent-base")
    link = BaseLink(SerialOptions(port.path, link_timeout=10.0), RealClock())
    try:

        def frame(us: int, gyro: float) -> Telemetry:
            return Telemetry(us, 0, 0, 0, 0, gyro, 0.0, 0.0, 9.81, 0, 12000, 0)

        link._handle([frame(1_000_000, 0.0)])
        link.take()
        link._handle([frame(1_200_000, 1.0), frame(1_200_100, 0.0), frame(1_200_200, 0.0)])
        _, _, _, gyro, new, _ = link.take()
        assert new and gyro == pytest.approx(0.2 / 0.2002, rel=1e-6)
        # the first frame after a reboot has no known period: its rate stands alone
        link._handle([frame(5_000, 0.3)])
        assert link.take()[3] == pytest.approx(0.3)
    finally:
        link.close()
        port.close()
