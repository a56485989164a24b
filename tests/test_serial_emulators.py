"""The emulators on their own, seen through a plain pyserial port: rates, protocol answers, faults."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from nav.types import Pose2D
from robot.profiles import load_profile
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
        _, nodes = parser.feed(read_for(ser, 2.0))
        elapsed = time.monotonic() - t0
        ser.write(request(Cmd.STOP))
    rate = len(nodes) / elapsed
    assert 1400 < rate < 2300, rate  # ~2000 samples/s (less if this machine starves the thread)
    rotations = ScanAssembler().push(nodes, 0.0)
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


def test_base_telemetry_rate_and_unknown_message(pair: EmulatorPair) -> None:
    with serial.Serial(pair.base_path, 115200, timeout=0.02) as ser:
        ser.reset_input_buffer()
        seq = Sequencer()
        ser.write(seq.encode(Telemetry(0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0)))  # wrong direction
        msgs = MessageDecoder().feed(read_for(ser, 1.0))
    telem = [m for m in msgs if isinstance(m, Telemetry)]
    assert 40 <= len(telem) <= 60  # 50 Hz over ~1 s, with slack for a late or early window edge
    us = np.array([t.mcu_us for t in telem])
    assert np.median(np.diff(us)) == pytest.approx(20_000, rel=0.1)
    errors = [m for m in msgs if isinstance(m, ErrorReport)]
    assert errors and errors[0].code == ErrorCode.UNKNOWN_MESSAGE


def test_wrong_wheel_radius_parameter_changes_real_speed(tmp_path) -> None:
    """Calibration matters: firmware converting with a 10 % too large radius drives 10 % slow."""
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
                x0 = p.pump.truth_pose.x
                end = time.monotonic() + 1.0
                while time.monotonic() < end:
                    ser.write(seq.encode(VelocityCommand(0.2, 0.0, 0.0)))
                    time.sleep(0.05)
                speeds.append(p.pump.truth_pose.x - x0)
    assert speeds[1] / speeds[0] == pytest.approx(1 / 1.1, rel=0.04)
