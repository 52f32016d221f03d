"""Payload encoding (requests) and decoding (replies) per message type.

Fixed parts follow ``defs.REQUEST_LAYOUT`` / ``defs.REPLY_LAYOUT`` (little-endian);
variable tails: PING ``echo`` bytes, SET_WINDOWS ``spans`` (N×4 int array of
``[window_id, row, col_start, col_stop)``), WINDOW_DATA and FRAME ``windows`` (list of
:class:`WindowPixels`), FULL_FRAME ``pixels`` (uint16 array), FIND_SPOTS ``spots`` (N×3
int array of ``[row, col, flux]``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numba import njit

from .defs import REPLY_FLAG, REPLY_LAYOUT, REQUEST_LAYOUT, MsgType, PixelFormat
from .errors import PayloadError, ProtocolUsageError, error_for
from .framing import Frame

_SPAN = struct.Struct("<HHHH")
_WIN_HEADER = struct.Struct("<HHI")
_SPOT = struct.Struct("<HHH")


@dataclass(frozen=True)
class WindowPixels:
    """One window of a capture: its id, the sum of its pixel values and the pixels (span order)."""

    window_id: int
    sum: int
    pixels: np.ndarray  # uint16, span order (rows ascending, columns ascending)


def _struct(layout: tuple[str, tuple[str, ...]]) -> struct.Struct:
    return struct.Struct("<" + layout[0])


def encode_request(msg_type: int, tail: bytes = b"", **fields) -> bytes:
    """Payload of a request: the fixed fields (reserved ones default to 0) then ``tail`` bytes."""
    msg_type = MsgType(msg_type)
    if msg_type not in REQUEST_LAYOUT:
        raise ProtocolUsageError(f"{msg_type.name} is reply-only")
    fmt, names = REQUEST_LAYOUT[msg_type]
    unknown = set(fields) - set(names)
    if unknown:
        raise ProtocolUsageError(f"{msg_type.name} has no field(s) {sorted(unknown)}; fields: {list(names)}")
    values = []
    for name in names:
        if name not in fields and not name.startswith("reserved"):
            raise ProtocolUsageError(f"{msg_type.name} needs field '{name}'")
        values.append(int(fields.get(name, 0)))
    try:
        return _struct((fmt, names)).pack(*values) + bytes(tail)
    except struct.error as exc:
        raise ProtocolUsageError(f"{msg_type.name}: a field does not fit its type ({exc})") from None


def encode_spans(spans, frame: int = 0) -> bytes:
    """SET_WINDOWS payload for an N×4 array of ``[window_id, row, col_start, col_stop)`` rows,
    first used for stream frame ``frame`` (0: the next readout / at once outside a stream)."""
    arr = np.asarray(spans, dtype=np.int64).reshape(-1, 4)
    if arr.size and (arr.min() < 0 or arr.max() > 0xFFFF):
        raise ProtocolUsageError("span values must fit uint16 (0..65535)")
    head = encode_request(MsgType.SET_WINDOWS, n_spans=len(arr), frame=frame)
    return head + arr.astype("<u2").tobytes()


def decode_spans(tail: bytes) -> np.ndarray:
    """Inverse of the span tail of :func:`encode_spans`: N×4 int32 array."""
    if len(tail) % _SPAN.size:
        raise PayloadError(f"span table of {len(tail)} bytes is not a multiple of {_SPAN.size}")
    return np.frombuffer(tail, dtype="<u2").reshape(-1, 4).astype(np.int32)


def pack10(values) -> bytes:
    """10-bit values as an LSB-first bit stream: value i occupies bits [10i, 10i+10)."""
    a = np.asarray(values)
    if a.dtype != np.uint16:       # (uint16: the kernel checks the range as it packs)
        if a.size and (int(a.max()) > 0x3FF or int(a.min()) < 0):
            raise ProtocolUsageError("pixel value outside 0..1023 cannot be packed in 10 bits")
    out = _pack10_kernel(np.ascontiguousarray(a, dtype=np.uint16).ravel())
    if out.size and out[-1] == _PACK10_BAD:
        raise ProtocolUsageError("pixel value outside 0..1023 cannot be packed in 10 bits")
    return out[:-1].tobytes()


_PACK10_BAD = 0xFF   # the kernel's trailing status byte: a value did not fit in 10 bits


@njit(cache=True)
def _pack10_kernel(v):
    """Bit-stream pack of uint16 values (LSB first): ``ceil(10 n / 8)`` bytes, then one status
    byte, 0 or ``_PACK10_BAD`` (0xFF) when a value exceeds 1023 (the packing stops there)."""
    out = np.zeros((10 * v.size + 7) // 8 + 1, np.uint8)
    if not _pack10_into(v, out, 0, out.size - 1):
        out[out.size - 1] = 0xFF
    return out


@njit(cache=True)
def _pack10_into(v, out, o, stop):
    """Pack uint16 ``v`` LSB first into the zeroed bytes ``out[o:stop]``; False at the first
    value above 1023 (the packing stops there)."""
    for i in range(v.size):
        if v[i] > 0x3FF:
            return False
        bit = 10 * i
        byte = o + (bit >> 3)
        word = np.uint32(v[i]) << (bit & 7)
        out[byte] |= np.uint8(word & 0xFF)
        if byte + 1 < stop:
            out[byte + 1] |= np.uint8((word >> 8) & 0xFF)
    return True


def unpack10(data: bytes, n: int) -> np.ndarray:
    """Inverse of :func:`pack10`: ``n`` uint16 values."""
    need = (10 * n + 7) // 8
    if len(data) < need:
        raise PayloadError(f"{n} packed 10-bit pixels need {need} bytes, got {len(data)}")
    return unpack10_kernel(np.frombuffer(data, dtype=np.uint8, count=need), n)


@njit(cache=True)
def unpack10_kernel(b, n):
    """Bit-stream unpack of ``n`` 10-bit values from uint8 ``b`` (LSB first)."""
    out = np.empty(n, np.uint16)
    _unpack10_from(b, 0, b.size, n, out, 0)
    return out


@njit(cache=True)
def _unpack10_from(b, o, stop, n, out, p):
    """``out[p:p + n]`` = the ``n`` 10-bit values packed LSB first in ``b[o:stop]``."""
    for i in range(n):
        bit = 10 * i
        byte = o + (bit >> 3)
        word = np.uint32(b[byte])
        if byte + 1 < stop:
            word |= np.uint32(b[byte + 1]) << 8
        out[p + i] = (word >> (bit & 7)) & 0x3FF


def pixel_bytes(n: int, pixel_format: int) -> int:
    """Bytes that ``n`` pixels take in ``pixel_format``."""
    return 2 * n if pixel_format == PixelFormat.U16 else (10 * n + 7) // 8


def encode_pixels(values, pixel_format: int) -> bytes:
    """Pixels (≤ 1023 for PACKED10) in a wire format."""
    if pixel_format == PixelFormat.U16:
        return np.asarray(values, dtype="<u2").tobytes()
    if pixel_format == PixelFormat.PACKED10:
        return pack10(values)
    raise ProtocolUsageError(f"unknown pixel format {pixel_format}")


def decode_pixels(data: bytes, n: int, pixel_format: int) -> np.ndarray:
    if pixel_format == PixelFormat.U16:
        if len(data) < 2 * n:
            raise PayloadError(f"{n} 16-bit pixels need {2 * n} bytes, got {len(data)}")
        return np.frombuffer(bytes(data[: 2 * n]), dtype="<u2").astype(np.uint16)
    if pixel_format == PixelFormat.PACKED10:
        return unpack10(data, n)
    raise PayloadError(f"unknown pixel format {pixel_format} in reply")


def _decode_windows(fields: dict, tail: bytes) -> list[WindowPixels]:
    fmt = fields["pixel_format"]
    count = fields["count"]
    if count and fmt not in (PixelFormat.U16, PixelFormat.PACKED10):
        raise PayloadError(f"unknown pixel format {fmt} in reply")
    status, wid, n, left, ids, sums, bounds, pixels = windows_tail_decode(
        np.frombuffer(tail, dtype=np.uint8), count, fmt == PixelFormat.PACKED10)
    if status == _TAIL_IN_HEADER:
        raise PayloadError("window data ends inside a window header")
    if status == _TAIL_SHORT:
        raise PayloadError(f"window {wid}: {n} pixels need {pixel_bytes(n, fmt)} bytes, {left} left")
    if status == _TAIL_EXTRA:
        raise PayloadError(f"window data has {left} bytes after its last window")
    b = bounds.tolist()
    return [WindowPixels(w, t, pixels[b[j]:b[j + 1]]) for j, (w, t) in enumerate(zip(ids.tolist(), sums.tolist()))]


_TAIL_OK, _TAIL_IN_HEADER, _TAIL_SHORT, _TAIL_EXTRA = range(4)


@njit(cache=True)
def windows_tail_decode(tail, count, packed):
    """Windows of a WINDOW_DATA/FRAME tail (uint8): ``(status, window id, pixel count, bytes
    left, ids (k,), sums (k,), pixel bounds (k + 1,), pixels uint16)``; status ``_TAIL_OK`` or
    the first fault in wire order: a header cut short, a window's pixels cut short (its id,
    count and the bytes left), bytes after the last window."""
    ids = np.zeros(count, np.int64)
    sums = np.zeros(count, np.int64)
    bounds = np.zeros(count + 1, np.int64)
    starts = np.zeros(count, np.int64)
    off = 0
    for j in range(count):
        if off + 8 > tail.size:
            return _TAIL_IN_HEADER, 0, 0, 0, ids, sums, bounds, np.zeros(0, np.uint16)
        wid = np.int64(tail[off]) | (np.int64(tail[off + 1]) << 8)
        n = np.int64(tail[off + 2]) | (np.int64(tail[off + 3]) << 8)
        total = (np.int64(tail[off + 4]) | (np.int64(tail[off + 5]) << 8) | (np.int64(tail[off + 6]) << 16)
                 | (np.int64(tail[off + 7]) << 24))
        off += 8
        nbytes = (10 * n + 7) // 8 if packed else 2 * n
        if off + nbytes > tail.size:
            return _TAIL_SHORT, wid, n, tail.size - off, ids, sums, bounds, np.zeros(0, np.uint16)
        ids[j] = wid
        sums[j] = total
        starts[j] = off
        bounds[j + 1] = bounds[j] + n
        off += nbytes
    if off != tail.size:
        return _TAIL_EXTRA, 0, 0, tail.size - off, ids, sums, bounds, np.zeros(0, np.uint16)
    pixels = np.empty(bounds[count], np.uint16)
    for j in range(count):
        o = starts[j]
        n = bounds[j + 1] - bounds[j]
        p = bounds[j]
        if packed:
            _unpack10_from(tail, o, o + (10 * n + 7) // 8, n, pixels, p)
        else:
            for i in range(n):
                pixels[p + i] = np.uint16(tail[o + 2 * i]) | (np.uint16(tail[o + 2 * i + 1]) << 8)
    return _TAIL_OK, 0, 0, 0, ids, sums, bounds, pixels


def decode_reply(frame: Frame, expect: int | None = None) -> dict:
    """Fields of a reply frame as a dict (plus ``echo``/``windows``/``pixels``/``spots`` tails).

    An ERROR frame raises the matching :class:`~gyrostar.protocol.errors.FirmwareError`;
    a reply of another type than ``expect`` | REPLY_FLAG, or a malformed payload, raises
    :class:`~gyrostar.protocol.errors.PayloadError`.
    """
    if frame.type == MsgType.ERROR:
        fmt, names = REPLY_LAYOUT[MsgType.ERROR]
        if len(frame.payload) != struct.calcsize("<" + fmt):
            raise PayloadError(f"ERROR reply of {len(frame.payload)} bytes")
        err = dict(zip(names, _struct((fmt, names)).unpack(frame.payload)))
        raise error_for(err["code"], err["request_type"], err["detail"])
    if not frame.type & REPLY_FLAG:
        raise PayloadError(f"frame type 0x{frame.type:02X} is a request, not a reply")
    try:
        msg_type = MsgType(frame.type & ~REPLY_FLAG)
    except ValueError:
        raise PayloadError(f"unknown reply type 0x{frame.type:02X}") from None
    if expect is not None and msg_type != expect:
        raise PayloadError(f"expected a {MsgType(expect).name} reply, got {msg_type.name}")
    fmt, names = REPLY_LAYOUT[msg_type]
    st = _struct((fmt, names))
    if len(frame.payload) < st.size:
        raise PayloadError(f"{msg_type.name} reply of {len(frame.payload)} bytes, fixed part is {st.size}")
    fields = dict(zip(names, st.unpack_from(frame.payload)))
    tail = frame.payload[st.size:]
    if msg_type == MsgType.PING:
        fields["echo"] = bytes(tail)
    elif msg_type in (MsgType.WINDOW_DATA, MsgType.FRAME):
        fields["windows"] = _decode_windows(fields, tail)
    elif msg_type == MsgType.FULL_FRAME:
        n, fmt_px = fields["count"], fields["pixel_format"]
        if len(tail) != pixel_bytes(n, fmt_px):
            raise PayloadError(f"FULL_FRAME: {n} pixels in {len(tail)} bytes")
        fields["pixels"] = decode_pixels(tail, n, fmt_px)
    elif msg_type == MsgType.FIND_SPOTS:
        fields["spots"] = decode_spots(fields, tail)
    elif tail:
        raise PayloadError(f"{msg_type.name} reply has {len(tail)} unexpected trailing bytes")
    return fields


def decode_spots(fields: dict, tail: bytes) -> np.ndarray:
    """FIND_SPOTS tail → (n, 3) int32 array of [row, col, flux] (window ids 1..n in order)."""
    n = fields["n_windows"]
    if len(tail) != _SPOT.size * n:
        raise PayloadError(f"FIND_SPOTS: {n} spots in {len(tail)} bytes")
    return np.frombuffer(tail, dtype="<u2").reshape(n, 3).astype(np.int32)


def encode_spots(spots) -> bytes:
    """FIND_SPOTS tail from rows of [row, col, flux] (for emulators and tests)."""
    a = np.asarray(spots, dtype=np.int64).reshape(-1, 3)
    if a.size and (a.min() < 0 or a.max() > 0xFFFF):
        raise ProtocolUsageError("FIND_SPOTS spot fields must fit u16")
    return a.astype("<u2").tobytes()


def encode_reply(msg_type: int, tail: bytes = b"", **fields) -> bytes:
    """Payload of a reply (for emulators and tests): the fixed fields then ``tail``."""
    msg_type = MsgType(msg_type)
    fmt, names = REPLY_LAYOUT[msg_type]
    values = [int(fields.get(n, 0)) for n in names]
    missing = [n for n in names if n not in fields and not n.startswith("reserved")]
    if missing:
        raise ProtocolUsageError(f"{msg_type.name} reply needs field(s) {missing}")
    return _struct((fmt, names)).pack(*values) + bytes(tail)


def encode_windows_tail(windows: list[WindowPixels], pixel_format: int) -> bytes:
    """WINDOW_DATA tail for a list of windows (for emulators and tests)."""
    if not windows:
        return b""
    pixels = [np.asarray(w.pixels) for w in windows]
    bounds = np.zeros(len(windows) + 1, np.int64)
    np.cumsum([p.size for p in pixels], out=bounds[1:])
    return encode_windows_arrays([w.window_id for w in windows], [w.sum for w in windows],
                                 np.concatenate(pixels), bounds, pixel_format)


def encode_windows_arrays(ids, sums, pixels, bounds, pixel_format: int) -> bytes:
    """WINDOW_DATA/FRAME tail of windows j = 0..k−1: ids (k,), pixel sums (k,), their pixels
    ``pixels[bounds[j]:bounds[j + 1]]`` (span order; ≤ 1023 for PACKED10)."""
    if pixel_format not in (PixelFormat.U16, PixelFormat.PACKED10):
        raise ProtocolUsageError(f"unknown pixel format {pixel_format}")
    ids = np.asarray(ids, dtype=np.int64)
    sums = np.asarray(sums, dtype=np.int64)
    px = np.asarray(pixels)
    if px.dtype != np.uint16 and px.size and (int(px.max()) > 0xFFFF or int(px.min()) < 0):
        raise ProtocolUsageError("pixel value outside 0..65535")
    out = _windows_tail_encode(ids, sums, np.ascontiguousarray(px, dtype=np.uint16).ravel(),
                               np.asarray(bounds, dtype=np.int64), pixel_format == PixelFormat.PACKED10)
    if out[-1] == _ENC_RANGE:
        raise ProtocolUsageError("window id, pixel count or sum does not fit its field (u16, u16, u32)")
    if out[-1] == _PACK10_BAD:
        raise ProtocolUsageError("pixel value outside 0..1023 cannot be packed in 10 bits")
    return out[:-1].tobytes()


_ENC_RANGE = 0xFE   # the encoder's trailing status byte: a header field does not fit


@njit(cache=True)
def _windows_tail_encode(ids, sums, pixels, bounds, packed):
    """Bytes of the windows' headers ``<HHI`` (id, pixel count, sum) and pixels (u16 LE, or
    the 10-bit LSB-first stream of :func:`pack10` per window), then one status byte: 0,
    ``_ENC_RANGE`` or ``_PACK10_BAD`` (the encoding stops there)."""
    k = ids.shape[0]
    size = 0
    for j in range(k):
        n = bounds[j + 1] - bounds[j]
        size += 8 + ((10 * n + 7) // 8 if packed else 2 * n)
    out = np.zeros(size + 1, np.uint8)
    o = 0
    for j in range(k):
        n = bounds[j + 1] - bounds[j]
        if ids[j] < 0 or ids[j] > 0xFFFF or n > 0xFFFF or sums[j] < 0 or sums[j] > 0xFFFFFFFF:
            out[size] = _ENC_RANGE
            return out
        out[o] = ids[j] & 0xFF
        out[o + 1] = (ids[j] >> 8) & 0xFF
        out[o + 2] = n & 0xFF
        out[o + 3] = (n >> 8) & 0xFF
        for b in range(4):
            out[o + 4 + b] = (sums[j] >> (8 * b)) & 0xFF
        o += 8
        p = bounds[j]
        if packed:
            nb = (10 * n + 7) // 8
            if not _pack10_into(pixels[p:p + n], out, o, o + nb):
                out[size] = _PACK10_BAD
                return out
            o += nb
        else:
            for i in range(n):
                out[o + 2 * i] = pixels[p + i] & 0xFF
                out[o + 2 * i + 1] = pixels[p + i] >> 8
            o += 2 * n
    return out


def spans_pixel_count(spans) -> int:
    """Number of pixels covered by an N×4 span array."""
    arr = np.asarray(spans, dtype=np.int64).reshape(-1, 4)
    return int((arr[:, 3] - arr[:, 2]).sum())


def decode_request(frame: Frame) -> dict:
    """Fields of a request frame (for emulators and tests), plus ``tail`` bytes.

    SET_WINDOWS adds ``spans`` (N×4 int32) when the tail is a whole number of spans.
    """
    try:
        msg_type = MsgType(frame.type)
    except ValueError:
        raise PayloadError(f"unknown request type 0x{frame.type:02X}") from None
    if msg_type not in REQUEST_LAYOUT:
        raise PayloadError(f"{msg_type.name} is reply-only")
    st = _struct(REQUEST_LAYOUT[msg_type])
    if len(frame.payload) < st.size:
        raise PayloadError(f"{msg_type.name} request of {len(frame.payload)} bytes, fixed part is {st.size}")
    fields = dict(zip(REQUEST_LAYOUT[msg_type][1], st.unpack_from(frame.payload)))
    fields["tail"] = bytes(frame.payload[st.size:])
    if msg_type == MsgType.SET_WINDOWS and len(fields["tail"]) % _SPAN.size == 0:
        fields["spans"] = decode_spans(fields["tail"])
    return fields
