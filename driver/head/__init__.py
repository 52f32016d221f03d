"""Camera-head client: request/response with retries, streamed frames, MCU↔host time sync."""

from .client import Capture, HeadClient, HeadTimeoutError
from .stream import StreamFrame
from .timesync import ClockSync

__all__ = ["HeadClient", "HeadTimeoutError", "Capture", "ClockSync", "StreamFrame"]
