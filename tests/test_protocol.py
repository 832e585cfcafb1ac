"""The link's framing and messages: round trips bit for bit, a total decoder (fuzzed),
resynchronisation after noise, and the example frame of docs/protocol.md."""
import re
import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil import protocol as P
from hil.framing import MAX_ENCODED, FrameDecoder, encode_frame

DOC = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"

u8, u16, u32, u64 = (st.integers(0, 2**n - 1) for n in (8, 16, 32, 64))
f64 = st.floats(allow_nan=True, allow_infinity=True) | st.builds(
    lambda b: struct.unpack("<d", b)[0], st.binary(min_size=8, max_size=8)
)  # every bit pattern, NaN payloads included
text = st.text(max_size=60)


def messages():
    cfg = st.builds(P.ConfigMsg, u8, u8, u16, u32, u16, f64, u16, u64)
    return st.one_of(
        st.builds(P.Hello, u32, u8, u8),
        st.builds(P.Info, u32, u8, u8, u16, f64, f64, u16, u16, st.text(max_size=10)),
        cfg,
        st.builds(P.Ready, cfg, f64, f64, f64),
        st.just(P.Start()),
        st.just(P.Stop()),
        st.builds(P.Commands, u32, st.lists(f64, min_size=1, max_size=P.MAX_BATCH).map(tuple)),
        st.builds(P.Samples, u32, u8, u16,
                  st.integers(1, P.MAX_BATCH).flatmap(lambda n: st.lists(f64, min_size=3 * n, max_size=3 * n)).map(tuple)),  # fmt: skip
        st.builds(P.Fault, u16, u32, text),
        st.builds(P.Stats, st.fixed_dictionaries({f: u32 for f in P.STATS_FIELDS})),
    )


@settings(max_examples=300, deadline=None)
@given(seq=u16, msg=messages())
def test_every_message_round_trips_bit_for_bit(seq, msg):
    body = P.encode(seq, msg)
    frames = FrameDecoder().feed(encode_frame(body))
    assert frames == [body]  # the framing gives back the very bytes (NaN payloads, -0.0 included)
    kind, seq2, back = P.parse(frames[0])
    assert seq2 == seq and P.encode(seq, back) == body
    assert type(back) is type(msg)


def test_samples_carry_exact_float64():
    vals = (1.0000000000000002e-6, -3.3e-5, 0.1 + 0.2, 5e-324, -0.0, 1.7976931348623157e308)
    body = P.samples(7, 123456, P.STATUS_HELD, 3, vals)
    kind, seq, m = P.parse(FrameDecoder().feed(encode_frame(body))[0])
    assert (kind, seq, m.tick0, m.status, m.missed) == (P.SAMPLES, 7, 123456, P.STATUS_HELD, 3)
    assert struct.pack("<6d", *m.values) == struct.pack("<6d", *vals)


@settings(max_examples=400, deadline=None)
@given(chunks=st.lists(st.binary(max_size=2 * MAX_ENCODED), max_size=12))
def test_the_decoder_is_total_on_arbitrary_bytes(chunks):
    dec = FrameDecoder()
    for c in chunks:
        for body in dec.feed(c):  # never raises
            try:
                P.parse(body)  # a message or Malformed, nothing else
            except P.Malformed:
                pass
        assert dec.buffered <= MAX_ENCODED  # bounded, whatever comes
    assert dec.bytes == sum(map(len, chunks))


@settings(max_examples=200, deadline=None)
@given(noise=st.binary(max_size=500), cuts=st.lists(st.integers(0, 200), max_size=6))
def test_frames_after_noise_are_recovered_in_any_chunking(noise, cuts):
    good = [encode_frame(P.commands(i, 1000 + i, (0.25 * i,))) for i in range(3)]
    stream = noise + b"\x00" + b"".join(good)
    dec, got, at = FrameDecoder(), [], 0
    for c in sorted(cuts) + [len(stream)]:
        got += dec.feed(stream[at:c])
        at = max(at, c)
    tail = [P.parse(b)[2] for b in got[-3:]]
    assert [m.values for m in tail if isinstance(m, P.Commands)][-3:] == [(0.0,), (0.25,), (0.5,)]


def test_errors_are_counted_by_kind():
    dec = FrameDecoder()
    frame = bytearray(encode_frame(P.stop(1)))
    frame[2] ^= 0x40  # a flipped bit: stuffing still valid, CRC not
    assert dec.feed(bytes(frame)) == [] and dec.crc_errors == 1
    assert dec.feed(b"\x05\x01\x00") == [] and dec.framing_errors == 1  # code byte points past the end
    assert dec.feed(b"\x01" * (MAX_ENCODED + 10)) == [] and dec.oversize == 1 and dec.buffered == 0
    assert dec.feed(b"\x01\x01\x00" + encode_frame(P.stop(2)))[-1] == P.stop(2)  # resynchronised
    assert dec.errors == 3  # the tail of the oversize chunk, up to its delimiter, is not counted again


@pytest.mark.parametrize(
    "body,needle",
    [
        (b"\x02\x84\x00", "shorter than its header"),
        (P.samples(0, 0, 0, 0, (1.0, 2.0, 3.0))[:-1], "SAMPLES frame of"),
        (bytes([P.VERSION]) + b"\x84\x00\x00" + struct.pack("<IBBH", 0, 0, 0, 0), "with 0 samples"),
        (b"\x01\x84\x00\x00", "protocol version 1"),
        (bytes([P.VERSION]) + b"\x7f\x00\x00", "unknown message type 0x7f"),
        (P.stop(0) + b"\x00", "STOP frame of 5 bytes"),
    ],
)
def test_malformed_bodies_are_rejected_with_a_reason(body, needle):
    with pytest.raises(P.Malformed, match=needle):
        P.parse(body)


def test_sequence_errors_are_classified():
    assert P.classify_seq(5, 5 + 1)[0] == "seq_repeated"
    assert P.classify_seq(2, 9)[0] == "seq_reordered"
    assert P.classify_seq(11, 9) == ("seq_dropped", "2 frame(s) missing (dropped)")
    assert P.classify_seq(10, 9, queued=[9])[0] == "seq_reordered"
    assert P.classify_seq(0, 65535) == ("seq_dropped", "1 frame(s) missing (dropped)")  # wraps mod 2^16


def test_the_example_frame_in_the_protocol_doc_decodes_as_documented():
    doc = DOC.read_text()
    hexes = re.findall(r"```text\nwire:\s*([0-9a-f ]+)\n", doc)
    assert hexes, "docs/protocol.md lost its example frame"
    wire = bytes.fromhex(hexes[0])
    (body,) = FrameDecoder().feed(wire)
    kind, seq, m = P.parse(body)
    assert (kind, seq, m.tick0, m.status, m.missed) == (P.SAMPLES, 5, 1000, 0, 0)
    assert m.values == (1.5e-6, -2.5e-4, 0.002)
    assert encode_frame(P.samples(5, 1000, 0, 0, (1.5e-6, -2.5e-4, 0.002))) == wire
