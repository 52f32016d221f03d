"""Driver speed: head-frame decoding and gyro FIFO read + conversion, each against a baseline.

* ``decode_10_window_frame`` — one WINDOW_DATA reply with 10 windows of 12×12 px in U16
  (the head client's default pixel format), from the bytes between two delimiters to
  per-window uint16 arrays, with the product path (:mod:`gyrostar.protocol`: ``cobs`` and
  ``crc32c`` C packages + numpy). Baseline: the same decode as a numba codec (COBS, table
  CRC-32C, pixel unpack). A ratio above 1 means the packages are faster. Target ≤ 200 µs.
* ``decode_10_window_frame_packed10`` — the same in 10-bit packed pixels (smaller on the
  link, slower to unpack in numpy).
* ``read_convert_40_fifo_frames`` — :meth:`Bmi088Gyro.read` of 40 FIFO frames (status read,
  burst, frame indices, time base, numba conversion to rad/s + times + flags into the
  preallocated arrays) over a replay bus that answers instantly (bus time excluded).
  Baseline: the same read with a per-sample pure-Python conversion. Target ≤ 100 µs.
"""

from __future__ import annotations

import statistics
import struct
import time

import numpy as np
from numba import njit


def _time_us(fn, repeat: int, inner: int) -> float:
    fn()
    samples = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        samples.append((time.perf_counter() - t0) / inner * 1e6)
    return statistics.median(samples)


# --- numba codec (baseline for the decode case) ------------------------------------------------
def _crc_table() -> np.ndarray:
    tab = np.zeros(256, np.uint32)
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        tab[i] = c
    return tab


CRC_TABLE = _crc_table()


@njit(cache=True)
def nb_cobs_decode(src, out):
    i = 0
    o = 0
    n = src.shape[0]
    while i < n:
        code = src[i]
        if code == 0:
            return -1
        i += 1
        for _ in range(code - 1):
            if i >= n:
                return -1
            out[o] = src[i]
            o += 1
            i += 1
        if code < 0xFF and i < n:
            out[o] = 0
            o += 1
    return o


@njit(cache=True)
def nb_crc32c(buf, n, table):
    c = np.uint32(0xFFFFFFFF)
    for i in range(n):
        c = table[(c ^ buf[i]) & 0xFF] ^ (c >> np.uint32(8))
    return c ^ np.uint32(0xFFFFFFFF)


@njit(cache=True)
def nb_unpack10(buf, off, n, out, o):
    for i in range(n):
        bit = 10 * i
        b = off + (bit >> 3)
        sh = bit & 7
        v = np.uint32(buf[b]) | (np.uint32(buf[b + 1]) << 8)  # 10 bits at offset ≤ 6 fit in 16
        out[o + i] = (v >> sh) & 0x3FF
    return n


@njit(cache=True)
def nb_decode_windows(src, raw, table, pixels, win_ids, win_n):
    """COBS → CRC check → WINDOW_DATA windows into flat ``pixels``; returns the window count."""
    n = nb_cobs_decode(src, raw)
    if n < 10:
        return -1
    crc = np.uint32(raw[n - 4]) | (np.uint32(raw[n - 3]) << 8) | (np.uint32(raw[n - 2]) << 16) \
        | (np.uint32(raw[n - 1]) << 24)
    if nb_crc32c(raw, n - 4, table) != crc:
        return -2
    p = 6 + 12  # header + WINDOW_DATA fixed part
    count = raw[6 + 6] | (raw[6 + 7] << 8)
    fmt = raw[6 + 10]
    o = 0
    for w in range(count):
        win_ids[w] = raw[p] | (raw[p + 1] << 8)
        m = raw[p + 2] | (raw[p + 3] << 8)
        win_n[w] = m
        p += 8
        if fmt == 1:
            nb_unpack10(raw, p, m, pixels, o)
            p += (10 * m + 7) // 8
        else:
            for i in range(m):
                pixels[o + i] = raw[p + 2 * i] | (np.uint16(raw[p + 2 * i + 1]) << 8)
            p += 2 * m
        o += m
    return count


def _window_frame(pixel_format):
    from gyrostar.protocol import MsgType, encode_frame
    from gyrostar.protocol.defs import REPLY_FLAG
    from gyrostar.protocol.payloads import WindowPixels, encode_reply, encode_windows_tail

    rng = np.random.default_rng(0)
    wins = [WindowPixels(w, 0, rng.integers(0, 1024, 144).astype(np.uint16)) for w in range(10)]
    wins = [WindowPixels(w.window_id, int(w.pixels.sum()), w.pixels) for w in wins]
    payload = encode_reply(MsgType.WINDOW_DATA, capture_no=1, start=0, count=10, total=10,
                           pixel_format=pixel_format) + encode_windows_tail(wins, pixel_format)
    return encode_frame(MsgType.WINDOW_DATA | REPLY_FLAG, 5, payload)[:-1], wins


def bench_decode(quick: bool, pixel_format: int) -> dict:
    from gyrostar.protocol import decode_frame
    from gyrostar.protocol.payloads import decode_reply

    packet, wins = _window_frame(pixel_format)

    def product():
        return decode_reply(decode_frame(packet))["windows"]

    src = np.frombuffer(packet, np.uint8)
    raw = np.empty(len(packet), np.uint8)
    pixels = np.empty(2048, np.uint16)
    ids = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)

    def baseline():
        return nb_decode_windows(src, raw, CRC_TABLE, pixels, ids, ns)

    got = product()
    assert all(np.array_equal(a.pixels, b.pixels) for a, b in zip(got, wins))
    assert baseline() == 10 and np.array_equal(pixels[:1440], np.concatenate([w.pixels for w in wins]))
    rep, inner = (5, 200) if quick else (15, 500)
    t = _time_us(product, rep, inner)
    b = _time_us(baseline, rep, inner)
    fmt = "U16" if pixel_format == 0 else "PACKED10"
    return {"us": t, "baseline_us": b, "ratio": b / t, "target_us": 200.0, "bytes": len(packet),
            "note": f"{fmt}: gyrostar.protocol (cobs+crc32c packages, numpy) vs numba codec"}


# --- gyro FIFO ---------------------------------------------------------------------------------
class ReplayBus:
    """Answers FIFO_STATUS with 40 frames and FIFO_DATA with a fixed 240-byte burst, instantly."""

    def __init__(self, raw: bytes):
        self.raw = raw
        self.status = bytes([40])

    def read(self, reg: int, n: int) -> bytes:
        return self.status if reg == 0x0E else self.raw[:n]

    def write(self, reg: int, data: bytes) -> None:
        pass

    def describe(self) -> str:
        return "replay bus"


def python_convert(raw, n, scale, mounting, t_ref, period, k_ref, first_index, first_flags, prev_raw,
                   out_t, out_index, out_rate, out_flags, start):
    """Per-sample pure-Python twin of :func:`gyrostar.gyro.convert.convert_frames`."""
    m = mounting.tolist()
    data = bytes(raw)
    for i in range(n):
        sx, sy, sz = struct.unpack_from("<3h", data, 6 * i)
        flags = first_flags if i == 0 else 0
        if sx in (32767, -32768):
            flags |= 1
        if sy in (32767, -32768):
            flags |= 2
        if sz in (32767, -32768):
            flags |= 4
        if prev_raw[3] and (sx, sy, sz) == (prev_raw[0], prev_raw[1], prev_raw[2]):
            flags |= 0x10
        prev_raw[0], prev_raw[1], prev_raw[2], prev_raw[3] = sx, sy, sz, 1
        w = (sx * scale, sy * scale, sz * scale)
        o = start + i
        for r in range(3):
            out_rate[o, r] = m[r][0] * w[0] + m[r][1] * w[1] + m[r][2] * w[2]
        k = first_index + i
        out_index[o] = k
        out_t[o] = t_ref + period * (k - k_ref)
        out_flags[o] = flags
    return n


def bench_fifo(quick: bool) -> dict:
    import gyrostar.gyro.base as base
    from gyrostar.clock import SimulatedClock
    from gyrostar.gyro import Bmi088Gyro, GyroSamples

    rng = np.random.default_rng(1)
    raw = rng.integers(-3000, 3000, (40, 3)).astype("<i2").tobytes()

    def make():
        clock = SimulatedClock(10.0)
        gyro = Bmi088Gyro(ReplayBus(raw), clock=clock)
        gyro.odr_hz, gyro.range_dps, gyro.watermark, gyro.scale = 400.0, 2000.0, 20, 2000 / 32768 * np.pi / 180
        gyro.start()
        out = GyroSamples(40)

        def one():
            clock.advance(0.1)
            out.n = 0
            return gyro.read(out)

        return one, out

    product, out_p = make()
    orig = base.convert_frames
    base.convert_frames = python_convert
    try:
        baseline, out_b = make()
        assert baseline() == 40
        rep, inner = (5, 300) if quick else (15, 1000)
        b = _time_us(baseline, rep, inner)
    finally:
        base.convert_frames = orig
    assert product() == 40
    assert np.allclose(out_p.rate, out_b.rate) and np.array_equal(out_p.flags, out_b.flags)
    t = _time_us(product, rep, inner)
    return {"us": t, "baseline_us": b, "ratio": b / t, "target_us": 100.0,
            "note": "Bmi088Gyro.read, polled (time-base solve amortised); numba vs per-sample Python; replay bus"}


def _stream_bytes(spans) -> tuple[int, int]:
    """Wire bytes of one streamed frame (FRAME, PACKED10, head → host) and of its SET_WINDOWS
    (host → head) for a span table, built by the protocol's own encoders."""
    from gyrostar.protocol import MsgType, encode_frame
    from gyrostar.protocol.defs import REPLY_FLAG
    from gyrostar.protocol.payloads import WindowPixels, encode_reply, encode_spans, encode_windows_tail

    wins = []
    for wid in np.unique(spans[:, 0]):
        rows = spans[spans[:, 0] == wid]
        n = int((rows[:, 3] - rows[:, 2]).sum())
        px = np.random.default_rng(int(wid)).integers(0, 1024, n)   # noise: COBS sees few zeros
        wins.append(WindowPixels(int(wid), int(px.sum()), px))
    n_px = sum(len(w.pixels) for w in wins)
    head = encode_reply(MsgType.FRAME, frame=1, set_frame=1, t_start_us=0, t_end_us=10_000, exposure_us=10_000,
                        late_sets=0, dropped=0, backpressure=0, n_pixels=n_px, start=0, count=len(wins),
                        total=len(wins), pixel_format=1)
    down = len(encode_frame(MsgType.FRAME | REPLY_FLAG, 1, head + encode_windows_tail(wins, 1))) + 1
    up = len(encode_frame(MsgType.SET_WINDOWS, 1, encode_spans(spans, frame=1))) + 1
    return down, up


def _measured_rate(preset_name: str, spans, seconds: float) -> dict:
    """Stream the windows at 100 Hz from the firmware host program through a relay paced at
    the preset: frames received per second and the head's drops (back-pressure)."""
    import time

    from gyrostar.head import HeadClient
    from gyrostar.mocks.firmware_host import FirmwareHost, is_built
    from gyrostar.mocks.paced_relay import RelayProcess
    from gyrostar.transport import SerialLink

    if not is_built():
        return {"note": "firmware host program not built (make fw-host)"}
    host = FirmwareHost(1024, 1024, planes=1)
    host.pixels.write_frame(np.random.default_rng(3).integers(0, 1024, (1024, 1024)).astype(np.uint16))
    host.start()
    relay = RelayProcess(host.path, preset_name)
    link = SerialLink(relay.path)
    try:
        head = HeadClient(link, timeout=1.0)
        head.set_windows(spans)
        head.sync(4)
        head.start_stream(10_000, 10_000, 1)
        n, t_end = 0, time.monotonic() + seconds
        while time.monotonic() < t_end:
            n += head.next_frame(0.1) is not None
        stop = head.stop_stream()
    finally:
        link.close()
        relay.close()
        host.close()
    return {"frames_per_s": n / seconds, "head_dropped": stop["dropped"], "head_backpressure": stop["backpressure"]}


def _lost_in_space_bytes(n_spots: int = 64, box: int = 7, width: int = 1024, height: int = 1024) -> dict:
    """Head → host bytes of one lost-in-space image, built with the protocol's own encoders:
    FIND_SPOTS (reply + WINDOW_DATA pages of ``n_spots`` box×box PACKED10 windows) against
    a full frame (FULL_FRAME chunks of frame_chunk_max px, PACKED10)."""
    from gyrostar.protocol import MsgType, PixelFormat
    from gyrostar.protocol.defs import LIMITS, MAX_PAYLOAD, REPLY_FLAG
    from gyrostar.protocol.framing import encode_frame
    from gyrostar.protocol.payloads import WindowPixels, encode_reply, encode_spots, encode_windows_tail, pixel_bytes

    fmt = PixelFormat.PACKED10
    spots = encode_reply(MsgType.FIND_SPOTS, encode_spots([[100 + i, 200, 1000] for i in range(n_spots)]),
                         capture_no=1, sensor_frame=1, t_start_us=0, t_end_us=10_000, exposure_us=10_000, gain_x16=16,
                         n_windows=n_spots, n_pixels=n_spots * box * box, candidates=n_spots, background_x16=0,
                         sigma_x16=8, threshold_x16=0)
    down = len(encode_frame(MsgType.FIND_SPOTS | REPLY_FLAG, 1, spots))
    wins = [WindowPixels(i + 1, 0, np.full(box * box, 512, np.uint16)) for i in range(n_spots)]
    fixed = len(encode_reply(MsgType.WINDOW_DATA, capture_no=0, start=0, count=0, total=0, pixel_format=0))
    start = 0
    while start < n_spots:                       # WINDOW_DATA pages, as many whole windows as fit
        size, k = fixed, start
        while k < n_spots and size + 8 + pixel_bytes(box * box, fmt) <= MAX_PAYLOAD:
            size += 8 + pixel_bytes(box * box, fmt)
            k += 1
        page = encode_reply(MsgType.WINDOW_DATA, encode_windows_tail(wins[start:k], fmt), capture_no=1, start=start,
                            count=k - start, total=n_spots, pixel_format=fmt)
        down += len(encode_frame(MsgType.WINDOW_DATA | REPLY_FLAG, 2, page))
        start = k
    chunk = LIMITS["frame_chunk_max"]
    full = 0
    for off in range(0, width * height, chunk):
        n = min(chunk, width * height - off)
        rep = encode_reply(MsgType.FULL_FRAME, np.zeros(pixel_bytes(n, fmt), np.uint8).tobytes(), sensor_frame=1,
                           offset=off, count=n, pixel_format=fmt, plane=0)
        full += len(encode_frame(MsgType.FULL_FRAME | REPLY_FLAG, 3, rep))
    return {"spots": down, "full_frame": full}


EXPOSURE_S = 0.010   # the streaming head's exposure (s)
GYRO_HZ = 400.0      # gyro output rate (Hz): an update waits half a period on average


def bench_link(quick: bool) -> dict:
    """Per link preset: bytes per frame at rest and at 5 °/s with 10 stars (paper 000's 6×6
    trajectory windows, PACKED10), link utilisation at 100 Hz, the highest frame rate the
    link carries within the loop's 0.8 budget, the rate a paced stream really sustains, the
    wire time of a lost-in-space image (the head's FIND_SPOTS windows vs a full frame), and
    the exposure → output floor the link allows (no host time, no head readout)."""
    from gyrostar.fwtools.wirecount import star_trajectory_windows
    from gyrostar.loop.linkbudget import frame_bytes, windows_bytes
    from gyrostar.transport.linkrate import PRESETS

    out = {}
    sets = {"rest": star_trajectory_windows(10, rate_dps=0.0, seed=2)[0],
            "5dps": star_trajectory_windows(10, rate_dps=5.0, seed=2)[0]}
    sizes = {k: _stream_bytes(v) for k, v in sets.items()}
    lis = _lost_in_space_bytes()
    for k, sp in sets.items():   # the loop's budget model must not under-count the real bytes
        n_px = int((sp[:, 3] - sp[:, 2]).sum())
        assert frame_bytes(n_px, len(np.unique(sp[:, 0]))) >= sizes[k][0] - 2
        assert windows_bytes(len(sp)) >= sizes[k][1] - 1
    for name, p in PRESETS.items():
        per = max(sizes["5dps"])
        fig = {"bytes_per_frame_rest": {"down": sizes["rest"][0], "up": sizes["rest"][1]},
               "bytes_per_frame_5dps": {"down": sizes["5dps"][0], "up": sizes["5dps"][1]},
               "utilisation_100hz_rest": p.utilisation(max(sizes["rest"]), 100.0),
               "utilisation_100hz_5dps": p.utilisation(per, 100.0),
               "max_frame_hz_5dps_budget_0.8": p.max_frame_hz(per, 0.8),
               "lost_in_space_bytes": lis,
               "lost_in_space_wire_s": {k: p.wire_time(v) for k, v in lis.items()},
               # the design's exposure → output floor with no host time: half the exposure,
               # the frame on this wire, half a gyro period (the wait for the next output)
               "exposure_to_output_floor_ms": {
                   k: 1e3 * (0.5 * EXPOSURE_S + p.wire_time(sizes[k][0]) + 0.5 / GYRO_HZ) for k in sizes}}
        if not quick:
            fig["measured_5dps_at_100hz"] = _measured_rate(name, sets["5dps"], 2.0)
        m = fig.get("measured_5dps_at_100hz", {})
        fig["note"] = (f"{name}: {sizes['rest'][0]}/{sizes['5dps'][0]} B down at rest/5°/s, "
                       f"util@100Hz {fig['utilisation_100hz_5dps']:.2f}, "
                       f"max {fig['max_frame_hz_5dps_budget_0.8']:.0f} Hz, "
                       f"exposure→output floor {fig['exposure_to_output_floor_ms']['5dps']:.1f} ms"
                       + (f", paced stream {m['frames_per_s']:.0f} fps" if "frames_per_s" in m else "")
                       + f"; lost-in-space {lis['spots']} B in {1e3 * p.wire_time(lis['spots']):.0f} ms (head's spots)"
                       f" vs {lis['full_frame'] / 1e6:.2f} MB in {p.wire_time(lis['full_frame']):.1f} s (full frame)")
        out[f"link_{name}"] = fig
    return out


def run(quick: bool = False) -> dict:
    return {"decode_10_window_frame": bench_decode(quick, 0),          # the head client's default format
            "decode_10_window_frame_packed10": bench_decode(quick, 1),
            "read_convert_40_fifo_frames": bench_fifo(quick)} | bench_link(quick)


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
