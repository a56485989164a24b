"""Messages of the navdeck base protocol (host <-> STM32), byte-exact spec in docs/serial-protocol.md.

Every message is a frozen dataclass with a fixed little-endian ``struct`` layout, so the firmware can
mirror it with packed C structs. ``encode(msg, seq)`` gives the wire frame; ``MessageDecoder`` turns
a byte stream into messages on top of ``framing.FrameDecoder`` (which counts and drops bad frames).
The message set follows the FreeRTOS task layout of source A: the 1 ms link task exchanges
``VelocityCommand``/``Heartbeat`` and ``Telemetry``; the obstacle task's interrupt sets
``STATUS_OBSTACLE_STOP``; the motor task obeys ``EStop``/``Reset`` and the command watchdog.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import astuple, dataclass
from enum import IntEnum, IntFlag
from typing import ClassVar

from robot.serial.framing import FrameDecoder, RawFrame, encode_frame


class MsgType(IntEnum):
    """Message type byte. 0x0_ host -> base commands, 0x1_ base -> host telemetry, 0x2_ parameters,
    0x3_ errors."""

    VELOCITY = 0x01
    HEARTBEAT = 0x02
    ESTOP = 0x03
    RESET = 0x04
    TELEMETRY = 0x10
    PARAM_GET = 0x20
    PARAM_SET = 0x21
    PARAM_VALUE = 0x22
    PARAM_SAVE = 0x23
    ERROR = 0x30


class Status(IntFlag):
    """``Telemetry.status`` bits (uint16)."""

    ESTOP_LATCHED = 1 << 0  # e-stop received; motors off until RESET
    OBSTACLE_STOP = 1 << 1  # the IR interrupt stopped forward motion (firmware safety layer)
    WATCHDOG_STOP = 1 << 2  # no VELOCITY/HEARTBEAT for cmd_timeout: motors stopped
    MOTOR_FAULT = 1 << 3  # a servo driver reported a fault
    IMU_FAULT = 1 << 4  # the MPU6050 stopped answering
    LOW_BATTERY = 1 << 5  # battery below the configured cut-off
    PARAMS_DEFAULT = 1 << 6  # parameters are the firmware defaults (not loaded from flash)


class ResetMode(IntEnum):
    CLEAR_ESTOP = 0  # release the e-stop latch and clear WATCHDOG/MOTOR_FAULT bits
    ZERO_ENCODERS = 1  # also zero the encoder counters
    REBOOT = 2  # NVIC_SystemReset()


class ParamId(IntEnum):
    """Parameters the host may read and write (float32 on the wire, SI units)."""

    WHEEL_RADIUS = 1  # m
    TRACK_WIDTH = 2  # m
    WHEEL_BASE = 3  # m
    TICKS_PER_REV = 4  # counts per wheel revolution (quadrature)
    PID_KP = 5  # motor speed PID, per wheel rad/s error -> PWM duty
    PID_KI = 6
    PID_KD = 7
    CMD_TIMEOUT = 8  # s, firmware watchdog (default 0.2)
    TELEMETRY_RATE = 9  # Hz (50..100)
    OBSTACLE_STOP_ENABLE = 10  # 0 or 1
    OMNI_RADIUS = 11  # m
    BATTERY_CUTOFF = 12  # V


class ParamStatus(IntEnum):
    OK = 0
    UNKNOWN_ID = 1
    OUT_OF_RANGE = 2
    READ_ONLY = 3
    FLASH_ERROR = 4  # PARAM_SAVE only: the flash write or its read-back check failed


class ErrorCode(IntEnum):
    """``ErrorReport.code`` values."""

    BAD_FRAME = 1  # the base dropped frames from the host (detail: count since last report)
    UNKNOWN_MESSAGE = 2  # detail: type byte
    MOTOR_FAULT = 3  # detail: wheel index
    IMU_FAULT = 4  # detail: I2C error code
    WATCHDOG = 5  # command watchdog fired (detail: ms since last command)
    BROWN_OUT = 6  # detail: battery mV
    PARAM = 7  # detail: param id


class Severity(IntEnum):
    INFO = 0
    WARNING = 1
    ERROR = 2


@dataclass(frozen=True, slots=True)
class Message:
    """Base class: ``TYPE`` and ``FORMAT`` define the wire layout of the body."""

    TYPE: ClassVar[MsgType]
    FORMAT: ClassVar[struct.Struct]

    def pack(self) -> bytes:
        return self.FORMAT.pack(*astuple(self))

    @classmethod
    def unpack(cls, body: bytes) -> Message:
        return cls(*cls.FORMAT.unpack(body))


@dataclass(frozen=True, slots=True)
class VelocityCommand(Message):
    """Body velocity in base_link (REP-103): ``vx`` forward m/s, ``vy`` left m/s, ``wz`` CCW rad/s."""

    vx: float
    vy: float
    wz: float
    TYPE: ClassVar[MsgType] = MsgType.VELOCITY
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<3f")


@dataclass(frozen=True, slots=True)
class Heartbeat(Message):
    """Keeps the firmware watchdog fed while the host holds a command; ``host_ms`` is echoed back
    by nothing, it only makes frames distinguishable in captures."""

    host_ms: int
    TYPE: ClassVar[MsgType] = MsgType.HEARTBEAT
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<I")


@dataclass(frozen=True, slots=True)
class EStop(Message):
    """Latch the e-stop: motors off at once, ignored commands until ``Reset``."""

    TYPE: ClassVar[MsgType] = MsgType.ESTOP
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<")


@dataclass(frozen=True, slots=True)
class Reset(Message):
    mode: int = ResetMode.CLEAR_ESTOP
    TYPE: ClassVar[MsgType] = MsgType.RESET
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<B")


@dataclass(frozen=True, slots=True)
class Telemetry(Message):
    """Sent by the base at ``TELEMETRY_RATE`` (50-100 Hz).

    ``enc`` are cumulative int32 counts in the profile's wheel order (skid: FL, RL, FR, RR; omni:
    front, left, rear, right), forward rolling positive; they wrap at 2^31 and the host unwraps.
    ``gyro_z`` rad/s CCW, ``accel`` m/s^2 in base_link, ``ir_bits`` bit i = IR sensor i sees an
    obstacle, ``battery_mv`` millivolts, ``status`` ``Status`` bits, ``mcu_us`` a free-running
    microsecond timer (wraps at 2^32).
    """

    mcu_us: int
    enc0: int
    enc1: int
    enc2: int
    enc3: int
    gyro_z: float
    accel_x: float
    accel_y: float
    accel_z: float
    ir_bits: int
    battery_mv: int
    status: int
    TYPE: ClassVar[MsgType] = MsgType.TELEMETRY
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<I4i4fBHH")

    @property
    def enc(self) -> tuple[int, int, int, int]:
        return (self.enc0, self.enc1, self.enc2, self.enc3)


ENCODER_CHANNELS = 4
"""Encoder counters every ``Telemetry`` carries, whatever the base: a 2-wheel diff base fills the first
two (L, R) and sends 0 in the others, so the host takes the profile's ``wheel_count`` of them."""


@dataclass(frozen=True, slots=True)
class ParamGet(Message):
    param_id: int
    TYPE: ClassVar[MsgType] = MsgType.PARAM_GET
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<B")


@dataclass(frozen=True, slots=True)
class ParamSet(Message):
    param_id: int
    value: float
    TYPE: ClassVar[MsgType] = MsgType.PARAM_SET
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<Bf")


@dataclass(frozen=True, slots=True)
class ParamValue(Message):
    """The base's answer to ``ParamGet`` and ``ParamSet`` (the value now in effect)."""

    param_id: int
    value: float
    status: int = ParamStatus.OK
    TYPE: ClassVar[MsgType] = MsgType.PARAM_VALUE
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<BfB")


@dataclass(frozen=True, slots=True)
class ParamSave(Message):
    """Write the parameters now in effect to flash, so they survive a reboot (PARAM_SET alone does
    not persist). The base answers ``ParamValue(PARAM_SAVE_ID, count written, status)``."""

    TYPE: ClassVar[MsgType] = MsgType.PARAM_SAVE
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<")


PARAM_SAVE_ID = 0
"""``ParamValue.param_id`` of the answer to ``ParamSave`` (no parameter has id 0)."""


@dataclass(frozen=True, slots=True)
class ErrorReport(Message):
    code: int
    severity: int
    detail: int
    TYPE: ClassVar[MsgType] = MsgType.ERROR
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<BBI")


MESSAGE_TYPES: dict[int, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        VelocityCommand,
        Heartbeat,
        EStop,
        Reset,
        Telemetry,
        ParamGet,
        ParamSet,
        ParamValue,
        ParamSave,
        ErrorReport,
    )
}
BODY_SIZES: dict[int, frozenset[int]] = {t: frozenset({c.FORMAT.size}) for t, c in MESSAGE_TYPES.items()}


def encode(msg: Message, seq: int) -> bytes:
    """The wire frame of ``msg`` with sequence number ``seq`` (mod 256)."""
    return encode_frame(msg.TYPE, seq, msg.pack())


def decode_body(frame: RawFrame) -> Message:
    """Unpack a frame already checked by ``FrameDecoder`` (type known, length right)."""
    return MESSAGE_TYPES[frame.msg_type].unpack(frame.body)


class MessageDecoder:
    """Bytes in, messages out; never raises. ``frames`` exposes the drop counters."""

    def __init__(self) -> None:
        self.frames = FrameDecoder(BODY_SIZES)

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[Message]:
        return [decode_body(f) for f in self.frames.feed(chunk)]

    def feed_all(self, chunks: Iterable[bytes]) -> list[Message]:
        out: list[Message] = []
        for c in chunks:
            out.extend(self.feed(c))
        return out

    def reset(self) -> None:
        self.frames.reset()

    @property
    def good(self) -> int:
        return self.frames.good

    @property
    def bad(self) -> int:
        return self.frames.bad


class Sequencer:
    """Per-direction sequence counter (uint8, wraps)."""

    def __init__(self) -> None:
        self._n = 0

    def encode(self, msg: Message) -> bytes:
        frame = encode(msg, self._n)
        self._n = (self._n + 1) & 0xFF
        return frame
