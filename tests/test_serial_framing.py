"""COBS, CRC-16/CCITT-FALSE and the streaming frame decoder (property-based fuzzing)."""

from __future__ import annotations

import logging

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robot.serial.framing import (
    MAX_PAYLOAD,
    CobsError,
    DropReason,
    FrameDecoder,
    cobs_decode,
    cobs_encode,
    crc16_ccitt_false,
    encode_frame,
)

FUZZ = settings(
    max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


def test_crc_check_value() -> None:
    # CRC-16/CCITT-FALSE catalogue check value (Greg Cook's CRC catalogue).
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


@pytest.mark.parametrize(
    ("data", "encoded"),
    [
        (b"", b"\x01"),
        (b"\x00", b"\x01\x01"),
        (b"\x00\x00", b"\x01\x01\x01"),
        (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
        (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
        (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
        (bytes(range(0, 255)), b"\x01\xff" + bytes(range(1, 255))),
        (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    ],
)
def test_cobs_wikipedia_vectors(data: bytes, encoded: bytes) -> None:
    assert cobs_encode(data) == encoded
    assert cobs_decode(encoded) == data


@pytest.mark.parametrize("n", [253, 254, 255, 508, 509])
def test_cobs_long_runs(n: int) -> None:
    data = bytes([7]) * n
    enc = cobs_encode(data)
    assert 0 not in enc
    assert cobs_decode(enc) == data
    assert cobs_decode(cobs_encode(data + b"\x00")) == data + b"\x00"


@given(st.binary(max_size=1200))
@FUZZ
def test_cobs_round_trip(data: bytes) -> None:
    enc = cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + len(data) // 254 + 1
    assert cobs_decode(enc) == data


def test_cobs_rejects_malformed() -> None:
    with pytest.raises(CobsError):
        cobs_decode(b"\x05\x11")
    with pytest.raises(CobsError):
        cobs_decode(b"\x02\x00")
    with pytest.raises(CobsError):
        cobs_decode(b"")


def _frames(payloads: list[bytes]) -> bytes:
    return b"".join(encode_frame(0x10, i, p) for i, p in enumerate(payloads))


bodies = st.lists(st.binary(max_size=MAX_PAYLOAD - 5), max_size=8)


@given(bodies, st.lists(st.integers(1, 40), min_size=1, max_size=30))
@FUZZ
def test_decoder_any_chunking(payloads: list[bytes], cuts: list[int]) -> None:
    stream = _frames(payloads)
    dec = FrameDecoder()
    out = []
    i = k = 0
    while i < len(stream):
        step = cuts[k % len(cuts)]
        out += dec.feed(stream[i : i + step])
        i += step
        k += 1
    assert [f.body for f in out] == payloads
    assert dec.bad == 0


@given(st.binary(max_size=3000))
@FUZZ
def test_decoder_never_raises_on_garbage(garbage: bytes) -> None:
    dec = FrameDecoder({0x10: frozenset({4})})
    dec.feed(garbage)
    # after any garbage, a delimiter resynchronises and good frames decode again
    good = encode_frame(0x10, 1, b"abcd")
    out = dec.feed(b"\x00" + good + good)
    assert [f.body for f in out] == [b"abcd", b"abcd"]


@given(bodies.filter(bool), st.data())
@FUZZ
def test_corrupted_frames_dropped_and_counted(payloads: list[bytes], data: st.DataObject) -> None:
    frames = [encode_frame(0x10, i, p) for i, p in enumerate(payloads)]
    victim = data.draw(st.integers(0, len(frames) - 1))
    f = bytearray(frames[victim])
    pos = data.draw(st.integers(0, len(f) - 2))  # never the delimiter
    f[pos] ^= data.draw(st.integers(1, 255))
    frames[victim] = bytes(f)
    dec = FrameDecoder()
    out = dec.feed(b"".join(frames))
    expected = [p for i, p in enumerate(payloads) if i != victim]
    got = [fr.body for fr in out]
    # CRC-16 detects every error confined to 16 bits; a flipped byte may also create a zero that
    # splits the frame in two, each of which is dropped.
    assert got == expected
    assert dec.bad >= 1


def test_each_drop_reason_counted_and_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    dec = FrameDecoder({0x10: frozenset({4})})
    good = encode_frame(0x10, 0, b"abcd")
    bad_crc = bytearray(cobs_decode(good[:-1]))
    bad_crc[-1] ^= 0xFF
    streams = {
        DropReason.BAD_COBS: b"\x09\x01\x02\x00",
        DropReason.BAD_CRC: cobs_encode(bytes(bad_crc)) + b"\x00",
        DropReason.BAD_VERSION: encode_frame(0x10, 0, b"abcd", version=9),
        DropReason.UNKNOWN_TYPE: encode_frame(0x77, 0, b"abcd"),
        DropReason.BAD_LENGTH: encode_frame(0x10, 0, b"abc"),
        DropReason.OVERSIZE: b"\x01" * 600 + b"\x00",
    }
    with caplog.at_level(logging.WARNING, logger="robot.serial.framing"):
        for reason, s in streams.items():
            for _ in range(3):
                assert dec.feed(s) == []
            assert dec.drops[reason] == 3, reason
            assert dec.feed(good)[0].body == b"abcd"
    assert len(caplog.records) == len(streams)


def test_oversize_without_delimiter_resyncs() -> None:
    dec = FrameDecoder()
    for _ in range(10):
        assert dec.feed(b"\x05" * 100) == []
    assert dec.drops[DropReason.OVERSIZE] == 1
    good = encode_frame(0x10, 0, b"xy")
    assert [f.body for f in dec.feed(b"\x00" + good)] == [b"xy"]


def test_sequence_gaps_counted() -> None:
    dec = FrameDecoder()
    dec.feed(encode_frame(1, 0) + encode_frame(1, 1) + encode_frame(1, 5) + encode_frame(1, 6))
    assert dec.seq_gaps == 3
    assert dec.good == 4
