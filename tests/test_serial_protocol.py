"""Round trips of every base-protocol message and decoder robustness on message streams."""

from __future__ import annotations

import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robot.serial.framing import DropReason, encode_frame
from robot.serial.protocol import (
    BODY_SIZES,
    MESSAGE_TYPES,
    ErrorReport,
    EStop,
    Heartbeat,
    MessageDecoder,
    MsgType,
    ParamGet,
    ParamSet,
    ParamValue,
    Reset,
    Sequencer,
    Telemetry,
    VelocityCommand,
    encode,
)

FUZZ = settings(
    max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)

f32 = st.floats(width=32, allow_nan=False)
u8, u16, u32 = st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)
i32 = st.integers(-(2**31), 2**31 - 1)

MESSAGES = st.one_of(
    st.builds(VelocityCommand, f32, f32, f32),
    st.builds(Heartbeat, u32),
    st.just(EStop()),
    st.builds(Reset, st.integers(0, 2)),
    st.builds(Telemetry, u32, i32, i32, i32, i32, f32, f32, f32, f32, u8, u16, u16),
    st.builds(ParamGet, u8),
    st.builds(ParamSet, u8, f32),
    st.builds(ParamValue, u8, f32, u8),
    st.builds(ErrorReport, u8, u8, u32),
)


def test_every_type_has_a_strategy_and_a_fixed_size() -> None:
    assert set(MESSAGE_TYPES) == set(MsgType)
    assert BODY_SIZES[MsgType.TELEMETRY] == frozenset({41})
    assert BODY_SIZES[MsgType.VELOCITY] == frozenset({12})


@given(st.lists(MESSAGES, min_size=1, max_size=12))
@FUZZ
def test_round_trip(msgs: list) -> None:
    seq = Sequencer()
    stream = b"".join(seq.encode(m) for m in msgs)
    dec = MessageDecoder()
    assert dec.feed(stream) == msgs
    assert dec.bad == 0 and dec.frames.seq_gaps == 0


def test_known_frame_bytes() -> None:
    # The example in docs/serial-protocol.md: VELOCITY vx=0.25 vy=0 wz=-0.5, seq 7.
    frame = encode(VelocityCommand(0.25, 0.0, -0.5), 7)
    assert frame.hex(" ") == "04 01 01 07 01 03 80 3e 01 01 01 01 01 01 04 bf 23 64 00"
    assert encode(EStop(), 7).hex(" ") == "06 01 03 07 18 de 00"


@given(st.lists(MESSAGES, max_size=4), st.binary(max_size=500), st.lists(MESSAGES, min_size=1, max_size=4))
@FUZZ
def test_good_frames_after_garbage(before: list, garbage: bytes, after: list) -> None:
    dec = MessageDecoder()
    dec.feed(b"".join(encode(m, i) for i, m in enumerate(before)))
    dec.feed(garbage)
    out = dec.feed(b"\x00" + b"".join(encode(m, i) for i, m in enumerate(after)))
    assert out[-len(after) :] == after


def test_wrong_length_and_unknown_type_rejected() -> None:
    dec = MessageDecoder()
    bad_len = encode_frame(MsgType.VELOCITY, 0, struct.pack("<2f", 1.0, 2.0))
    unknown = encode_frame(0x7E, 1, b"")
    assert dec.feed(bad_len + unknown + encode(Heartbeat(5), 2)) == [Heartbeat(5)]
    assert dec.frames.drops[DropReason.BAD_LENGTH] == 1
    assert dec.frames.drops[DropReason.UNKNOWN_TYPE] == 1


@pytest.mark.parametrize("vx", [0.0, -0.15, 1.5])
def test_velocity_float32_precision(vx: float) -> None:
    (msg,) = MessageDecoder().feed(encode(VelocityCommand(vx, 0.0, 0.0), 0))
    assert msg.vx == pytest.approx(vx, abs=1e-7)
