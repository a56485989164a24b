"""The C protocol header (robot/firmware/include/navdeck_protocol.h) against robot/serial, byte for byte.

A host program built from the header with the system ``cc`` answers one request per line (CRC, COBS
both ways, frames from packed structs, a streaming receiver); every answer is compared with the
Python implementation on seeded random inputs and on the edge cases of the spec.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest

from robot.firmware.build import CompilerMissingError, build
from robot.serial.framing import FrameDecoder, cobs_decode, cobs_encode, crc16_ccitt_false, encode_frame
from robot.serial.protocol import (
    BODY_SIZES,
    ErrorReport,
    EStop,
    Heartbeat,
    Message,
    MessageDecoder,
    MsgType,
    ParamGet,
    ParamSave,
    ParamSet,
    ParamValue,
    Reset,
    Telemetry,
    VelocityCommand,
    encode,
)


class VectorProgram:
    """The C test program as a line-oriented coprocess."""

    def __init__(self) -> None:
        try:
            exe = build("protocol_vectors")
        except CompilerMissingError as exc:
            pytest.skip(str(exc))
        self.proc = subprocess.Popen(
            [str(exe)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1
        )

    def ask(self, line: str) -> str:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return self.proc.stdout.readline().rstrip("\n")

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        assert self.proc.wait(timeout=10) == 0


@pytest.fixture(scope="module")
def c() -> Iterator[VectorProgram]:
    prog = VectorProgram()
    yield prog
    prog.close()


def random_bytes(rng: np.random.Generator, n: int, zero_share: float) -> bytes:
    data = rng.integers(1, 256, n, dtype=np.uint8)
    data[rng.random(n) < zero_share] = 0
    return data.tobytes()


def test_crc_matches_python(c: VectorProgram) -> None:
    assert c.ask("crc " + b"123456789".hex()) == "29b1"
    rng = np.random.default_rng(1)
    for n in (0, 1, 2, 5, 41, 254, 600):
        data = random_bytes(rng, n, 0.1)
        assert c.ask(f"crc {data.hex()}") == f"{crc16_ccitt_false(data):04x}", n


@pytest.mark.parametrize("zero_share", [0.0, 0.05, 0.5, 1.0])
def test_cobs_encode_and_decode_match_python(c: VectorProgram, zero_share: float) -> None:
    rng = np.random.default_rng(2)
    # lengths around the 254-byte block boundary are where encoders differ
    for n in (1, 2, 3, 100, 252, 253, 254, 255, 256, 507, 508, 509, 1000):
        data = random_bytes(rng, n, zero_share)
        enc = cobs_encode(data)
        assert c.ask(f"cobs {data.hex()}") == enc.hex(), (n, zero_share)
        assert c.ask(f"uncobs {enc.hex()}") == data.hex(), (n, zero_share)
        assert cobs_decode(bytes.fromhex(c.ask(f"cobs {data.hex()}"))) == data


def test_cobs_decoder_rejects_malformed_input(c: VectorProgram) -> None:
    for bad in ("", "00", "0501020300", "05010203", "ff" + "01" * 10):
        assert c.ask(f"uncobs {bad}") == "ERR", bad
    # the non-canonical form (a trailing 01 after a full block) decodes like the canonical one
    block = bytes(range(1, 255))
    assert c.ask("uncobs " + (b"\xff" + block + b"\x01").hex()) == block.hex()


MESSAGES: list[tuple[str, Message]] = [
    ("velocity", VelocityCommand(0.25, 0.0, -0.5)),
    ("velocity", VelocityCommand(-1.5, 0.125, 3.0)),
    ("heartbeat", Heartbeat(1234)),
    ("heartbeat", Heartbeat(0xFFFFFFFF)),
    ("estop", EStop()),
    ("reset", Reset(2)),
    ("telemetry", Telemetry(1_000_000, 1320, 1320, -660, -660, 0.5, 0.0, 0.0, 9.8125, 1, 12345, 2)),
    (
        "telemetry",
        Telemetry(0xFFFFFFFF, -(2**31), 2**31 - 1, 0, -1, -0.75, 0.5, -0.25, 9.75, 255, 65535, 0x7F),
    ),
    ("param_get", ParamGet(1)),
    ("param_set", ParamSet(1, 0.0325)),
    ("param_value", ParamValue(1, 0.0325, 0)),
    ("param_value", ParamValue(0, 12.0, 4)),
    ("param_save", ParamSave()),
    ("error", ErrorReport(5, 1, 210)),
]


def _values(msg: Message) -> tuple[float | int, ...]:
    return astuple(msg)


@pytest.mark.parametrize(("name", "msg"), MESSAGES)
def test_packed_structs_give_the_python_wire_bytes(c: VectorProgram, name: str, msg: Message) -> None:
    for seq in (0, 7, 255):
        args = " ".join(repr(v) if isinstance(v, float) else str(int(v)) for v in _values(msg))
        assert c.ask(f"pack {name} {seq} {args}") == encode(msg, seq).hex(), (name, seq)


@pytest.mark.parametrize(("name", "msg"), MESSAGES)
def test_c_unpacks_python_frames_into_the_same_fields(c: VectorProgram, name: str, msg: Message) -> None:
    answer = c.ask(f"unpack {encode(msg, 9).hex()}").split()
    assert int(answer[0], 16) == msg.TYPE and answer[1] == "9"
    for got, want in zip(answer[2:], _values(msg), strict=True):
        assert float(got) == pytest.approx(float(np.float32(want)), rel=1e-7, abs=0), name


def test_every_python_message_type_has_the_same_size_in_c(c: VectorProgram) -> None:
    names = {m.TYPE: n for n, m in MESSAGES}
    assert set(names) == set(BODY_SIZES)  # the C program knows every type the Python side has
    for t, sizes in BODY_SIZES.items():
        (size,) = sizes
        body = bytes(range(1, size + 1))
        wire = c.ask(f"frame {t:02x} 3 {body.hex()}")
        assert wire == encode_frame(t, 3, body).hex()
        assert c.ask(f"stream {wire}").startswith(f"{t:02x}:03:{body.hex()} good=1"), t


VELOCITY_SIZE = VelocityCommand.FORMAT.size


def test_streaming_receiver_counts_like_the_python_decoder(c: VectorProgram) -> None:
    """Garbage, truncation, bit flips, wrong versions, unknown types and oversize runs between good
    frames: the C receiver keeps the same good frames and the same drop counts as FrameDecoder."""
    rng = np.random.default_rng(5)
    msgs = [m for _, m in MESSAGES]
    for trial in range(40):
        stream = bytearray()
        for k in range(int(rng.integers(3, 12))):
            frame = bytearray(encode(msgs[int(rng.integers(len(msgs)))], k))
            kind = int(rng.integers(0, 8))
            if kind == 1:  # flip a bit (CRC or COBS catches it)
                i = int(rng.integers(0, len(frame) - 1))
                frame[i] ^= 1 << int(rng.integers(0, 8))
                if frame[i] == 0:
                    frame[i] = 0x55
            elif kind == 2:  # truncated: the next delimiter ends it early
                frame = frame[: int(rng.integers(1, len(frame)))] + b"\x00"
            elif kind == 3:  # a protocol version the receivers do not speak
                frame = bytearray(encode_frame(MsgType.VELOCITY, k, b"\x00" * VELOCITY_SIZE, version=2))
            elif kind == 4:  # an unknown type
                frame = bytearray(encode_frame(0x55, k, b"abc"))
            elif kind == 5:  # a known type with a body of the wrong size
                frame = bytearray(encode_frame(MsgType.VELOCITY, k, b"\x01" * (VELOCITY_SIZE - 1)))
            elif kind == 6:  # line noise without delimiters longer than a frame
                frame = bytearray(random_bytes(rng, int(rng.integers(200, 400)), 0.0)) + frame
            stream += frame
        py = FrameDecoder(BODY_SIZES)
        good = py.feed(bytes(stream))
        want = " ".join(f"{f.msg_type:02x}:{f.seq:02x}:{f.body.hex()}" for f in good)
        order = ("oversize", "bad_cobs", "bad_length", "bad_crc", "bad_version", "unknown_type")
        counts = ",".join(str(sum(v for k, v in py.drops.items() if k.value == r)) for r in order)
        expect = (want + " " if want else "") + f"good={py.good} drops={counts}"
        assert c.ask(f"stream {bytes(stream).hex()}") == expect, trial
    assert MessageDecoder().feed(encode(ParamSave(), 0)) == [ParamSave()]


def test_param_save_example_in_the_spec_is_the_encoder_output() -> None:
    spec = (Path(__file__).resolve().parent.parent / "docs" / "serial-protocol.md").read_text()
    wire = encode(ParamSave(), 7)
    assert f"wire `{wire.hex(' ')}`" in spec
    assert f"payload `{cobs_decode(wire[:-1]).hex(' ')}`" in spec
