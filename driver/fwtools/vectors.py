"""Golden test vectors of the head link, shared by the C and the Python test suites.

``python -m gyrostar.fwtools.vectors --write`` writes ``firmware/proto/vectors.json``;
without ``--write`` it exits 1 if the file differs from what this module builds.

Sections (hex strings are the exact bytes):
* ``crc``: data → CRC-32C (includes the 0xE3069283 check value).
* ``cobs``: raw → encoded (hand examples from the COBS paper / Wikipedia, no delimiter).
* ``frames``: message (type, seq, payload, decoded ``fields``) → framed bytes incl. 0x00.
* ``corrupt``: frames that must be rejected, with the reason (``cobs``, ``short``, ``crc``,
  ``length``, ``version``; ``length`` and ``version`` frames have valid CRCs).
* ``stream``: garbage, corrupt and valid frames concatenated; the decoder must return the
  listed frames and count ``corrupt`` rejections.
* ``exchanges``: request → exact reply of a freshly booted head (1024×1024 sensor with a
  dark plane, port 0) for every command whose reply does not depend on the clock or the
  pixels, and for every rejection reachable from a single request.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys

from ..protocol import defs, payloads
from ..protocol.defs import ErrorCode, MsgType, PixelFormat, Plane
from ..protocol.framing import crc32c, encode_frame
from .protogen import repo_root

VECTORS_REL = "firmware/proto/vectors.json"
_HDR = struct.Struct("<BBHH")
L = defs.LIMITS


def _raw_frame(raw: bytes) -> bytes:
    from cobs import cobs
    return cobs.encode(raw) + b"\x00"


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack("<I", crc32c(body))


def _frame_entry(name: str, msg_type: int, seq: int, payload: bytes, fields: dict | None = None) -> dict:
    entry = {"name": name, "type": int(msg_type), "seq": seq, "payload": payload.hex(),
             "frame": encode_frame(msg_type, seq, payload).hex()}
    if fields is not None:
        entry["fields"] = fields
    return entry


def _reply(msg_type: int, seq: int, tail: bytes = b"", **fields) -> bytes:
    return encode_frame(int(msg_type) | defs.REPLY_FLAG, seq, payloads.encode_reply(msg_type, tail, **fields))


def _error(seq: int, code: ErrorCode, request_type: int, detail: int = 0) -> bytes:
    payload = payloads.encode_reply(MsgType.ERROR, code=code, request_type=request_type, detail=detail)
    return encode_frame(MsgType.ERROR, seq, payload)


def _info_fields() -> dict:
    s = defs.SENSOR_DEFAULT
    return dict(proto_version=defs.VERSION, fw_major=1, fw_minor=0, fw_patch=0, width=s["width"],
                height=s["height"], bits=s["bits"], port=0, max_windows=L["max_windows"],
                max_spans=L["max_spans"], max_window_pixels=L["max_window_pixels"],
                pixel_budget=L["pixel_budget"], max_payload=defs.MAX_PAYLOAD,
                frame_chunk_max=L["frame_chunk_max"], exposure_min_us=L["exposure_min_us"],
                exposure_max_us=L["exposure_max_us"], gain_min_x16=L["gain_min_x16"],
                gain_max_x16=L["gain_max_x16"], planes=2)


def _spans_req(seq: int, spans, n_spans: int | None = None, extra: bytes = b"", reserved: int = 0,
               frame: int = 0) -> bytes:
    body = payloads.encode_spans(spans, frame=frame) + extra
    if n_spans is not None or reserved:
        n = len(spans) if n_spans is None else n_spans
        body = struct.pack("<HHI", n, reserved, frame) + body[8:]
    return encode_frame(MsgType.SET_WINDOWS, seq, body)


def _stream_req(seq: int, period_us: int, exposure_us: int, pixel_format: int = PixelFormat.PACKED10,
                reserved: int = 0) -> bytes:
    return encode_frame(MsgType.START_STREAM, seq, struct.pack("<IIBBH", period_us, exposure_us, pixel_format,
                                                               reserved, 0))


def _exchanges() -> list[dict]:
    W = defs.SENSOR_DEFAULT["width"]
    H = defs.SENSOR_DEFAULT["height"]
    ex: list[dict] = []

    def add(name, request: bytes, reply: bytes, expect: dict | None = None):
        ex.append({"name": name, "request": request.hex(), "reply": reply.hex(), "expect": expect or {}})

    def reject(name, request: bytes, seq: int, code: ErrorCode, rtype: int, detail: int = 0):
        add(name, request, _error(seq, code, rtype, detail),
            {"error": code.name, "request_type": int(rtype), "detail": detail})

    add("ping", encode_frame(MsgType.PING, 1, b"hello"), _reply(MsgType.PING, 1, b"hello"), {"echo": b"hello".hex()})
    add("ping_empty", encode_frame(MsgType.PING, 2), _reply(MsgType.PING, 2))
    add("get_info", encode_frame(MsgType.GET_INFO, 3), _reply(MsgType.GET_INFO, 3, **_info_fields()),
        _info_fields())
    add("set_exposure", encode_frame(MsgType.SET_EXPOSURE, 4, struct.pack("<I", 10000)),
        _reply(MsgType.SET_EXPOSURE, 4, exposure_us=10000), {"exposure_us": 10000})
    add("set_gain", encode_frame(MsgType.SET_GAIN, 5, struct.pack("<H", 32)),
        _reply(MsgType.SET_GAIN, 5, gain_x16=32), {"gain_x16": 32})
    spans = [[3, 10, 20, 26], [3, 11, 20, 27], [7, 500, 1018, 1024]]
    add("set_windows", _spans_req(6, spans),
        _reply(MsgType.SET_WINDOWS, 6, n_windows=2, n_spans=3, n_pixels=19, frame=0),
        {"n_windows": 2, "n_spans": 3, "n_pixels": 19})
    add("set_windows_clear", _spans_req(7, []),
        _reply(MsgType.SET_WINDOWS, 7, n_windows=0, n_spans=0, n_pixels=0, frame=0))
    # outside a stream the named frame is ignored: the set applies at once (reply frame 0)
    add("set_windows_frame_idle", _spans_req(10, spans, frame=77),
        _reply(MsgType.SET_WINDOWS, 10, n_windows=2, n_spans=3, n_pixels=19, frame=0),
        {"n_windows": 2, "n_spans": 3, "n_pixels": 19, "frame": 0})
    add("stop_stream_idle", encode_frame(MsgType.STOP_STREAM, 11),
        _reply(MsgType.STOP_STREAM, 11, frames=0, last_frame=0, dropped=0, late_sets=0, backpressure=0),
        {"frames": 0, "last_frame": 0, "dropped": 0, "late_sets": 0, "backpressure": 0})
    add("reset", encode_frame(MsgType.RESET, 8), _reply(MsgType.RESET, 8))
    ping_max = b"\xa5" * defs.PING_MAX
    add("ping_max", encode_frame(MsgType.PING, 9, ping_max), _reply(MsgType.PING, 9, ping_max))

    # every rejection reachable with one request
    reject("bad_version", encode_frame(MsgType.PING, 20, b"", version=defs.VERSION + 1), 20,
           ErrorCode.BAD_VERSION, MsgType.PING, defs.VERSION + 1)
    reject("unknown_type", encode_frame(0x42, 21), 21, ErrorCode.UNKNOWN_TYPE, 0x42)
    reject("reply_type_sent", encode_frame(MsgType.PING | defs.REPLY_FLAG, 22), 22, ErrorCode.UNKNOWN_TYPE,
           MsgType.PING | defs.REPLY_FLAG)
    reject("error_type_sent", encode_frame(MsgType.ERROR, 23), 23, ErrorCode.UNKNOWN_TYPE, MsgType.ERROR)
    bad_len = _raw_frame(_with_crc(_HDR.pack(defs.VERSION, MsgType.PING, 24, 3) + b"ab"))
    reject("frame_length", bad_len, 24, ErrorCode.FRAME_LENGTH, MsgType.PING, 3)
    reject("ping_too_long", encode_frame(MsgType.PING, 25, b"x" * (defs.PING_MAX + 1)), 25,
           ErrorCode.PAYLOAD_LENGTH, MsgType.PING, defs.PING_MAX + 1)
    for i, (mt, pl) in enumerate([(MsgType.GET_INFO, b"\x00"), (MsgType.SET_EXPOSURE, b"\x10\x27"),
                                  (MsgType.SET_GAIN, b"\x10\x00\x00"), (MsgType.SET_WINDOWS, b"\x00"),
                                  (MsgType.CAPTURE, b"\x01"), (MsgType.WINDOW_DATA, b"\x00\x00"),
                                  (MsgType.FULL_FRAME, b"\x00" * 7), (MsgType.DARK, b"\x00"),
                                  (MsgType.TIME_SYNC, b"\x00" * 4), (MsgType.TELEMETRY, b"\x00"),
                                  (MsgType.RESET, b"\x00"), (MsgType.START_STREAM, b"\x00" * 11),
                                  (MsgType.STOP_STREAM, b"\x00"), (MsgType.FIND_SPOTS, b"\x00" * 7)]):
        reject(f"payload_length_{mt.name.lower()}", encode_frame(mt, 30 + i, pl), 30 + i,
               ErrorCode.PAYLOAD_LENGTH, mt, len(pl))
    reject("exposure_low", encode_frame(MsgType.SET_EXPOSURE, 50, struct.pack("<I", L["exposure_min_us"] - 1)),
           50, ErrorCode.EXPOSURE_RANGE, MsgType.SET_EXPOSURE, L["exposure_min_us"] - 1)
    reject("exposure_high", encode_frame(MsgType.SET_EXPOSURE, 51, struct.pack("<I", L["exposure_max_us"] + 1)),
           51, ErrorCode.EXPOSURE_RANGE, MsgType.SET_EXPOSURE, L["exposure_max_us"] + 1)
    reject("gain_low", encode_frame(MsgType.SET_GAIN, 52, struct.pack("<H", L["gain_min_x16"] - 1)),
           52, ErrorCode.GAIN_RANGE, MsgType.SET_GAIN, L["gain_min_x16"] - 1)
    reject("gain_high", encode_frame(MsgType.SET_GAIN, 53, struct.pack("<H", L["gain_max_x16"] + 1)),
           53, ErrorCode.GAIN_RANGE, MsgType.SET_GAIN, L["gain_max_x16"] + 1)
    n_over = L["max_spans"] + 1
    reject("span_count", encode_frame(MsgType.SET_WINDOWS, 54, struct.pack("<HHI", n_over, 0, 0)), 54,
           ErrorCode.SPAN_COUNT, MsgType.SET_WINDOWS, n_over)
    reject("spans_length_short", _spans_req(55, spans, n_spans=4), 55, ErrorCode.SPANS_LENGTH,
           MsgType.SET_WINDOWS, 4)
    reject("spans_length_extra", _spans_req(56, spans, extra=b"\x01\x02"), 56, ErrorCode.SPANS_LENGTH,
           MsgType.SET_WINDOWS, 3)
    reject("windows_reserved", _spans_req(57, spans, reserved=1), 57, ErrorCode.RESERVED_NONZERO,
           MsgType.SET_WINDOWS, 1)
    reject("span_row_outside", _spans_req(58, [[1, 5, 0, 4], [1, H, 0, 4]]), 58, ErrorCode.SPAN_OUTSIDE,
           MsgType.SET_WINDOWS, 1)
    reject("span_col_outside", _spans_req(59, [[1, 5, W - 3, W + 1]]), 59, ErrorCode.SPAN_OUTSIDE,
           MsgType.SET_WINDOWS, 0)
    reject("span_empty", _spans_req(60, [[1, 5, 0, 4], [1, 6, 9, 9]]), 60, ErrorCode.SPAN_EMPTY,
           MsgType.SET_WINDOWS, 1)
    reject("span_reversed", _spans_req(61, [[1, 5, 9, 4]]), 61, ErrorCode.SPAN_EMPTY, MsgType.SET_WINDOWS, 0)
    reject("span_order_id", _spans_req(62, [[2, 5, 0, 4], [1, 6, 0, 4]]), 62, ErrorCode.SPAN_ORDER,
           MsgType.SET_WINDOWS, 1)
    reject("span_order_row", _spans_req(63, [[1, 6, 0, 4], [1, 5, 0, 4]]), 63, ErrorCode.SPAN_ORDER,
           MsgType.SET_WINDOWS, 1)
    reject("span_row_repeat", _spans_req(64, [[1, 6, 0, 4], [1, 6, 10, 14]]), 64, ErrorCode.SPAN_ORDER,
           MsgType.SET_WINDOWS, 1)
    many = [[i, 0, 0, 1] for i in range(L["max_windows"] + 1)]
    reject("window_count", _spans_req(65, many), 65, ErrorCode.WINDOW_COUNT, MsgType.SET_WINDOWS,
           L["max_windows"])
    big = [[1, r, 0, 1000] for r in range(3)]  # 3000 pixels > max_window_pixels
    reject("window_too_large", _spans_req(66, big), 66, ErrorCode.WINDOW_TOO_LARGE, MsgType.SET_WINDOWS, 2)
    budget = [[w, r, 0, 1000] for w in range(5) for r in range(2)]  # 10000 pixels > 8192
    reject("pixel_budget", _spans_req(67, budget), 67, ErrorCode.PIXEL_BUDGET, MsgType.SET_WINDOWS, 8)
    reject("capture_no_windows", encode_frame(MsgType.CAPTURE, 68), 68, ErrorCode.NO_WINDOWS, MsgType.CAPTURE)
    reject("dark_no_windows", encode_frame(MsgType.DARK, 69), 69, ErrorCode.NO_WINDOWS, MsgType.DARK)
    reject("window_data_no_capture", encode_frame(MsgType.WINDOW_DATA, 70, struct.pack("<HBB", 0, 0, 0)), 70,
           ErrorCode.NO_CAPTURE, MsgType.WINDOW_DATA)
    ff = struct.Struct("<IHBB")
    reject("frame_range", encode_frame(MsgType.FULL_FRAME, 71, ff.pack(W * H - 10, 11, 0, 0)), 71,
           ErrorCode.FRAME_RANGE, MsgType.FULL_FRAME, W * H - 10)
    reject("frame_chunk_zero", encode_frame(MsgType.FULL_FRAME, 72, ff.pack(0, 0, 0, 0)), 72,
           ErrorCode.CHUNK_SIZE, MsgType.FULL_FRAME, 0)
    reject("frame_chunk_big", encode_frame(MsgType.FULL_FRAME, 73, ff.pack(0, L["frame_chunk_max"] + 1, 0, 0)),
           73, ErrorCode.CHUNK_SIZE, MsgType.FULL_FRAME, L["frame_chunk_max"] + 1)
    reject("frame_format", encode_frame(MsgType.FULL_FRAME, 74, ff.pack(0, 16, 7, 0)), 74,
           ErrorCode.PIXEL_FORMAT, MsgType.FULL_FRAME, 7)
    reject("frame_plane", encode_frame(MsgType.FULL_FRAME, 75, ff.pack(0, 16, 0, 2)), 75,
           ErrorCode.BAD_PLANE, MsgType.FULL_FRAME, 2)
    # FIND_SPOTS checks in order reserved, n_sigma, max_spots, box, spans, pixels (detail: which)
    fs = struct.Struct("<HHBBH")
    reject("spots_reserved", encode_frame(MsgType.FIND_SPOTS, 76, fs.pack(96, 8, 7, 1, 0)), 76,
           ErrorCode.RESERVED_NONZERO, MsgType.FIND_SPOTS, 1)
    for i, (settings, detail) in enumerate([((0, 8, 7), 1), ((96, 0, 7), 2), ((96, L["max_windows"] + 1, 7), 2),
                                            ((96, 8, 6), 3), ((96, 8, 1), 3), ((96, 8, L["spot_box_max"] + 2), 3),
                                            ((96, 64, 9), 4)]):
        reject(f"spots_settings_{i}", encode_frame(MsgType.FIND_SPOTS, 90 + i, fs.pack(*settings, 0, 0)), 90 + i,
               ErrorCode.SPOT_SETTINGS, MsgType.FIND_SPOTS, detail)
    # streaming: START_STREAM checks in order reserved, exposure, period, pixel format
    reject("stream_reserved", _stream_req(80, 10000, 10000, reserved=1), 80, ErrorCode.RESERVED_NONZERO,
           MsgType.START_STREAM, 1)
    reject("stream_exposure_low", _stream_req(81, 10000, L["exposure_min_us"] - 1), 81, ErrorCode.EXPOSURE_RANGE,
           MsgType.START_STREAM, L["exposure_min_us"] - 1)
    reject("stream_period_short", _stream_req(82, L["stream_period_min_us"] - 1, 500), 82,
           ErrorCode.STREAM_PERIOD, MsgType.START_STREAM, L["stream_period_min_us"] - 1)
    reject("stream_period_long", _stream_req(83, L["stream_period_max_us"] + 1, 10000), 83,
           ErrorCode.STREAM_PERIOD, MsgType.START_STREAM, L["stream_period_max_us"] + 1)
    reject("stream_period_below_exposure", _stream_req(84, 9999, 10000), 84, ErrorCode.STREAM_PERIOD,
           MsgType.START_STREAM, 9999)
    reject("stream_pixel_format", _stream_req(85, 10000, 10000, pixel_format=2), 85, ErrorCode.PIXEL_FORMAT,
           MsgType.START_STREAM, 2)
    return ex


def build() -> dict:
    """The whole vector set as a JSON-ready dict."""
    crc = [{"data": d.hex(), "crc": crc32c(d)} for d in (b"123456789", b"", b"\x00", b"\xff" * 32)]
    cobs_cases = [("00", "0101"), ("0000", "010101"), ("11220033", "0311220233"), ("11223344", "0511223344"),
                  ("11000000", "0211010101"), ("01" + "".join(f"{i:02x}" for i in range(2, 255)),
                                             "ff01" + "".join(f"{i:02x}" for i in range(2, 255)))]
    frames = [
        _frame_entry("ping_req", MsgType.PING, 1, b"", {}),
        _frame_entry("ping_req_echo", MsgType.PING, 0xBEEF, b"\x00\x01\x00", {}),
        _frame_entry("set_exposure_req", MsgType.SET_EXPOSURE, 2, payloads.encode_request(
            MsgType.SET_EXPOSURE, exposure_us=12345), {"exposure_us": 12345}),
        _frame_entry("set_windows_req", MsgType.SET_WINDOWS, 3, payloads.encode_spans(
            [[0, 100, 200, 206], [0, 101, 200, 207]]), {"n_spans": 2}),
        _frame_entry("window_data_req", MsgType.WINDOW_DATA, 4, payloads.encode_request(
            MsgType.WINDOW_DATA, start=0, pixel_format=PixelFormat.PACKED10), {"start": 0, "pixel_format": 1}),
        _frame_entry("full_frame_req", MsgType.FULL_FRAME, 5, payloads.encode_request(
            MsgType.FULL_FRAME, offset=2048, count=1024, pixel_format=0, plane=Plane.DARK),
            {"offset": 2048, "count": 1024, "pixel_format": 0, "plane": 1}),
        _frame_entry("time_sync_req", MsgType.TIME_SYNC, 6, payloads.encode_request(
            MsgType.TIME_SYNC, host_us=1_700_000_000_123_456), {"host_us": 1_700_000_000_123_456}),
        _frame_entry("capture_rep", MsgType.CAPTURE | defs.REPLY_FLAG, 7, payloads.encode_reply(
            MsgType.CAPTURE, capture_no=9, sensor_frame=41, t_start_us=1_000_000, t_end_us=1_010_000,
            exposure_us=10000, gain_x16=16, n_windows=2, n_pixels=19, plane=0),
            {"capture_no": 9, "sensor_frame": 41, "t_start_us": 1_000_000, "t_end_us": 1_010_000,
             "exposure_us": 10000, "gain_x16": 16, "n_windows": 2, "n_pixels": 19, "plane": 0}),
        _frame_entry("window_data_rep_packed10", MsgType.WINDOW_DATA | defs.REPLY_FLAG, 8,
                     payloads.encode_reply(MsgType.WINDOW_DATA, payloads.encode_windows_tail(
                         [payloads.WindowPixels(3, 1023 + 1 + 512 + 7 + 0, [1023, 1, 512, 7, 0])], 1),
                         capture_no=9, start=0, count=1, total=1, pixel_format=1),
                     {"capture_no": 9, "start": 0, "count": 1, "total": 1, "pixel_format": 1,
                      "windows": [{"window_id": 3, "sum": 1543, "pixels": [1023, 1, 512, 7, 0]}]}),
        _frame_entry("telemetry_rep", MsgType.TELEMETRY | defs.REPLY_FLAG, 9, payloads.encode_reply(
            MsgType.TELEMETRY, uptime_us=5_000_000, temperature_cdeg=-1234, last_error=9, captures=3,
            rx_frames=10, crc_errors=1, framing_errors=2, overruns=0, rejected=4),
            {"uptime_us": 5_000_000, "temperature_cdeg": -1234, "last_error": 9, "captures": 3,
             "rx_frames": 10, "crc_errors": 1, "framing_errors": 2, "overruns": 0, "rejected": 4}),
        _frame_entry("set_windows_req_frame", MsgType.SET_WINDOWS, 11, payloads.encode_spans(
            [[4, 7, 8, 14]], frame=123456), {"n_spans": 1, "frame": 123456}),
        _frame_entry("start_stream_req", MsgType.START_STREAM, 12, payloads.encode_request(
            MsgType.START_STREAM, period_us=10000, exposure_us=10000, pixel_format=PixelFormat.PACKED10),
            {"period_us": 10000, "exposure_us": 10000, "pixel_format": 1}),
        _frame_entry("start_stream_rep", MsgType.START_STREAM | defs.REPLY_FLAG, 12, payloads.encode_reply(
            MsgType.START_STREAM, first_frame=5, t_first_us=2_000_000, period_us=10000, exposure_us=10000),
            {"first_frame": 5, "t_first_us": 2_000_000, "period_us": 10000, "exposure_us": 10000}),
        _frame_entry("frame_push_packed10", MsgType.FRAME | defs.REPLY_FLAG, 12,
                     payloads.encode_reply(MsgType.FRAME, payloads.encode_windows_tail(
                         [payloads.WindowPixels(2, 1023 + 1 + 512, [1023, 1, 512]),
                          payloads.WindowPixels(9, 7, [7])], 1),
                         frame=7, set_frame=6, t_start_us=2_020_000, t_end_us=2_030_000, exposure_us=10000,
                         late_sets=1, dropped=2, backpressure=1, n_pixels=4, start=0, count=2, total=2,
                         pixel_format=1),
                     {"frame": 7, "set_frame": 6, "t_start_us": 2_020_000, "t_end_us": 2_030_000,
                      "exposure_us": 10000, "late_sets": 1, "dropped": 2, "backpressure": 1, "n_pixels": 4,
                      "start": 0, "count": 2, "total": 2, "pixel_format": 1,
                      "windows": [{"window_id": 2, "sum": 1536, "pixels": [1023, 1, 512]},
                                  {"window_id": 9, "sum": 7, "pixels": [7]}]}),
        _frame_entry("find_spots_req", MsgType.FIND_SPOTS, 13, payloads.encode_request(
            MsgType.FIND_SPOTS, n_sigma_x16=96, max_spots=40, box=7), {"n_sigma_x16": 96, "max_spots": 40, "box": 7}),
        _frame_entry("find_spots_rep", MsgType.FIND_SPOTS | defs.REPLY_FLAG, 13, payloads.encode_reply(
            MsgType.FIND_SPOTS, payloads.encode_spots([[20, 20, 1023], [1, 1022, 650]]), capture_no=3,
            sensor_frame=77, t_start_us=3_000_000, t_end_us=3_010_000, exposure_us=10000, gain_x16=16,
            n_windows=2, n_pixels=84, candidates=5, background_x16=1600, sigma_x16=40, threshold_x16=1840),
            {"capture_no": 3, "sensor_frame": 77, "t_start_us": 3_000_000, "t_end_us": 3_010_000,
             "exposure_us": 10000, "gain_x16": 16, "n_windows": 2, "n_pixels": 84, "candidates": 5,
             "background_x16": 1600, "sigma_x16": 40, "threshold_x16": 1840,
             "spots": [[20, 20, 1023], [1, 1022, 650]]}),
        _frame_entry("error_rep", MsgType.ERROR, 10, payloads.encode_reply(
            MsgType.ERROR, code=ErrorCode.SPAN_OUTSIDE, request_type=MsgType.SET_WINDOWS, detail=4),
            {"code": 9, "request_type": 5, "detail": 4}),
    ]
    good = encode_frame(MsgType.PING, 1, b"ok")
    good_raw = _with_crc(_HDR.pack(defs.VERSION, MsgType.PING, 1, 2) + b"ok")
    bad_crc = bytearray(good)
    bad_crc[good.index(b"ok")] ^= 0x01  # 'o' -> 'n': still no zero byte, CRC now wrong
    corrupt = [
        {"name": "crc_flip", "frame": bytes(bad_crc).hex(), "reason": "crc"},
        # code byte 0x05 promises 4 data bytes, the delimiter arrives after 2
        {"name": "cobs_bad_code", "frame": "05112200", "reason": "cobs"},
        {"name": "short", "frame": _raw_frame(b"\x01\x01\x00").hex(), "reason": "short"},
        {"name": "length_field", "frame": _raw_frame(_with_crc(_HDR.pack(1, 1, 5, 9) + b"abc")).hex(),
         "reason": "length"},
        {"name": "version", "frame": encode_frame(MsgType.PING, 5, b"", version=defs.VERSION + 1).hex(),
         "reason": "version"},
        {"name": "payload_byte_lost", "frame": _raw_frame(good_raw[:-6] + good_raw[-4:]).hex(), "reason": "crc"},
    ]
    f1 = encode_frame(MsgType.PING, 100, b"one")
    f2 = encode_frame(MsgType.TELEMETRY, 101)
    stream = (b"\x13\x37\xff" + b"\x00" + f1 + bytes(bad_crc) + b"\x00\x00" + b"\x02\x05\x00" + f2)
    return {
        "comment": "generated by python -m gyrostar.fwtools.vectors --write; see that module's docstring",
        "protocol_version": defs.VERSION,
        "crc": crc,
        "cobs": [{"raw": r, "encoded": e} for r, e in cobs_cases],
        "frames": frames,
        "corrupt": corrupt,
        "stream": {"bytes": stream.hex(), "frames": [{"type": 1, "seq": 100, "payload": b"one".hex()},
                                                     {"type": int(MsgType.TELEMETRY), "seq": 101, "payload": ""}],
                   "corrupt": 3},
        "exchanges": _exchanges(),
    }


def render() -> str:
    return json.dumps(build(), indent=1) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    path = repo_root() / VECTORS_REL
    text = render()
    if args.write:
        path.write_text(text)
        print(f"wrote {VECTORS_REL}")
        return 0
    if not path.exists() or path.read_text() != text:
        print(f"stale: {VECTORS_REL}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
