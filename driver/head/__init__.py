"""Camera-head client: request/response with retries, streamed frames, MCU↔host time sync."""

from .client import Capture, HeadClient, HeadClockError, HeadTimeoutError, SpotCapture
from .stream import StreamFrame
from .timesync import ClockSync

__all__ = ["HeadClient", "HeadTimeoutError", "HeadClockError", "Capture", "SpotCapture", "ClockSync", "StreamFrame"]
