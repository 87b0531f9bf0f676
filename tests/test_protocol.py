"""Wire protocol (robot/protocol.py): encoding, COBS framing, CRC, the streaming decoder."""

from __future__ import annotations

import re
import zlib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoservo.robot import protocol as P

Q = (0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7)
SAMPLES = [
    P.Hello(7),
    P.VersionInfo(1, 7, 4000, 4000, 3, 1000, Q, Q, Q),
    P.Servo(True),
    P.Servo(False),
    P.JointSetpoint(123_456_789_012, Q, Q),
    P.StateReport(1, 2, 3, 4, int(P.Status.SERVO_ON | P.Status.MOVING), 0, 5, Q, Q),
    P.Stop(),
    P.EStop(),
    P.Tool(0, True),
    P.ClearFault(),
    P.Ack(65535, 3),
    P.Nack(12, 3, int(P.Error.JUMP), 2, 0.5),
]


def f32(x: tuple) -> tuple:
    import struct
    return tuple(struct.unpack(f"<{len(x)}f", struct.pack(f"<{len(x)}f", *x)))


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_message_round_trips(msg):
    wire = P.encode(msg, 70000)  # seq is taken mod 2^16
    assert wire[0] == 0 and wire[-1] == 0 and 0 not in wire[1:-1]
    frames = P.Decoder().feed(wire)
    assert len(frames) == 1
    f = frames[0]
    assert f.seq == 70000 & 0xFFFF and f.version == P.PROTOCOL_VERSION
    assert type(f.msg) is type(msg)
    for name, code, n, _ in msg.LAYOUT:
        got, want = getattr(f.msg, name), getattr(msg, name)
        if code == "f":
            want = f32(want if n > 1 else (want,))
            got = got if n > 1 else (got,)
        assert got == want, name


def test_crc_is_crc32_iso_hdlc_as_documented():
    assert zlib.crc32(b"123456789") == 0xCBF43926  # the catalogue check value stated in the doc
    body = P.encode_body(P.Stop(), 1)
    assert body[:4] == bytes([1, 0x04, 1, 0])  # version, type, seq little-endian
    assert int.from_bytes(body[4:], "little") == zlib.crc32(body[:4])


def test_single_bit_errors_are_counted_never_yielded():
    wire = P.encode(P.JointSetpoint(5, Q, Q), 9)
    for i in range(1, len(wire) - 1):
        for bit in (0x01, 0x80):
            bad = bytearray(wire)
            bad[i] ^= bit
            d = P.Decoder()
            frames = d.feed(bytes(bad) + wire)  # the next good frame still comes through
            assert [f.seq for f in frames] == [9], (i, bit)
            assert d.resyncs >= 1 or d.overruns >= 1


def test_garbage_before_and_between_frames_resynchronises():
    wire = P.encode(P.Tool(0, True), 1) + b"\xff\x13\x37" * 200 + P.encode(P.Stop(), 2)
    d = P.Decoder()
    frames = []
    for i in range(0, len(wire), 7):  # arbitrary chunking
        frames += d.feed(wire[i:i + 7])
    assert [f.seq for f in frames] == [1, 2]
    assert d.overruns == 1


def test_wrong_version_and_unknown_type_are_refused():
    body = bytearray(P.encode_body(P.Stop(), 1))
    body[0] = 2
    body[-4:] = zlib.crc32(bytes(body[:-4])).to_bytes(4, "little")
    d = P.Decoder()
    assert d.feed(b"\x00" + P.cobs_encode(bytes(body)) + b"\x00") == []
    assert d.version_errors == 1
    body[0], body[1] = 1, 0x55
    body[-4:] = zlib.crc32(bytes(body[:-4])).to_bytes(4, "little")
    assert d.feed(P.cobs_encode(bytes(body)) + b"\x00") == []
    assert d.type_errors == 1


@given(st.binary(max_size=700))
def test_cobs_round_trip(data):
    enc = P.cobs_encode(data)
    assert 0 not in enc
    assert P.cobs_decode(enc) == data


@settings(max_examples=300)
@given(st.lists(st.one_of(st.binary(max_size=300),
                          st.sampled_from([P.encode(m, i) for i, m in enumerate(SAMPLES)])),
                max_size=12),
       st.integers(1, 64))
def test_decoder_fuzz_never_crashes_never_yields_bad_crc(chunks, step):
    stream = b"".join(chunks)
    d = P.Decoder()
    frames = []
    for i in range(0, len(stream), step):
        frames += d.feed(stream[i:i + step])
    for f in frames:
        assert zlib.crc32(f.body[:-4]) == int.from_bytes(f.body[-4:], "little")
        assert P.encode_body(f.msg, f.seq) == f.body  # what was yielded is exactly what was sent
    assert d.frames == len(frames)


def test_doc_tables_match_the_code():
    doc = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"
    text = doc.read_text()
    for t, size in P.PAYLOAD_SIZES.items():
        m = re.search(rf"\|\s*0x{int(t):02X}\s*\|\s*{t.name}\s*\|[^|]*\|\s*(\d+)\s*\|", text)
        assert m, f"message {t.name} missing from the summary table in {doc}"
        assert int(m.group(1)) == size, t.name
