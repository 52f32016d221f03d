"""Frames on the head link: COBS(header || payload || CRC-32C) followed by 0x00.

Header (little-endian): version u8, type u8, seq u16, length u16. The CRC-32C
(Castagnoli; check value 0xE3069283 over b"123456789") covers header and payload and is
appended as u32 LE before COBS encoding.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import crc32c as _crc32c
from cobs import cobs

from .defs import CRC_SIZE, HEADER_SIZE, MAX_PAYLOAD, VERSION
from .errors import CobsError, CrcError, FrameError, LengthMismatchError, ShortFrameError, VersionError

_HEADER = struct.Struct("<BBHH")
_CRC = struct.Struct("<I")
MAX_RAW = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
MAX_ENCODED = MAX_RAW + MAX_RAW // 254 + 1  # COBS worst case, without the delimiter


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli) of ``data`` as an unsigned 32-bit integer."""
    return _crc32c.crc32c(data)


@dataclass(frozen=True)
class Frame:
    """One decoded frame: message type, sequence number and payload bytes."""

    type: int
    seq: int
    payload: bytes
    version: int = VERSION


def encode_frame(msg_type: int, seq: int, payload: bytes = b"", version: int = VERSION) -> bytes:
    """The bytes on the wire for one frame, trailing 0x00 delimiter included."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds the protocol maximum {MAX_PAYLOAD}")
    raw = _HEADER.pack(version, msg_type & 0xFF, seq & 0xFFFF, len(payload)) + bytes(payload)
    raw += _CRC.pack(crc32c(raw))
    return cobs.encode(raw) + b"\x00"


def decode_frame(encoded: bytes, check_version: bool = True) -> Frame:
    """Decode the bytes between two delimiters (no 0x00 included); raise a FrameError subclass."""
    try:
        raw = cobs.decode(bytes(encoded))
    except cobs.DecodeError as exc:
        raise CobsError(f"COBS decoding failed: {exc}") from None
    if len(raw) < HEADER_SIZE + CRC_SIZE:
        raise ShortFrameError(f"frame of {len(raw)} bytes is shorter than header + CRC "
                              f"({HEADER_SIZE + CRC_SIZE})")
    body, (crc,) = raw[:-CRC_SIZE], _CRC.unpack(raw[-CRC_SIZE:])
    calc = crc32c(body)
    if calc != crc:
        raise CrcError(f"CRC-32C mismatch: frame says 0x{crc:08X}, computed 0x{calc:08X}")
    version, msg_type, seq, length = _HEADER.unpack(body[:HEADER_SIZE])
    payload = body[HEADER_SIZE:]
    if length != len(payload):
        raise LengthMismatchError(f"header length {length} but {len(payload)} payload bytes")
    if check_version and version != VERSION:
        raise VersionError(f"protocol version {version}, this driver speaks {VERSION}")
    return Frame(msg_type, seq, payload, version)


class StreamDecoder:
    """Split a byte stream into frames at 0x00; drop and count corrupt ones.

    ``feed(data)`` returns the complete valid frames. A corrupt frame is dropped, counted
    in ``corrupt`` (and ``errors`` by exception class name, ``last_error`` keeps the last
    one) and decoding resumes after the next delimiter. Bytes beyond the longest legal
    frame are discarded up to the next delimiter and counted in ``overruns``.
    """

    def __init__(self, max_encoded: int = MAX_ENCODED):
        self.max_encoded = max_encoded
        self._buf = bytearray()
        self._discarding = False
        self.frames = 0
        self.corrupt = 0
        self.overruns = 0
        self.errors: dict[str, int] = {}
        self.last_error: FrameError | None = None

    def feed(self, data: bytes) -> list[Frame]:
        out: list[Frame] = []
        start = 0
        while start < len(data):
            end = data.find(b"\x00", start)
            chunk = data[start:] if end < 0 else data[start:end]
            if not self._discarding:
                self._buf += chunk
                if len(self._buf) > self.max_encoded:
                    self._buf.clear()
                    self._discarding = True
                    self.overruns += 1
            if end < 0:
                break
            if not self._discarding and self._buf:
                self._finish(out)
            self._buf.clear()
            self._discarding = False
            start = end + 1
        return out

    def _finish(self, out: list[Frame]) -> None:
        try:
            out.append(decode_frame(self._buf))
            self.frames += 1
        except FrameError as exc:
            self.corrupt += 1
            name = type(exc).__name__
            self.errors[name] = self.errors.get(name, 0) + 1
            self.last_error = exc

    @property
    def pending(self) -> int:
        """Bytes buffered towards an incomplete frame."""
        return len(self._buf)
