"""Exceptions of the head link: framing faults and one class per firmware error code.

``FrameError`` (and subclasses) mean bytes on the link were not a valid frame.
``FirmwareError`` subclasses — ``BadVersionError``, ``SpanOutsideError``, … one per
:class:`~gyrostar.protocol.defs.ErrorCode` — mean the firmware rejected a request; each
carries ``code``, ``request_type`` and ``detail`` (e.g. the offending span index).
"""

from __future__ import annotations

from ..errors import DeviceError, GyrostarError
from .defs import ERROR_TEXT, ErrorCode, MsgType


class FrameError(DeviceError):
    """Bytes between two delimiters are not a valid frame."""


class CobsError(FrameError):
    """COBS decoding failed (bad code byte or an embedded zero)."""


class ShortFrameError(FrameError):
    """Decoded frame shorter than header + CRC."""


class CrcError(FrameError):
    """CRC-32C trailer does not match header + payload."""


class LengthMismatchError(FrameError):
    """Header length field disagrees with the payload bytes present."""


class VersionError(FrameError):
    """Frame carries a protocol version this driver does not speak."""


class PayloadError(DeviceError):
    """A reply payload does not have the layout its message type requires."""


class FirmwareError(DeviceError):
    """The firmware rejected a request with an ERROR reply."""

    code: ErrorCode

    def __init__(self, request_type: int = 0, detail: int = 0):
        self.request_type = request_type
        self.detail = detail
        try:
            req = MsgType(request_type).name
        except ValueError:
            req = f"type 0x{request_type:02X}"
        super().__init__(f"firmware rejected {req}: {ERROR_TEXT[self.code]} "
                         f"(error {int(self.code)} {self.code.name}, detail {detail})")


def _class_name(code: ErrorCode) -> str:
    return "".join(part.capitalize() for part in code.name.split("_")) + "Error"


FIRMWARE_ERRORS: dict[int, type[FirmwareError]] = {}
for _code in ErrorCode:
    _cls = type(_class_name(_code), (FirmwareError,),
                {"code": _code, "__doc__": f"Firmware error {int(_code)}: {ERROR_TEXT[_code]}.",
                 "__module__": __name__})
    globals()[_cls.__name__] = _cls
    FIRMWARE_ERRORS[int(_code)] = _cls


class UnknownFirmwareError(FirmwareError):
    """An ERROR reply whose code this driver does not know (newer firmware)."""

    def __init__(self, code: int, request_type: int = 0, detail: int = 0):
        self.code = code
        self.request_type = request_type
        self.detail = detail
        DeviceError.__init__(self, f"firmware rejected type 0x{request_type:02X} with unknown error "
                                   f"code {code} (detail {detail})")


def error_for(code: int, request_type: int = 0, detail: int = 0) -> FirmwareError:
    """The exception instance for a firmware ERROR reply."""
    cls = FIRMWARE_ERRORS.get(code)
    if cls is None:
        return UnknownFirmwareError(code, request_type, detail)
    return cls(request_type, detail)


class ProtocolUsageError(GyrostarError, ValueError):
    """A request cannot be encoded (missing field, value does not fit its type)."""
