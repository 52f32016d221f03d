"""Protocol constants and payload layouts — GENERATED from firmware/proto/protocol.toml
by ``python -m gyrostar.fwtools.protogen --write``. Do not edit."""

from enum import IntEnum

VERSION = 2
HEADER_SIZE = 6
CRC_SIZE = 4
REPLY_FLAG = 128
MAX_PAYLOAD = 4160
PING_MAX = 256
CRC_CHECK = 0xE3069283
SENSOR_DEFAULT = {'width': 1024, 'height': 1024, 'bits': 10}
LIMITS = {
    'max_windows': 64,
    'max_spans': 512,
    'max_window_pixels': 2048,
    'pixel_budget': 8192,
    'frame_chunk_max': 2048,
    'exposure_min_us': 10,
    'exposure_max_us': 1000000,
    'exposure_default_us': 10000,
    'gain_min_x16': 16,
    'gain_max_x16': 128,
    'gain_default_x16': 16,
    'stream_period_min_us': 1000,
    'stream_period_max_us': 1000000,
    'stream_pending_sets': 2,
    'stream_tx_backlog_max': 256,
    'spot_width_max': 1024,
    'spot_box_max': 15,
    'spot_grid': 7,
}


class PixelFormat(IntEnum):
    """Pixel encodings on the wire."""

    U16 = 0
    PACKED10 = 1


class Plane(IntEnum):
    """Image planes of the sensor."""

    LIGHT = 0
    DARK = 1


class MsgType(IntEnum):
    """Request message types (a reply is type | REPLY_FLAG; ERROR is reply-only)."""

    PING = 0x01
    GET_INFO = 0x02
    SET_EXPOSURE = 0x03
    SET_GAIN = 0x04
    SET_WINDOWS = 0x05
    CAPTURE = 0x06
    WINDOW_DATA = 0x07
    FULL_FRAME = 0x08
    DARK = 0x09
    TIME_SYNC = 0x0A
    TELEMETRY = 0x0B
    RESET = 0x0C
    START_STREAM = 0x0D
    STOP_STREAM = 0x0E
    FRAME = 0x0F
    FIND_SPOTS = 0x10
    ERROR = 0xFF


class ErrorCode(IntEnum):
    """Firmware rejection codes (ERROR reply `code`)."""

    BAD_VERSION = 1
    UNKNOWN_TYPE = 2
    FRAME_LENGTH = 3
    PAYLOAD_LENGTH = 4
    EXPOSURE_RANGE = 5
    GAIN_RANGE = 6
    SPAN_COUNT = 7
    SPANS_LENGTH = 8
    SPAN_OUTSIDE = 9
    SPAN_EMPTY = 10
    SPAN_ORDER = 11
    WINDOW_COUNT = 12
    WINDOW_TOO_LARGE = 13
    PIXEL_BUDGET = 14
    NO_WINDOWS = 15
    NO_CAPTURE = 16
    WINDOW_INDEX = 17
    PIXEL_FORMAT = 18
    FRAME_RANGE = 19
    CHUNK_SIZE = 20
    BAD_PLANE = 21
    DARK_UNAVAILABLE = 22
    SENSOR_IO = 23
    SENSOR_BUSY = 24
    RESERVED_NONZERO = 25
    STREAM_PERIOD = 26
    STREAMING = 27
    SPOT_SETTINGS = 28
    SENSOR_TOO_WIDE = 29


ERROR_TEXT = {
    ErrorCode.BAD_VERSION: "protocol version in the header is not the firmware's",
    ErrorCode.UNKNOWN_TYPE: 'unknown or reply-only message type',
    ErrorCode.FRAME_LENGTH: "header length field disagrees with the frame's payload size",
    ErrorCode.PAYLOAD_LENGTH: 'payload length is wrong for this message type',
    ErrorCode.EXPOSURE_RANGE: "exposure time outside the firmware's limits",
    ErrorCode.GAIN_RANGE: "gain outside the firmware's limits",
    ErrorCode.SPAN_COUNT: 'more spans than the span table holds',
    ErrorCode.SPANS_LENGTH: 'n_spans disagrees with the SET_WINDOWS payload length',
    ErrorCode.SPAN_OUTSIDE: 'a span leaves the sensor (row >= height or col_stop > width)',
    ErrorCode.SPAN_EMPTY: 'a span has col_start >= col_stop',
    ErrorCode.SPAN_ORDER: 'spans are not sorted by (window_id, row) or a row repeats within a window',
    ErrorCode.WINDOW_COUNT: 'more windows than the firmware tracks',
    ErrorCode.WINDOW_TOO_LARGE: 'one window has more pixels than max_window_pixels',
    ErrorCode.PIXEL_BUDGET: 'all windows together exceed the pixel budget',
    ErrorCode.NO_WINDOWS: 'capture requested with no windows set',
    ErrorCode.NO_CAPTURE: 'window data requested before any capture',
    ErrorCode.WINDOW_INDEX: 'window start index beyond the captured windows',
    ErrorCode.PIXEL_FORMAT: 'unknown pixel format',
    ErrorCode.FRAME_RANGE: 'full-frame chunk leaves the sensor',
    ErrorCode.CHUNK_SIZE: 'full-frame chunk is empty or larger than frame_chunk_max',
    ErrorCode.BAD_PLANE: 'unknown image plane',
    ErrorCode.DARK_UNAVAILABLE: 'the sensor has no dark plane',
    ErrorCode.SENSOR_IO: 'the sensor array could not be read',
    ErrorCode.SENSOR_BUSY: 'no stable sensor frame (the frame kept changing during readout)',
    ErrorCode.RESERVED_NONZERO: 'a reserved field is not zero',
    ErrorCode.STREAM_PERIOD: 'stream period outside the limits or shorter than the exposure',
    ErrorCode.STREAMING: 'not available while the head streams (STOP_STREAM first)',
    ErrorCode.SPOT_SETTINGS: 'FIND_SPOTS setting outside the limits (detail: 1 n_sigma 2 max_spots 3 box 4 spans 5 px)',
    ErrorCode.SENSOR_TOO_WIDE: 'the sensor rows are wider than the FIND_SPOTS scan buffers (spot_width_max)',
}

# (struct format without byte-order prefix, field names) of each payload's fixed part.
REQUEST_LAYOUT = {
    MsgType.PING: ('', (
    )),
    MsgType.GET_INFO: ('', (
    )),
    MsgType.SET_EXPOSURE: ('I', (
        'exposure_us',
    )),
    MsgType.SET_GAIN: ('H', (
        'gain_x16',
    )),
    MsgType.SET_WINDOWS: ('HHI', (
        'n_spans', 'reserved', 'frame',
    )),
    MsgType.CAPTURE: ('', (
    )),
    MsgType.WINDOW_DATA: ('HBB', (
        'start', 'pixel_format', 'reserved',
    )),
    MsgType.FULL_FRAME: ('IHBB', (
        'offset', 'count', 'pixel_format', 'plane',
    )),
    MsgType.DARK: ('', (
    )),
    MsgType.TIME_SYNC: ('Q', (
        'host_us',
    )),
    MsgType.TELEMETRY: ('', (
    )),
    MsgType.RESET: ('', (
    )),
    MsgType.START_STREAM: ('IIBBH', (
        'period_us', 'exposure_us', 'pixel_format', 'reserved', 'reserved2',
    )),
    MsgType.STOP_STREAM: ('', (
    )),
    MsgType.FIND_SPOTS: ('HHBBH', (
        'n_sigma_x16', 'max_spots', 'box', 'reserved', 'reserved2',
    )),
}
REPLY_LAYOUT = {
    MsgType.PING: ('', (
    )),
    MsgType.GET_INFO: ('BBBBHHBBHHHIHHIIHHBB', (
        'proto_version', 'fw_major', 'fw_minor', 'fw_patch', 'width', 'height', 'bits', 'port',
        'max_windows', 'max_spans', 'max_window_pixels', 'pixel_budget', 'max_payload',
        'frame_chunk_max', 'exposure_min_us', 'exposure_max_us', 'gain_min_x16', 'gain_max_x16',
        'planes', 'reserved',
    )),
    MsgType.SET_EXPOSURE: ('I', (
        'exposure_us',
    )),
    MsgType.SET_GAIN: ('H', (
        'gain_x16',
    )),
    MsgType.SET_WINDOWS: ('HHII', (
        'n_windows', 'n_spans', 'n_pixels', 'frame',
    )),
    MsgType.CAPTURE: ('IIQQIHHIBBH', (
        'capture_no', 'sensor_frame', 't_start_us', 't_end_us', 'exposure_us', 'gain_x16',
        'n_windows', 'n_pixels', 'plane', 'reserved', 'reserved2',
    )),
    MsgType.WINDOW_DATA: ('IHHHBB', (
        'capture_no', 'start', 'count', 'total', 'pixel_format', 'reserved',
    )),
    MsgType.FULL_FRAME: ('IIHBB', (
        'sensor_frame', 'offset', 'count', 'pixel_format', 'plane',
    )),
    MsgType.DARK: ('IIQQIHHIBBH', (
        'capture_no', 'sensor_frame', 't_start_us', 't_end_us', 'exposure_us', 'gain_x16',
        'n_windows', 'n_pixels', 'plane', 'reserved', 'reserved2',
    )),
    MsgType.TIME_SYNC: ('QQQ', (
        'host_us', 'mcu_rx_us', 'mcu_tx_us',
    )),
    MsgType.TELEMETRY: ('QhHIIIIII', (
        'uptime_us', 'temperature_cdeg', 'last_error', 'captures', 'rx_frames', 'crc_errors',
        'framing_errors', 'overruns', 'rejected',
    )),
    MsgType.RESET: ('', (
    )),
    MsgType.START_STREAM: ('IQII', (
        'first_frame', 't_first_us', 'period_us', 'exposure_us',
    )),
    MsgType.STOP_STREAM: ('IIIII', (
        'frames', 'last_frame', 'dropped', 'late_sets', 'backpressure',
    )),
    MsgType.FRAME: ('IIQQIIIIIHHHBB', (
        'frame', 'set_frame', 't_start_us', 't_end_us', 'exposure_us', 'late_sets', 'dropped',
        'backpressure', 'n_pixels', 'start', 'count', 'total', 'pixel_format', 'reserved',
    )),
    MsgType.FIND_SPOTS: ('IIQQIHHIIIII', (
        'capture_no', 'sensor_frame', 't_start_us', 't_end_us', 'exposure_us', 'gain_x16',
        'n_windows', 'n_pixels', 'candidates', 'background_x16', 'sigma_x16', 'threshold_x16',
    )),
    MsgType.ERROR: ('HBBI', (
        'code', 'request_type', 'reserved', 'detail',
    )),
}
TAIL = {
    MsgType.PING: 'echo',
    MsgType.SET_WINDOWS: 'spans',
    MsgType.WINDOW_DATA: 'windows',
    MsgType.FULL_FRAME: 'pixels',
    MsgType.FRAME: 'windows',
    MsgType.FIND_SPOTS: 'spots',
}
