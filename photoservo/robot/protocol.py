"""Wire protocol between the host and the PA-10 serial bridge (pure: bytes in, bytes out, no I/O).

Specified in docs/protocol.md; this module is the reference implementation and the tables there
are generated from the same layouts (`LAYOUTS`). One frame on the wire:

    0x00 | COBS( version u8 | type u8 | seq u16 | payload | crc32 u32 ) | 0x00

All integers and floats little-endian; joint values in radians and rad/s (float32), times in
microseconds (u64): the host's monotonic clock for setpoints, the bridge's own clock for states.
CRC-32 is zlib.crc32 (CRC-32/ISO-HDLC: poly 0x04C11DB7 reflected, init 0xFFFFFFFF, xorout
0xFFFFFFFF) over everything before it. The leading 0x00 is optional for a receiver (empty frames
are skipped) but both ends send it, so line noise before a frame cannot swallow that frame.
"""

from __future__ import annotations

import enum
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import ClassVar

PROTOCOL_VERSION = 1
N_JOINTS = 7
HEADER = struct.Struct("<BBH")  # version, type, seq
CRC = struct.Struct("<I")
MAX_BODY = 255  # longest unstuffed frame (header + payload + crc) a receiver must accept
MAX_ENCODED = MAX_BODY + 2  # COBS adds one byte per started 254-byte block (body < 254 => 1)


class MsgType(enum.IntEnum):
    """Message type byte. Host -> bridge below 0x80, bridge -> host from 0x80."""

    HELLO = 0x01
    SERVO = 0x02
    SETPOINT = 0x03
    STOP = 0x04
    ESTOP = 0x05
    TOOL = 0x06
    CLEAR_FAULT = 0x07
    VERSION = 0x81
    STATE = 0x82
    ACK = 0x83
    NACK = 0x84


class Status(enum.IntFlag):
    """State report status bits."""

    SERVO_ON = 0x0001  # servo enabled, brakes released, joints under position control
    MOVING = 0x0002  # some joint speed above 1e-4 rad/s
    TRACKING = 0x0004  # following a setpoint stream (a valid setpoint within the watchdog)
    STOPPING = 0x0008  # decelerating to a stop (controlled stop or setpoint watchdog)
    BRAKED = 0x0010  # brakes engaged (servo off); joints cannot move
    WATCHDOG = 0x0020  # the setpoint watchdog fired since the last valid setpoint
    ESTOP = 0x0040  # emergency stop latched (clear with CLEAR_FAULT)
    FAULT = 0x0080  # a fault is latched; `fault` says which
    TOOL0 = 0x0100  # tool output 0 (net/gripper) on
    TOOL1 = 0x0200  # tool output 1 on


class Fault(enum.IntEnum):
    """State report fault code (0 = none); what engaged the brakes last."""

    NONE = 0
    ESTOP = 1  # emergency stop message (latched)
    SILENCE = 2  # no setpoint for the brake timeout while servo on: brakes engaged
    LIMIT = 3  # a joint reached its range limit (latched)
    INTERNAL = 4  # bridge-internal error (latched)


class Error(enum.IntEnum):
    """NACK error code: why the bridge refused a message."""

    UNKNOWN_TYPE = 1  # message type not known to this bridge
    BAD_LENGTH = 2  # payload length wrong for the type
    BAD_VERSION = 3  # header version differs from the bridge's
    SERVO_OFF = 4  # setpoint while the servo is off or braked: enable first
    OUT_OF_RANGE = 5  # setpoint position outside the joint range (joint, value say which)
    JUMP = 6  # setpoint further from the last one than the joint can move in one period
    SPEED = 7  # setpoint velocity above the joint's speed limit
    NOT_FINITE = 8  # NaN or infinity in a setpoint
    STALE = 9  # setpoint sequence number not newer than the last accepted one
    FAULT_LATCHED = 10  # servo enable refused while a fault is latched: CLEAR_FAULT first
    BAD_VALUE = 11  # a field has a value outside its documented set


class ProtocolError(ValueError):
    """A frame that cannot be decoded; `reason` is one of the Decoder's counter names."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


# ----------------------------------------------------------------------------- messages
# Each message class carries its type and payload layout; `fields` lists (name, struct code,
# count, meaning) for the generated documentation table.


@dataclass(frozen=True)
class Hello:
    """Host -> bridge: open a session. Answered with VERSION (not ACK)."""

    client_id: int = 0
    TYPE: ClassVar[MsgType] = MsgType.HELLO
    LAYOUT: ClassVar[tuple] = (("client_id", "I", 1, "free host identifier, echoed nowhere"),)


@dataclass(frozen=True)
class VersionInfo:
    """Bridge -> host: answer to HELLO, the bridge's timing and the joint limits it enforces."""

    firmware: int
    n_joints: int
    control_period_us: int
    state_period_us: int
    watchdog_periods: int
    brake_after_ms: int
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    dq_max: tuple[float, ...]
    TYPE: ClassVar[MsgType] = MsgType.VERSION
    LAYOUT: ClassVar[tuple] = (
        ("firmware", "I", 1, "bridge firmware version (free format)"),
        ("control_period_us", "H", 1, "bridge control period T (us)"),
        ("state_period_us", "H", 1, "state report period (us)"),
        ("brake_after_ms", "H", 1, "setpoint silence (ms) before the brakes engage"),
        ("n_joints", "B", 1, "number of joints (7)"),
        ("watchdog_periods", "B", 1, "setpoint silence (in T) before a controlled stop (3)"),
        ("q_min", "f", N_JOINTS, "joint range lower ends (rad)"),
        ("q_max", "f", N_JOINTS, "joint range upper ends (rad)"),
        ("dq_max", "f", N_JOINTS, "joint speed limits (rad/s)"),
    )


@dataclass(frozen=True)
class Servo:
    """Host -> bridge: enable (release brakes, hold the current position) or disable the servo
    (stop, then engage brakes). ACK or NACK."""

    enable: bool
    TYPE: ClassVar[MsgType] = MsgType.SERVO
    LAYOUT: ClassVar[tuple] = (("enable", "B", 1, "1 = enable, 0 = disable"),)


@dataclass(frozen=True)
class JointSetpoint:
    """Host -> bridge: where each joint should be one control period from now (rad) and its
    velocity there (rad/s), stamped with the host's monotonic clock. Not acknowledged (the state
    report echoes the last accepted one); NACKed when refused."""

    t_host_us: int
    q: tuple[float, ...]
    dq: tuple[float, ...]
    TYPE: ClassVar[MsgType] = MsgType.SETPOINT
    LAYOUT: ClassVar[tuple] = (
        ("t_host_us", "Q", 1, "host monotonic time when the setpoint was made (us)"),
        ("q", "f", N_JOINTS, "joint positions (rad)"),
        ("dq", "f", N_JOINTS, "joint velocities (rad/s)"),
    )


@dataclass(frozen=True)
class StateReport:
    """Bridge -> host, every state period: measured joint state and bridge status."""

    t_bridge_us: int
    t_host_echo_us: int
    last_seq: int
    setpoint_seq: int
    status: int
    fault: int
    rx_crc_errors: int
    q: tuple[float, ...]
    dq: tuple[float, ...]
    TYPE: ClassVar[MsgType] = MsgType.STATE
    LAYOUT: ClassVar[tuple] = (
        ("t_bridge_us", "Q", 1, "bridge clock when q, dq were measured (us)"),
        ("t_host_echo_us", "Q", 1, "t_host_us of the last accepted setpoint (0 = none yet)"),
        ("last_seq", "H", 1, "seq of the last valid frame received (any type)"),
        ("setpoint_seq", "H", 1, "seq of the last accepted setpoint"),
        ("status", "H", 1, "Status bits"),
        ("fault", "H", 1, "Fault code (0 = none)"),
        ("rx_crc_errors", "I", 1, "frames the bridge dropped: bad CRC, COBS, length (wraps)"),
        ("q", "f", N_JOINTS, "measured joint positions (rad)"),
        ("dq", "f", N_JOINTS, "measured joint velocities (rad/s)"),
    )


@dataclass(frozen=True)
class Stop:
    """Host -> bridge: controlled stop — drop the setpoint stream and decelerate every joint to
    rest within its limits; the servo stays on, holding. ACK."""

    TYPE: ClassVar[MsgType] = MsgType.STOP
    LAYOUT: ClassVar[tuple] = ()


@dataclass(frozen=True)
class EStop:
    """Host -> bridge: emergency stop — brakes at once, servo off, fault latched. ACK."""

    TYPE: ClassVar[MsgType] = MsgType.ESTOP
    LAYOUT: ClassVar[tuple] = ()


@dataclass(frozen=True)
class Tool:
    """Host -> bridge: set a digital tool output (0 = the net/gripper). ACK or NACK."""

    output: int
    on: bool
    TYPE: ClassVar[MsgType] = MsgType.TOOL
    LAYOUT: ClassVar[tuple] = (
        ("output", "B", 1, "output number: 0 = net/gripper, 1 = spare"),
        ("on", "B", 1, "1 = on (close/raise), 0 = off"),
    )


@dataclass(frozen=True)
class ClearFault:
    """Host -> bridge: clear a latched fault (ESTOP, LIMIT). Servo stays off. ACK."""

    TYPE: ClassVar[MsgType] = MsgType.CLEAR_FAULT
    LAYOUT: ClassVar[tuple] = ()


@dataclass(frozen=True)
class Ack:
    """Bridge -> host: the message with sequence `seq` and type `msg_type` was carried out."""

    seq: int
    msg_type: int
    TYPE: ClassVar[MsgType] = MsgType.ACK
    LAYOUT: ClassVar[tuple] = (
        ("seq", "H", 1, "seq of the acknowledged message"),
        ("msg_type", "B", 1, "its type"),
    )


@dataclass(frozen=True)
class Nack:
    """Bridge -> host: the message `seq` was refused; `error` says why, `joint` (0..6, 255 =
    none) and `value` (rad, rad/s or 0) say where."""

    seq: int
    msg_type: int
    error: int
    joint: int = 255
    value: float = 0.0
    TYPE: ClassVar[MsgType] = MsgType.NACK
    LAYOUT: ClassVar[tuple] = (
        ("value", "f", 1, "offending value (rad, rad/s or seq), 0 if none"),
        ("seq", "H", 1, "seq of the refused message"),
        ("msg_type", "B", 1, "its type"),
        ("error", "B", 1, "Error code"),
        ("joint", "B", 1, "joint index 0..6 at fault, 255 = none"),
    )


Message = (Hello | VersionInfo | Servo | JointSetpoint | StateReport | Stop | EStop | Tool
           | ClearFault | Ack | Nack)
MESSAGES: tuple[type, ...] = (Hello, VersionInfo, Servo, JointSetpoint, StateReport, Stop, EStop,
                              Tool, ClearFault, Ack, Nack)


@dataclass(frozen=True)
class _Codec:
    cls: type
    packer: struct.Struct
    names: tuple[str, ...]
    counts: tuple[int, ...]


def _codec(cls: type) -> _Codec:
    fmt = "<" + "".join(f"{n}{code}" if n > 1 else code for _, code, n, _ in cls.LAYOUT)
    return _Codec(cls, struct.Struct(fmt), tuple(f[0] for f in cls.LAYOUT),
                  tuple(f[2] for f in cls.LAYOUT))


CODECS: dict[int, _Codec] = {int(c.TYPE): _codec(c) for c in MESSAGES}
PAYLOAD_SIZES: dict[MsgType, int] = {MsgType(t): c.packer.size for t, c in CODECS.items()}


@dataclass(frozen=True)
class Frame:
    """One decoded frame: header fields, the message, and the unstuffed body (CRC included)."""

    version: int
    seq: int
    msg: Message
    body: bytes = field(repr=False, default=b"")


# ----------------------------------------------------------------------------- COBS


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing (Cheshire & Baker 1999): output has no 0x00 byte.
    Each run between zero bytes becomes a code byte (run length + 1) and the run; a run of 254
    non-zero bytes is closed with code 255 and no implied zero. The runs are found with
    bytes.split (a per-byte Python loop cost the emulator and the link ~0.1 ms a frame)."""
    out = bytearray()
    for run in bytes(data).split(b"\x00"):
        while len(run) >= 254:
            out.append(255)
            out += run[:254]
            run = run[254:]
        out.append(len(run) + 1)
        out += run
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of cobs_encode; raises ProtocolError('cobs_errors', ...) on an invalid stuffing."""
    data = bytes(data)
    zero = data.find(0)
    if zero >= 0:
        raise ProtocolError("cobs_errors", f"zero byte at {zero}")
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            raise ProtocolError("cobs_errors", f"block at {i} runs past the end")
        out += data[i + 1:end]
        i = end
        if code != 255 and i < n:
            out.append(0)
    return bytes(out)


# ----------------------------------------------------------------------------- frames


def _pack_payload(msg: Message) -> bytes:
    c = CODECS[int(msg.TYPE)]
    values: list = []
    for name, n in zip(c.names, c.counts):
        v = getattr(msg, name)
        if n == 1:
            values.append(int(v) if isinstance(v, bool) else v)
        else:
            if len(v) != n:
                raise ValueError(f"{type(msg).__name__}.{name}: expected {n} values, got {len(v)}")
            values.extend(float(x) for x in v)
    return c.packer.pack(*values)


def encode_body(msg: Message, seq: int, version: int = PROTOCOL_VERSION) -> bytes:
    """Unstuffed frame: header | payload | crc32 (little-endian)."""
    head = HEADER.pack(version, int(msg.TYPE), seq & 0xFFFF) + _pack_payload(msg)
    return head + CRC.pack(zlib.crc32(head))


def encode(msg: Message, seq: int, version: int = PROTOCOL_VERSION) -> bytes:
    """Bytes to put on the line for `msg` with sequence number `seq` (mod 2^16):
    0x00 | COBS(body) | 0x00."""
    return b"\x00" + cobs_encode(encode_body(msg, seq, version)) + b"\x00"


def decode_body(body: bytes) -> Frame:
    """Unstuffed frame -> Frame. Checks CRC first, then version, type and payload length;
    raises ProtocolError whose `reason` names the check that failed."""
    if len(body) < HEADER.size + CRC.size:
        raise ProtocolError("length_errors", f"frame of {len(body)} bytes is shorter than 8")
    (crc,) = CRC.unpack_from(body, len(body) - CRC.size)
    if zlib.crc32(body[:-CRC.size]) != crc:
        raise ProtocolError("crc_errors", "CRC-32 mismatch")
    version, mtype, seq = HEADER.unpack_from(body)
    if version != PROTOCOL_VERSION:
        raise ProtocolError("version_errors", f"protocol version {version}, expected {PROTOCOL_VERSION}")
    c = CODECS.get(mtype)
    if c is None:
        raise ProtocolError("type_errors", f"unknown message type 0x{mtype:02x}")
    payload = body[HEADER.size:-CRC.size]
    if len(payload) != c.packer.size:
        raise ProtocolError("length_errors",
                            f"{c.cls.__name__} payload of {len(payload)} bytes, expected {c.packer.size}")
    flat = c.packer.unpack(payload)
    kwargs, i = {}, 0
    for name, n in zip(c.names, c.counts):
        if n == 1:
            kwargs[name] = flat[i]
        else:
            kwargs[name] = tuple(flat[i:i + n])
        i += n
    if c.cls in (Servo, Tool):
        for k in ("enable", "on"):
            if k in kwargs:
                kwargs[k] = bool(kwargs[k])
    return Frame(version, seq, c.cls(**kwargs), bytes(body))


class Decoder:
    """Streaming receiver: feed arbitrary byte chunks, get whole valid frames back.

    Bytes are collected up to each 0x00 delimiter; the collected block is COBS-decoded,
    CRC-checked and parsed. A bad block is counted (crc_errors, cobs_errors, length_errors,
    version_errors, type_errors) and dropped — the next 0x00 resynchronises. A block growing past
    MAX_ENCODED without a delimiter is garbage: it is discarded up to the next 0x00 and counted
    in `overruns`. `resyncs` counts every discarded block, whatever the reason.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._skipping = False
        self.frames = 0
        self.crc_errors = 0
        self.cobs_errors = 0
        self.length_errors = 0
        self.version_errors = 0
        self.type_errors = 0
        self.overruns = 0
        self.resyncs = 0
        self.bytes_in = 0

    @property
    def errors(self) -> int:
        """All dropped blocks except overruns (which may be line noise between frames)."""
        return (self.crc_errors + self.cobs_errors + self.length_errors + self.version_errors
                + self.type_errors)

    def feed(self, data: bytes) -> list[Frame]:
        """Consume `data`; return the valid frames completed by it, in order."""
        return list(self.iter_feed(data))

    def iter_feed(self, data: bytes) -> Iterator[Frame]:
        self.bytes_in += len(data)
        start = 0
        while True:
            z = data.find(b"\x00", start)
            chunk = data[start:] if z < 0 else data[start:z]
            if not self._skipping:
                self._buf += chunk
                if len(self._buf) > MAX_ENCODED:
                    self._buf.clear()
                    self._skipping = True
                    self.overruns += 1
                    self.resyncs += 1
            if z < 0:
                return
            start = z + 1
            if self._skipping:
                self._skipping = False
                continue
            if not self._buf:
                continue  # empty frame: the optional leading delimiter
            block = bytes(self._buf)
            self._buf.clear()
            try:
                frame = decode_body(cobs_decode(block))
            except ProtocolError as e:
                setattr(self, e.reason, getattr(self, e.reason) + 1)
                self.resyncs += 1
                continue
            self.frames += 1
            yield frame
