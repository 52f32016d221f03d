"""Window tails (WINDOW_DATA / FRAME) against hand-computed bytes, and every malformed tail."""

import numpy as np
import pytest
from gyrostar.protocol import MsgType
from gyrostar.protocol.defs import REPLY_FLAG, PixelFormat
from gyrostar.protocol.errors import PayloadError, ProtocolUsageError
from gyrostar.protocol.framing import Frame
from gyrostar.protocol.payloads import WindowPixels, decode_reply, encode_reply, encode_windows_tail

# window 0x0102, pixels 1, 1023, 512 (sum 1536): header <HHI, then the pixels
HEADER = bytes([0x02, 0x01, 0x03, 0x00, 0x00, 0x06, 0x00, 0x00])
U16 = HEADER + bytes([0x01, 0x00, 0xFF, 0x03, 0x00, 0x02])
# 1 | 1023 << 10 | 512 << 20 = 0x200FFC01, LSB first
PACKED = HEADER + bytes([0x01, 0xFC, 0x0F, 0x20])
WIN = WindowPixels(0x0102, 1536, np.array([1, 1023, 512], np.uint16))


def _decode_windows(fields: dict, tail: bytes):
    """The windows of a WINDOW_DATA reply with ``fields`` (pixel format, count) and ``tail``."""
    head = encode_reply(MsgType.WINDOW_DATA, capture_no=1, start=0, total=fields["count"], **fields)
    return decode_reply(Frame(MsgType.WINDOW_DATA | REPLY_FLAG, 1, head + tail))["windows"]


@pytest.mark.parametrize("fmt,wire", [(PixelFormat.U16, U16), (PixelFormat.PACKED10, PACKED)])
def test_tail_bytes_by_hand_both_ways(fmt, wire):
    assert encode_windows_tail([WIN], fmt) == wire
    second = WindowPixels(7, 5, np.array([5], np.uint16))
    both = encode_windows_tail([WIN, second], fmt)
    got = _decode_windows({"pixel_format": fmt, "count": 2}, both)
    assert [(w.window_id, w.sum, w.pixels.tolist()) for w in got] == [(0x0102, 1536, [1, 1023, 512]), (7, 5, [5])]


@pytest.mark.parametrize("fmt,wire", [(PixelFormat.U16, U16), (PixelFormat.PACKED10, PACKED)])
def test_malformed_tails_name_the_fault(fmt, wire):
    with pytest.raises(PayloadError, match="ends inside a window header"):
        _decode_windows({"pixel_format": fmt, "count": 1}, wire[:5])
    with pytest.raises(PayloadError, match=rf"window 258: 3 pixels need {len(wire) - 8} bytes, {len(wire) - 9} left"):
        _decode_windows({"pixel_format": fmt, "count": 1}, wire[:-1])
    with pytest.raises(PayloadError, match="2 bytes after its last window"):
        _decode_windows({"pixel_format": fmt, "count": 1}, wire + b"\x00\x00")
    with pytest.raises(PayloadError, match="ends inside a window header"):
        _decode_windows({"pixel_format": fmt, "count": 2}, wire)
    with pytest.raises(PayloadError, match="unknown pixel format 9"):
        _decode_windows({"pixel_format": 9, "count": 1}, wire)


def test_values_that_do_not_fit_are_refused():
    with pytest.raises(ProtocolUsageError, match="10 bits"):
        encode_windows_tail([WindowPixels(1, 1024, np.array([1024], np.uint16))], PixelFormat.PACKED10)
    with pytest.raises(ProtocolUsageError, match="does not fit"):
        encode_windows_tail([WindowPixels(70000, 1, np.array([1], np.uint16))], PixelFormat.U16)
    with pytest.raises(ProtocolUsageError, match="does not fit"):
        encode_windows_tail([WindowPixels(1, 2**32, np.array([1], np.uint16))], PixelFormat.U16)
    with pytest.raises(ProtocolUsageError, match="unknown pixel format"):
        encode_windows_tail([WIN], 9)
