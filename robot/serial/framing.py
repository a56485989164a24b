"""Byte framing for the base link: COBS + zero delimiter, CRC-16/CCITT-FALSE, a streaming decoder.

A frame on the wire is ``COBS(payload) 0x00`` where ``payload = version | type | seq | body | crc16``
(``crc16`` little-endian, over ``version .. body``). COBS (Cheshire & Baker, "Consistent Overhead
Byte Stuffing", IEEE/ACM ToN 1999) removes every zero from the payload at a cost of one byte per
254, so a zero byte always marks a frame boundary: a receiver that joins mid-stream or loses bytes
resynchronises at the next zero without any timeout. The CRC is CRC-16/CCITT-FALSE (poly 0x1021,
init 0xFFFF, no reflection, no final xor; check value 0x29B1 for ``b"123456789"``), which is what
``binascii.crc_hqx(data, 0xFFFF)`` computes in C, and what STM32's CRC unit or a 512-byte table
computes on the MCU.

The decoder works on whole chunks: ``bytes.split(b"\\0")`` finds every boundary in C, and each
frame costs one COBS pass over its few code blocks plus one C CRC, well above 10,000 frames/s.
"""

from __future__ import annotations

import binascii
import logging
import struct
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

log = logging.getLogger(__name__)

PROTOCOL_VERSION = 1
HEADER = struct.Struct("<BBB")  # version, type, seq
CRC = struct.Struct("<H")
MAX_PAYLOAD = 254  # header + body + crc; keeps every encoded frame within one COBS block + 1
MAX_ENCODED = MAX_PAYLOAD + 2  # COBS adds at most 2 code bytes to 254 bytes; delimiter excluded
MIN_PAYLOAD = HEADER.size + CRC.size


def crc16_ccitt_false(data: bytes | bytearray | memoryview, init: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, MSB first, no final xor)."""
    return binascii.crc_hqx(data, init)


def cobs_encode(data: bytes | bytearray) -> bytes:
    """COBS-encode ``data`` (the result contains no zero byte; the caller appends the delimiter).

    Each zero-free run of up to 254 bytes is prefixed by ``len(run) + 1``; a run of exactly 254
    non-zero bytes is followed by a new block without an implied zero (code 0xFF).
    """
    out = bytearray()
    pieces = bytes(data).split(b"\x00")
    last = len(pieces) - 1
    for k, piece in enumerate(pieces):
        # every piece except the last is followed by an implied zero
        full = False
        while len(piece) >= 254:
            out.append(0xFF)
            out += piece[:254]
            piece = piece[254:]
            full = True
        if k == last and full and not piece:
            break  # canonical form: a final full block needs no empty block after it
        out.append(len(piece) + 1)
        out += piece
    return bytes(out)


class CobsError(ValueError):
    """Malformed COBS data (a zero inside, or a code byte running past the end)."""


def cobs_decode(data: bytes | bytearray | memoryview) -> bytes:
    """Decode one COBS block sequence (without the delimiter); raises ``CobsError`` if malformed.

    Fast path: each code byte after the first marks where a zero was, so decoding is "walk the code
    chain, zero each code byte in place, drop the first": one integer add per block. A 0xFF block
    (254 bytes without an implied zero) takes the general path.
    """
    buf = bytearray(data)
    n = len(buf)
    if n == 0:
        raise CobsError("empty frame")
    if 0 in buf:
        raise CobsError("zero byte inside frame")
    i = buf[0]
    if i != 0xFF:
        while i < n:
            code = buf[i]
            if code == 0xFF:
                return _cobs_decode_general(bytes(data))
            buf[i] = 0
            i += code
        if i == n:
            return bytes(buf[1:])
        raise CobsError("code byte runs past the end of the frame")
    return _cobs_decode_general(bytes(data))


def _cobs_decode_general(data: bytes) -> bytes:
    n = len(data)
    out = bytearray()
    i = 0
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            raise CobsError("code byte runs past the end of the frame")
        out += data[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


def encode_frame(msg_type: int, seq: int, body: bytes = b"", version: int = PROTOCOL_VERSION) -> bytes:
    """Build one wire frame: ``COBS(version type seq body crc16_le) 0x00``."""
    payload = HEADER.pack(version, msg_type, seq & 0xFF) + body
    if len(payload) + CRC.size > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload) + CRC.size} bytes exceeds {MAX_PAYLOAD}")
    payload += CRC.pack(crc16_ccitt_false(payload))
    return cobs_encode(payload) + b"\x00"


class DropReason(StrEnum):
    """Why the decoder dropped a frame (one counter each)."""

    BAD_COBS = "bad_cobs"
    BAD_CRC = "bad_crc"
    BAD_VERSION = "bad_version"
    UNKNOWN_TYPE = "unknown_type"
    BAD_LENGTH = "bad_length"
    OVERSIZE = "oversize"


@dataclass(frozen=True, slots=True)
class RawFrame:
    """A frame that passed COBS, CRC and version checks: type, sequence number and body bytes."""

    msg_type: int
    seq: int
    body: bytes


class FrameDecoder:
    """Streaming frame decoder: feed arbitrary byte chunks, get the good frames back.

    Never raises on input. Bad frames are dropped and counted per ``DropReason``; each reason is
    logged once (at WARNING) so a noisy line cannot flood the log. After any error the decoder is
    already synchronised: the next zero byte starts a new frame. ``body_sizes`` (type -> allowed
    body lengths) lets it reject unknown types and wrong lengths before any struct unpacking.
    """

    def __init__(self, body_sizes: dict[int, frozenset[int]] | None = None, max_encoded: int = MAX_ENCODED):
        self.body_sizes = body_sizes
        self.max_encoded = max_encoded
        self._buf = b""
        self._discarding = False  # inside an oversize run: skip until the next zero
        self.drops: Counter[DropReason] = Counter()
        self.good = 0
        self.seq_gaps = 0  # frames missing according to sequence numbers
        self._last_seq: int | None = None
        self._logged: set[DropReason] = set()

    @property
    def bad(self) -> int:
        return sum(self.drops.values())

    def reset(self) -> None:
        """Forget a partial frame and the sequence history (after a reconnect); keep the counters."""
        self._buf = b""
        self._discarding = False
        self._last_seq = None

    def _drop(self, reason: DropReason, detail: str) -> None:
        self.drops[reason] += 1
        if reason not in self._logged:
            self._logged.add(reason)
            log.warning(
                "serial link: dropped a frame (%s: %s); further drops of this kind are counted only",
                reason.value,
                detail,
            )

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[RawFrame]:
        """Consume ``chunk`` and return every complete good frame it finished, in order."""
        data = self._buf + bytes(chunk)
        parts = data.split(b"\x00")
        self._buf = parts.pop()  # incomplete tail (empty if the chunk ended on a delimiter)
        out: list[RawFrame] = []
        for part in parts:
            if self._discarding:  # the rest of an oversize frame ends here
                self._discarding = False
                continue
            if part:
                frame = self._decode_one(part)
                if frame is not None:
                    out.append(frame)
        if len(self._buf) > self.max_encoded:
            if not self._discarding:
                self._drop(DropReason.OVERSIZE, f"no delimiter within {self.max_encoded} bytes")
            self._discarding = True
            self._buf = b""
        return out

    def _decode_one(self, encoded: bytes) -> RawFrame | None:
        if len(encoded) > self.max_encoded:
            self._drop(DropReason.OVERSIZE, f"{len(encoded)} encoded bytes")
            return None
        try:
            payload = cobs_decode(encoded)
        except CobsError as exc:
            self._drop(DropReason.BAD_COBS, str(exc))
            return None
        if len(payload) < MIN_PAYLOAD:
            self._drop(DropReason.BAD_LENGTH, f"{len(payload)}-byte payload is shorter than a header + crc")
            return None
        if crc16_ccitt_false(payload[:-2]) != CRC.unpack_from(payload, len(payload) - 2)[0]:
            self._drop(DropReason.BAD_CRC, f"{len(payload)}-byte payload")
            return None
        version, msg_type, seq = HEADER.unpack_from(payload)
        if version != PROTOCOL_VERSION:
            self._drop(DropReason.BAD_VERSION, f"version {version}, expected {PROTOCOL_VERSION}")
            return None
        body = payload[HEADER.size : -2]
        if self.body_sizes is not None:
            sizes = self.body_sizes.get(msg_type)
            if sizes is None:
                self._drop(DropReason.UNKNOWN_TYPE, f"type 0x{msg_type:02x}")
                return None
            if len(body) not in sizes:
                self._drop(DropReason.BAD_LENGTH, f"type 0x{msg_type:02x} with a {len(body)}-byte body")
                return None
        if self._last_seq is not None:
            self.seq_gaps += (seq - self._last_seq - 1) & 0xFF
        self._last_seq = seq
        self.good += 1
        return RawFrame(msg_type, seq, body)

    def feed_all(self, chunks: Iterable[bytes]) -> list[RawFrame]:
        out: list[RawFrame] = []
        for c in chunks:
            out.extend(self.feed(c))
        return out
