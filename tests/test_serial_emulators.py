"""The emulators on their own, seen through a plain pyserial port: rates, protocol answers, faults.

Behaviour, not speed: what is read is read until enough of it arrived (a starved emulator thread only
makes that take longer), rates come from the emulators' own clocks (MCU time, nodes per rotation),
and the wall-time rates themselves are benchmarks (``navdeck bench serial.emulated_link``)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from nav.types import Pose2D
from robot.base import ImuReading, WheelTicks
from robot.odometry import WheelOdometry
from robot.profiles import load_profile
from robot.serial.driver import wait_for
from robot.serial.emulate import EmulatorPair
from robot.serial.protocol import (
    ErrorCode,
    ErrorReport,
    MessageDecoder,
    ParamId,
    ParamSet,
    Sequencer,
    Telemetry,
    VelocityCommand,
)
from robot.serial.rplidar import Cmd, DeviceInfo, Health, Nodes, ScanAssembler, StreamParser, request

PROFILE = load_profile("skid4")


@pytest.fixture
def pair(tmp_path) -> Iterator[EmulatorPair]:
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path, seed=3) as p:
        yield p


def read_for(ser: serial.Serial, seconds: float) -> bytes:
    out = b""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += ser.read(max(1, ser.in_waiting))
    return out


def read_until(ser: serial.Serial, enough, timeout: float = 30.0) -> bytes:
    """Read until ``enough(bytes so far)`` (or ``timeout`` s, then fail)."""
    out = b""
    end = time.monotonic() + timeout
    while not enough(out):
        assert time.monotonic() < end, f"only {len(out)} bytes in {timeout} s"
        out += ser.read(max(1, ser.in_waiting))
    return out


def test_rplidar_answers_and_streams_at_a1_rates(pair: EmulatorPair) -> None:
    assert pair.lidar_path is not None
    with serial.Serial(pair.lidar_path, 115200, timeout=0.02) as ser:
        parser = StreamParser()
        ser.write(request(Cmd.GET_HEALTH) + request(Cmd.GET_INFO))
        responses, _ = parser.feed(read_for(ser, 0.2))
        assert responses[0] == Health(0, 0)
        assert isinstance(responses[1], DeviceInfo) and responses[1].model == 0x18
        parser.reset()
        ser.write(request(Cmd.SCAN))
        t0 = time.monotonic()
        data = read_until(ser, lambda b: len(b) >= 5 * 5 * 364)  # ~5 rotations of 364 5-byte nodes
        elapsed = time.monotonic() - t0
        ser.write(request(Cmd.STOP))
    _, nodes = parser.feed(data)
    # never faster than the A1's 2000 samples/s (the emulator's credit holds at most 50 ms of them);
    # slower only means this machine starved the thread: the rate itself is benchmarked
    assert len(nodes) <= 2000 * elapsed + 100, (len(nodes), elapsed)
    rotations = ScanAssembler().push(nodes, 0.0)
    assert len(rotations) >= 3
    per_rot = np.median([len(r) for r, _ in rotations])
    assert per_rot == pytest.approx(2000 / PROFILE.lidar.rate_hz, rel=0.05)
    first: Nodes = rotations[0][0]
    assert np.all(np.diff(first.angle_deg) > 0)  # clockwise sweep from 0 to 360
    assert (first.dist_mm > 0).mean() > 0.9  # the box's walls are all within 6 m


def test_rplidar_stop_silences_the_stream(pair: EmulatorPair) -> None:
    assert pair.lidar_path is not None
    with serial.Serial(pair.lidar_path, 115200, timeout=0.02) as ser:
        ser.write(request(Cmd.SCAN))
        assert len(read_for(ser, 0.5)) > 500
        ser.write(request(Cmd.STOP))
        time.sleep(0.05)
        ser.reset_input_buffer()
        assert read_for(ser, 0.3) == b""


def read_messages(ser: serial.Serial, enough, timeout: float = 30.0) -> list:
    """Decode base frames until ``enough(messages so far)`` (or ``timeout`` s, then fail)."""
    decoder, msgs = MessageDecoder(), []
    end = time.monotonic() + timeout
    while not enough(msgs):
        assert time.monotonic() < end, f"only {len(msgs)} messages in {timeout} s"
        msgs.extend(decoder.feed(ser.read(max(1, ser.in_waiting))))
    return msgs


def test_base_telemetry_rate_and_unknown_message(pair: EmulatorPair) -> None:
    with serial.Serial(pair.base_path, 115200, timeout=0.02) as ser:
        ser.reset_input_buffer()
        seq = Sequencer()
        ser.write(seq.encode(Telemetry(0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0)))  # wrong direction
        msgs = read_messages(ser, lambda ms: sum(isinstance(m, Telemetry) for m in ms) >= 50)
    telem = [m for m in msgs if isinstance(m, Telemetry)]
    # The rate on the emulated MCU's own clock: 50 Hz, never faster. A starved emulator thread sends
    # late frames back to back and drops what is over 100 ms late, so the mean period may grow a little
    # on a loaded machine; the wall-time rate is benchmarked (serial.emulated_link).
    period_us = (telem[-1].mcu_us - telem[0].mcu_us) / (len(telem) - 1)
    assert 19_000 <= period_us <= 30_000, period_us
    errors = [m for m in msgs if isinstance(m, ErrorReport)]
    assert errors and errors[0].code == ErrorCode.UNKNOWN_MESSAGE


def steady_speed(p: EmulatorPair, ser: serial.Serial, seq: Sequencer, vx: float) -> tuple[float, float]:
    """Command ``vx`` (kept alive at 20 Hz) until the simulated motors run at the speed the firmware
    asked of them; (that speed, the highest speed seen on the way)."""
    fastest = 0.0

    def at_target() -> bool:
        nonlocal fastest
        ser.write(seq.encode(VelocityCommand(vx, 0.0, 0.0)))
        target, speed = p.pump.sim._cmd.vx, p.pump.sim.truth_velocity.vx
        fastest = max(fastest, speed)
        return target > 0.0 and abs(speed - target) < 1e-9

    assert wait_for(at_target, timeout=30.0, period=0.05)
    return p.pump.sim.truth_velocity.vx, fastest


def test_wrong_wheel_radius_parameter_changes_real_speed(tmp_path) -> None:
    """Calibration matters: firmware converting with a 10 % too large radius drives 10 % slow.

    The speed is the simulated robot's own once its motors reach what the firmware commanded (an
    acceleration ramp, never an overshoot), not a distance over wall time: a starved emulator thread
    only makes it take longer."""
    speeds = []
    for radius in (PROFILE.wheel_radius, PROFILE.wheel_radius * 1.1):
        with EmulatorPair(
            PROFILE,
            world="box",
            link_dir=tmp_path / str(radius),
            lidar=False,
            start_pose=Pose2D(1.0, 2.0, 0.0),
        ) as p:
            p.pump.sim.options = type(p.pump.sim.options)(
                slip_noise_std=0.0, gyro_noise=False, lidar_noise=False
            )
            with serial.Serial(p.base_path, 115200, timeout=0.02) as ser:
                seq = Sequencer()
                ser.write(seq.encode(ParamSet(ParamId.WHEEL_RADIUS, radius)))
                speed, fastest = steady_speed(p, ser, seq, 0.2)
                assert fastest <= speed + 1e-9  # it never went faster on the way
                assert p.pump.truth_pose.x > 1.0  # it drove forwards from its start
            speeds.append(speed)
    assert speeds[0] == pytest.approx(0.2, rel=1e-6)
    assert speeds[1] / speeds[0] == pytest.approx(1 / 1.1, rel=1e-6)


def test_gyro_rate_times_period_adds_up_to_the_turn_when_the_simulator_starves(tmp_path) -> None:
    """The telemetry's gyro is the mean rate over each frame's own MCU period, so the host's sum of
    rate x period is the angle turned, even when the simulator thread stalls mid-turn (as on a loaded
    machine: no new data for a while, then all of it in one catch-up frame)."""
    with EmulatorPair(PROFILE, world="box", link_dir=tmp_path, lidar=False) as p:
        p.pump.sim.options = type(p.pump.sim.options)(slip_noise_std=0.0, gyro_noise=False, lidar_noise=False)
        with serial.Serial(p.base_path, 115200, timeout=0.02) as ser:
            seq, decoder, telem = Sequencer(), MessageDecoder(), []

            def run(cmd: VelocityCommand, done) -> None:
                end = time.monotonic() + 30.0
                while not done():
                    assert time.monotonic() < end
                    ser.write(seq.encode(cmd))
                    telem.extend(
                        m for m in decoder.feed(ser.read(max(1, ser.in_waiting))) if isinstance(m, Telemetry)
                    )
                    time.sleep(0.02)

            def quiet(n: int = 5):
                start = len(telem)
                return lambda: len(telem) - start >= n and p.pump.sim.truth_velocity.is_zero()

            run(VelocityCommand(0.0, 0.0, 0.0), quiet())
            th0, first = p.pump.truth_pose.theta, len(telem) - 1
            run(VelocityCommand(0.0, 0.0, 0.8), lambda: p.pump.sim.truth_velocity.wz > 0.7)
            p.pump.step = lambda: None  # type: ignore[method-assign]  # the simulator thread stalls
            frozen = len(telem)
            run(VelocityCommand(0.0, 0.0, 0.8), lambda: len(telem) - frozen >= 8)
            del p.pump.step
            run(
                VelocityCommand(0.0, 0.0, 0.8),
                lambda: p.pump.truth_pose.relative_to(Pose2D(0, 0, th0)).theta > 1.0,
            )
            run(VelocityCommand(0.0, 0.0, 0.0), quiet())
            turned = float(p.pump.truth_pose.relative_to(Pose2D(0.0, 0.0, th0)).theta)
    frames = telem[first:]
    us = np.array([t.mcu_us for t in frames], dtype=np.int64)
    rates = np.array([t.gyro_z for t in frames])
    integrated = float(np.sum(rates[1:] * np.diff(us) * 1e-6))
    assert integrated == pytest.approx(turned, abs=0.02), (integrated, turned)
    # and the host's gyro-fused odometry, which takes still wheels for a zero-velocity update (gyro
    # bias), follows: frames of the stall must not claim a turn their counts do not show
    odometry = WheelOdometry(PROFILE)
    for t in frames:
        stamp = t.mcu_us * 1e-6
        odometry.update(WheelTicks(stamp, np.array(t.enc)), ImuReading(stamp, t.gyro_z, (0.0, 0.0, 9.81)))
    assert odometry.pose.theta == pytest.approx(turned, abs=0.03), (odometry.pose.theta, turned)
    # stall frames claiming the 0.8 rad/s turn would pull the bias to >= 0.06 (8 frames, 2 s time
    # constant); a loaded machine's long first frame of the turn, its wheels still under one tick, leaves
    # about 0.01
    assert abs(odometry.gyro_bias) < 0.03, odometry.gyro_bias
