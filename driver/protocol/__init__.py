"""gyrostar head link protocol (the Python side of firmware/proto/protocol.toml).

* :mod:`.defs` — generated constants: message types, error codes, limits, payload layouts.
* :mod:`.framing` — COBS + header + CRC-32C frames; :class:`StreamDecoder` for byte streams.
* :mod:`.payloads` — encode requests / decode replies per message; window spans; pixels.
* :mod:`.errors` — one :class:`~gyrostar.errors.DeviceError` subclass per firmware error code.
"""

from .defs import ErrorCode, MsgType, PixelFormat, Plane
from .errors import FirmwareError, FrameError, error_for
from .framing import Frame, StreamDecoder, crc32c, decode_frame, encode_frame
from .payloads import decode_reply, encode_request

__all__ = ["ErrorCode", "MsgType", "PixelFormat", "Plane", "FirmwareError", "FrameError", "error_for",
           "Frame", "StreamDecoder", "crc32c", "decode_frame", "encode_frame", "decode_reply",
           "encode_request"]
