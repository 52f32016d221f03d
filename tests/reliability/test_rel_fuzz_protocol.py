"""Hypothesis campaign over the head-link decoder: arbitrary and mutated bytes raise only the
documented errors (FrameError / PayloadError / FirmwareError, all DeviceError), valid frames
survive garbage around them, and nothing corrupt is ever returned as a frame.

``make test`` runs a few hundred cases per property; ``make fuzz`` sets
GYROSTAR_FUZZ_EXAMPLES and runs the ≥ 10⁵-case campaign (``-m fuzz``).
"""

import struct

import pytest
from gyrostar.errors import DeviceError
from gyrostar.protocol import Frame, StreamDecoder, decode_frame, decode_reply, encode_frame
from gyrostar.protocol.defs import MAX_PAYLOAD, REPLY_FLAG, REPLY_LAYOUT, MsgType
from gyrostar.protocol.errors import FirmwareError, FrameError, PayloadError
from gyrostar.protocol.payloads import decode_request
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rel_fuzz_support import fuzz_examples

pytestmark = pytest.mark.fuzz
N = fuzz_examples()
CFG = settings(max_examples=N, deadline=None, database=None, derandomize=False,
               suppress_health_check=list(HealthCheck))
REPLY_TYPES = [int(t) | REPLY_FLAG for t in MsgType if t != MsgType.ERROR] + [int(MsgType.ERROR)]


@CFG
@given(st.binary(max_size=600))
def test_decode_frame_arbitrary_bytes(cases, data):
    cases["decode_frame(arbitrary bytes)"] += 1
    try:
        f = decode_frame(data)
    except FrameError:
        return
    assert encode_frame(f.type, f.seq, f.payload, f.version)[:-1] == data  # only a genuine frame decodes


@CFG
@given(st.integers(0, 255), st.integers(0, 0xFFFF), st.binary(max_size=300), st.data())
def test_mutated_frame_never_decodes_to_something_else(cases, typ, seq, payload, data):
    cases["decode_frame(mutated frame)"] += 1
    wire = bytearray(encode_frame(typ, seq, payload)[:-1])
    n = data.draw(st.integers(1, 4))
    for _ in range(n):
        op = data.draw(st.sampled_from(["flip", "drop", "insert"]))
        i = data.draw(st.integers(0, max(len(wire) - 1, 0)))
        if op == "flip" and wire:
            wire[i] ^= 1 << data.draw(st.integers(0, 7))
        elif op == "drop" and wire:
            del wire[i]
        else:
            wire.insert(i, data.draw(st.integers(0, 255)))
    try:
        f = decode_frame(bytes(wire))
    except FrameError:
        return
    assert (f.type, f.seq, f.payload) == (typ, seq, payload)


@CFG
@given(st.lists(st.one_of(st.binary(max_size=80),
                          st.builds(lambda t, s, p: encode_frame(t, s, p), st.integers(0, 255),
                                    st.integers(0, 0xFFFF), st.binary(max_size=120))), max_size=12),
       st.integers(1, 64))
def test_stream_decoder_garbage_and_frames(cases, parts, chunk):
    """Garbage between frames never raises; a frame preceded by a delimiter is recovered."""
    cases["StreamDecoder(garbage + frames)"] += 1
    stream = b""
    expected = []
    for p in parts:
        if p.endswith(b"\x00") and len(p) > 1 and p.count(0) == 1:
            try:
                f = decode_frame(p[:-1])
                stream += b"\x00" + p            # a delimiter ends any garbage before it
                expected.append((f.type, f.seq, f.payload))
                continue
            except FrameError:
                pass
        stream += p
    dec = StreamDecoder()
    got = []
    for i in range(0, len(stream), chunk):
        got += dec.feed(stream[i:i + chunk])
    got_t = [(f.type, f.seq, f.payload) for f in got]
    it = iter(got_t)
    assert all(e in it for e in expected)          # every clean frame, in order
    assert dec.frames == len(got)
    assert dec.pending <= dec.max_encoded


@CFG
@given(st.sampled_from(REPLY_TYPES + list(range(256))), st.integers(0, 0xFFFF), st.binary(max_size=400),
       st.sampled_from([None] + [int(t) for t in MsgType if t != MsgType.ERROR]))
def test_decode_reply_arbitrary_payload(cases, typ, seq, payload, expect):
    cases["decode_reply(arbitrary payload)"] += 1
    try:
        out = decode_reply(Frame(typ, seq, payload), expect=expect)
    except (PayloadError, FirmwareError) as exc:
        assert isinstance(exc, DeviceError)
        return
    assert isinstance(out, dict)


def _fixed(msg_type, draw):
    fmt, names = REPLY_LAYOUT[msg_type]
    s = struct.Struct("<" + fmt)
    vals = []
    for code in s.format.lstrip("<"):
        if code.isdigit():
            continue
        bits = {"B": 8, "b": 8, "H": 16, "h": 16, "I": 32, "i": 32, "Q": 64, "q": 64, "x": 0}[code]
        if code == "x":
            continue
        lo, hi = (0, 2 ** bits - 1) if code.isupper() else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
        small = draw(st.booleans())
        vals.append(draw(st.integers(max(lo, 0), min(hi, 40)) if small else st.integers(lo, hi)))
    return s.pack(*vals)


@CFG
@given(st.sampled_from([t for t in MsgType if t != MsgType.ERROR]), st.data())
def test_decode_reply_structured(cases, msg_type, data):
    """Well-formed fixed part (small counts likely) + random tail: reaches window/pixel decoding."""
    cases["decode_reply(structured)"] += 1
    payload = _fixed(msg_type, data.draw) + data.draw(st.binary(max_size=300))
    try:
        out = decode_reply(Frame(int(msg_type) | REPLY_FLAG, 1, payload), expect=int(msg_type))
    except PayloadError:
        return
    if msg_type == MsgType.WINDOW_DATA:
        assert len(out["windows"]) == out["count"]
    if msg_type == MsgType.FULL_FRAME:
        assert len(out["pixels"]) == out["count"]


@CFG
@given(st.integers(0, 255), st.binary(max_size=300))
def test_decode_request_arbitrary(cases, typ, payload):
    cases["decode_request(arbitrary)"] += 1
    try:
        out = decode_request(Frame(typ, 0, payload))
    except PayloadError:
        return
    assert isinstance(out["tail"], bytes)


def test_oversized_stream_is_discarded_and_counted(cases):
    cases["StreamDecoder(oversize)"] += 1
    dec = StreamDecoder()
    assert dec.feed(b"\x01" * (dec.max_encoded + 10)) == []
    good = encode_frame(0x81, 7, b"abc")
    got = dec.feed(b"\x00" + good)
    assert dec.overruns == 1 and [(f.seq, f.payload) for f in got] == [(7, b"abc")]
    assert MAX_PAYLOAD > 0
