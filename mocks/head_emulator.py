"""Python camera-head emulator: the head's protocol on a real pseudo-terminal, backed by the simulator.

:class:`HeadEmulator` answers every request of :mod:`gyrostar.protocol` as the firmware does
(same checks in the same order, same error codes and details; corrupt frames are dropped
and counted, never answered). CAPTURE really takes the exposure time, stamps start and end
with the emulated MCU clock and renders *only the requested windows* with
:meth:`gyrostar.mocks.sky.Sky.render_windows` at the scene's attitude and rate at that time;
FULL_FRAME renders the whole frame once per sensor frame. The MCU clock is the host
monotonic clock with an offset (µs) and a rate error (ppm), so time sync has a truth to
be measured against (:meth:`mcu_offset_us_at`).

:meth:`start` opens a pty (raw mode, slave kept open) and serves it from a thread; connect
with ``serial.serial_for_url(emulator.path)`` or :class:`gyrostar.transport.SerialLink`.
Replies pass through an optional :class:`~gyrostar.mocks.faults.ByteFaults` (corrupt, drop,
delay/jitter; ``disconnect()`` closes the pty master).

Streaming (START_STREAM) follows the firmware's engine (``firmware/core/gs_stream.c``): the
exposures free-run on the emulated MCU clock, frame k is rendered over its own
[t_start, t_end] and pushed at its end as FRAME messages while frame k+1 integrates; window
sets wait (at most ``stream_pending_sets``) for the frame they name, a late one applies at
the next readout and is counted; a frame is dropped when more than
``stream_tx_backlog_max`` bytes still wait in the pty (a paced link relay reads them only at
the line rate, :mod:`gyrostar.mocks.paced_relay`).
"""

from __future__ import annotations

import fcntl
import os
import select
import struct
import termios
import threading
import time
import tty

import numpy as np
from cobs import cobs
from gyrostar.core.windows import span_pixel_count
from gyrostar.protocol import MsgType
from gyrostar.protocol.defs import (
    ERROR_TEXT,
    LIMITS,
    MAX_PAYLOAD,
    PING_MAX,
    REPLY_FLAG,
    REPLY_LAYOUT,
    REQUEST_LAYOUT,
    VERSION,
    ErrorCode,
    PixelFormat,
    Plane,
)
from gyrostar.protocol.errors import CrcError, FrameError, LengthMismatchError
from gyrostar.protocol.framing import decode_frame, encode_frame
from gyrostar.protocol.payloads import (
    WindowPixels,
    encode_pixels,
    encode_reply,
    encode_spots,
    encode_windows_arrays,
    encode_windows_tail,
    pixel_bytes,
)
from numba import njit

FW_VERSION = (0, 9, 0)
PORT_ID_EMULATOR = 2
_WIN_HEADER = 8


class _Reject(Exception):
    def __init__(self, code: ErrorCode, detail: int = 0):
        super().__init__(ERROR_TEXT[code])
        self.code = code
        self.detail = int(detail)


class ConstantRateScene:
    """Attitude truth for the emulator: ``q0`` (ICRS→body) at host time ``t0``, constant body rate."""

    def __init__(self, q0, omega=(0.0, 0.0, 0.0), t0: float | None = None):
        from .trajectory import Constant

        self.omega = np.asarray(omega, float)
        self._profile = Constant(tuple(self.omega))
        self._t, self._q = (time.monotonic() if t0 is None else t0), np.asarray(q0, float)

    def at(self, t_host: float):
        """``(q, omega)`` at host time ``t_host`` (s, not before the previous call)."""
        from .trajectory import integrate

        if t_host > self._t:
            self._q = integrate(self._q, self._profile, np.array([self._t, t_host]), max_step_s=0.01)[-1]
            self._t = t_host
        return self._q.copy(), self.omega


class HeadEmulator:
    def __init__(self, sky, scene, mcu_offset_us: int = 123_456_789, drift_ppm: float = 0.0, faults=None,
                 noise: bool = True, clock=None):
        from gyrostar.clock import MONOTONIC

        self.clock = MONOTONIC if clock is None else clock   # host time: exposures take their time on it
        self.sky = sky
        self.scene = scene
        self.width = sky.camera.width_px
        self.height = sky.camera.height_px
        self.mcu_offset_us = int(mcu_offset_us)
        self.drift_ppm = drift_ppm
        self.faults = faults
        self.noise = noise
        self._skies = {}
        self._t_boot = self.clock.now()
        self.master = self.slave = None
        self.path = None
        self._thread = None
        self._stop = threading.Event()
        self.rendered_pixels = 0   # pixels rendered for window captures (only the windows)
        self.full_renders = 0
        self.frame_no = 0          # last stream frame number handed out (never reused)
        # bytes handed to the link and not yet on the wire: the pty's queue by default; a
        # link model in the same process (fast mode's gyrostar.hil.lockstep.SimHead) gives its own
        self.backlog_source = None
        # fast runs: the stream's window renders done elsewhere, ahead of their readout (an
        # object with submit/result/discard/eclipse: gyrostar.hil.render_ahead.RenderAhead)
        self.renderer = None
        self._reset_state()

    # --- clocks -------------------------------------------------------------------------------
    def mcu_us(self, t_host: float | None = None) -> int:
        t = self.clock.now() if t_host is None else t_host
        return self.mcu_offset_us + int(round(t * 1e6 * (1 + self.drift_ppm * 1e-6)))

    def mcu_offset_us_at(self, t_host: float) -> float:
        """Truth: MCU − host offset (µs) at host time ``t_host``."""
        return self.mcu_offset_us + t_host * 1e6 * self.drift_ppm * 1e-6

    # --- state --------------------------------------------------------------------------------
    def _reset_state(self) -> None:
        self.exposure_us = LIMITS["exposure_default_us"]
        self.gain_x16 = LIMITS["gain_default_x16"]
        self.spans = np.zeros((0, 4), np.int32)
        self.window_ids: list[int] = []
        self.window_slices: list[slice] = []
        self.capture_no = 0
        self.has_capture = False
        self.pixels = None
        self.sums = []
        self.sensor_frame = 0
        self._full = None
        self.stream = None         # _Stream while streaming
        self.last_stream = None
        self.cnt = dict(rx_frames=0, crc_errors=0, framing_errors=0, overruns=0, rejected=0, last_error=0)
        self._boot_us = self.mcu_us()

    def step_clock(self, step_s: float) -> None:
        """The MCU clock jumps by ``step_s`` (s) against the host's and runs on from there, the
        link open (+: a host suspend, CLOCK_MONOTONIC stopped while the MCU counted on; −:
        set back). :meth:`mcu_offset_us_at` is the truth after it."""
        self.mcu_offset_us += int(round(step_s * 1e6))

    def eclipse(self, on: bool) -> None:
        """No starlight reaches the sensor while ``on`` (stars' signal 0; background and noise stay)."""
        sky = self._sky_for(self.exposure_us)
        if on and getattr(self, "_eclipsed", None) is None:
            self._eclipsed = sky.electrons.copy()
            sky.electrons[:] = 0.0
        elif not on and getattr(self, "_eclipsed", None) is not None:
            sky.electrons[:] = self._eclipsed
            self._eclipsed = None
        if self.renderer is not None:
            self.renderer.eclipse(on, self.exposure_us)

    def _sky_for(self, exposure_us: int):
        sky = self._skies.get(exposure_us)
        if sky is None:
            sky = self.sky.with_exposure(exposure_us * 1e-6)    # glints and environment kept
            self._skies = {exposure_us: sky}
        return sky

    def _env_time(self, t_host: float):
        """Scenario time (s) of host time ``t_host`` for the sky's environment, or None (no
        environment, or a scene without a scenario clock)."""
        if self.sky.environment is None:
            return None
        env_time = getattr(self.scene, "env_time", None)
        return None if env_time is None else env_time(t_host)

    # --- frame handling -----------------------------------------------------------------------
    def handle(self, encoded: bytes, rx_us: int) -> bytes | None:
        """Reply bytes (with delimiter) for one encoded frame (without delimiter), or None."""
        try:
            fr = decode_frame(encoded, check_version=False)
        except LengthMismatchError:
            raw = cobs.decode(bytes(encoded))
            _, typ, seq, length = struct.unpack_from("<BBHH", raw)
            self.cnt["rx_frames"] += 1
            return self._reject(typ, seq, ErrorCode.FRAME_LENGTH, length)
        except CrcError:
            self.cnt["crc_errors"] += 1
            return None
        except FrameError:
            self.cnt["framing_errors"] += 1
            return None
        self.cnt["rx_frames"] += 1
        if fr.version != VERSION:
            return self._reject(fr.type, fr.seq, ErrorCode.BAD_VERSION, fr.version)
        try:
            payload = self._dispatch(fr.type, fr.payload, rx_us, fr.seq)
        except _Reject as r:
            return self._reject(fr.type, fr.seq, r.code, r.detail)
        out = encode_frame(fr.type | REPLY_FLAG, fr.seq, payload)
        if fr.type == MsgType.RESET:
            self._reset_state()
        return out

    def _reject(self, typ, seq, code, detail) -> bytes:
        self.cnt["rejected"] += 1
        self.cnt["last_error"] = int(code)
        return encode_frame(MsgType.ERROR, seq, encode_reply(MsgType.ERROR, code=int(code), request_type=typ,
                                                             detail=int(detail) & 0xFFFFFFFF))

    def _need(self, typ, n):
        size = struct.calcsize("<" + REQUEST_LAYOUT[typ][0])
        if n != size:
            raise _Reject(ErrorCode.PAYLOAD_LENGTH, n)

    def _fields(self, typ, q):
        fmt, names = REQUEST_LAYOUT[typ]
        return dict(zip(names, struct.unpack_from("<" + fmt, q)))

    def _dispatch(self, typ: int, q: bytes, rx_us: int, seq: int = 0) -> bytes:
        n = len(q)
        if typ == MsgType.PING:
            if n > PING_MAX:
                raise _Reject(ErrorCode.PAYLOAD_LENGTH, n)
            return q
        if typ == MsgType.GET_INFO:
            self._need(typ, n)
            return encode_reply(MsgType.GET_INFO, proto_version=VERSION, fw_major=FW_VERSION[0],
                                fw_minor=FW_VERSION[1], fw_patch=FW_VERSION[2], width=self.width,
                                height=self.height, bits=10, port=PORT_ID_EMULATOR,
                                max_windows=LIMITS["max_windows"], max_spans=LIMITS["max_spans"],
                                max_window_pixels=LIMITS["max_window_pixels"], pixel_budget=LIMITS["pixel_budget"],
                                max_payload=MAX_PAYLOAD, frame_chunk_max=LIMITS["frame_chunk_max"],
                                exposure_min_us=LIMITS["exposure_min_us"], exposure_max_us=LIMITS["exposure_max_us"],
                                gain_min_x16=LIMITS["gain_min_x16"], gain_max_x16=LIMITS["gain_max_x16"], planes=1)
        if typ == MsgType.SET_EXPOSURE:
            self._need(typ, n)
            self._not_streaming()
            us = self._fields(typ, q)["exposure_us"]
            if not LIMITS["exposure_min_us"] <= us <= LIMITS["exposure_max_us"]:
                raise _Reject(ErrorCode.EXPOSURE_RANGE, us)
            self.exposure_us = us
            return encode_reply(typ, exposure_us=us)
        if typ == MsgType.SET_GAIN:
            self._need(typ, n)
            g = self._fields(typ, q)["gain_x16"]
            if not LIMITS["gain_min_x16"] <= g <= LIMITS["gain_max_x16"]:
                raise _Reject(ErrorCode.GAIN_RANGE, g)
            self.gain_x16 = g
            return encode_reply(typ, gain_x16=g)
        if typ == MsgType.SET_WINDOWS:
            return self._set_windows(q)
        if typ in (MsgType.CAPTURE, MsgType.DARK):
            self._need(typ, n)
            self._not_streaming()
            if not self.window_ids:
                raise _Reject(ErrorCode.NO_WINDOWS)
            if typ == MsgType.DARK:
                raise _Reject(ErrorCode.DARK_UNAVAILABLE)
            return self._capture()
        if typ == MsgType.WINDOW_DATA:
            return self._window_data(q)
        if typ == MsgType.FULL_FRAME:
            return self._full_frame(q)
        if typ == MsgType.FIND_SPOTS:
            return self._find_spots(q)
        if typ == MsgType.TIME_SYNC:
            self._need(typ, n)
            host_us = self._fields(typ, q)["host_us"]
            return encode_reply(typ, host_us=host_us, mcu_rx_us=rx_us, mcu_tx_us=self.mcu_us())
        if typ == MsgType.TELEMETRY:
            self._need(typ, n)
            c = self.cnt
            return encode_reply(typ, uptime_us=self.mcu_us() - self._boot_us, temperature_cdeg=2500,
                                last_error=c["last_error"], captures=self.capture_no, rx_frames=c["rx_frames"],
                                crc_errors=c["crc_errors"], framing_errors=c["framing_errors"],
                                overruns=c["overruns"], rejected=c["rejected"])
        if typ == MsgType.RESET:
            self._need(typ, n)
            return b""
        if typ == MsgType.START_STREAM:
            return self._start_stream(q, seq, rx_us)
        if typ == MsgType.STOP_STREAM:
            self._need(typ, n)
            return self._stop_stream()
        raise _Reject(ErrorCode.UNKNOWN_TYPE)

    def _not_streaming(self) -> None:
        if self.stream is not None:
            raise _Reject(ErrorCode.STREAMING)

    def _set_windows(self, q: bytes) -> bytes:
        n = len(q)
        if n < 8:
            raise _Reject(ErrorCode.PAYLOAD_LENGTH, n)
        count, reserved, named = struct.unpack_from("<HHI", q)
        if reserved:
            raise _Reject(ErrorCode.RESERVED_NONZERO, reserved)
        if count > LIMITS["max_spans"]:
            raise _Reject(ErrorCode.SPAN_COUNT, count)
        if n != 8 + 8 * count:
            raise _Reject(ErrorCode.SPANS_LENGTH, count)
        spans = np.frombuffer(q[8:], "<u2").reshape(-1, 4).astype(np.int32)
        wset = self._validate_spans(spans)
        applies = 0
        if self.stream is not None:
            st = self.stream
            applies = st.queue(wset, named)
            if st.prepared is not None and st.due()[1][1] is not st.prepared[0][1]:
                self._prepare(st)      # the frame integrating now changed sets: render it now, not at readout
        else:
            self.spans, self.window_ids, self.window_slices = wset[:3]
            self.has_capture = False
        return encode_reply(MsgType.SET_WINDOWS, n_windows=len(wset[1]), n_spans=count, n_pixels=wset[3],
                            frame=applies)

    def _validate_spans(self, spans: np.ndarray) -> tuple:
        """(spans, window ids, pixel slices per window, pixels) of a valid set, else _Reject."""
        fault, at, ids, bounds, total = _scan_spans(np.ascontiguousarray(spans, dtype=np.int64), self.height,
                                                    self.width, LIMITS["max_windows"],
                                                    LIMITS["max_window_pixels"], LIMITS["pixel_budget"])
        if fault:
            raise _Reject(_SCAN_FAULTS[fault], int(at))
        b = bounds.tolist()
        return spans, ids.tolist(), [slice(b[j], b[j + 1]) for j in range(len(b) - 1)], int(total)

    def _capture(self) -> bytes:
        t0_host = self.clock.now()
        t0 = self.mcu_us(t0_host)
        q_start, omega = self.scene.at(t0_host)
        sky = self._sky_for(self.exposure_us)
        self.sensor_frame += 1
        pixels = sky.window_pixels(self.spans, q_start, omega, frame=self.sensor_frame, noise=self.noise,
                                   t_s=self._env_time(t0_host))
        self.rendered_pixels += len(pixels)
        # the exposure takes its time: the reply leaves after the exposure end
        remaining = t0_host + self.exposure_us * 1e-6 - self.clock.now()
        if remaining > 0:
            self.clock.sleep(remaining)
        t1_host = self.clock.now()
        t1 = self.mcu_us(t1_host)
        self.last_exposure_host = (t0_host, t1_host)  # truth for tests: exposure start/end, host s
        self.pixels = np.minimum(pixels, 0x3FF).astype(np.uint16)
        self.sums = _window_sums(self.pixels, self.window_slices)
        self.has_capture = True
        self.capture_no += 1
        return encode_reply(MsgType.CAPTURE, capture_no=self.capture_no, sensor_frame=self.sensor_frame,
                            t_start_us=t0, t_end_us=t1, exposure_us=self.exposure_us, gain_x16=self.gain_x16,
                            n_windows=len(self.window_ids), n_pixels=len(self.pixels), plane=Plane.LIGHT)

    def _window_data(self, q: bytes) -> bytes:
        self._need(MsgType.WINDOW_DATA, len(q))
        f = self._fields(MsgType.WINDOW_DATA, q)
        if f["reserved"]:
            raise _Reject(ErrorCode.RESERVED_NONZERO, f["reserved"])
        fmt = f["pixel_format"]
        if fmt > PixelFormat.PACKED10:
            raise _Reject(ErrorCode.PIXEL_FORMAT, fmt)
        if not self.has_capture:
            raise _Reject(ErrorCode.NO_CAPTURE)
        start = f["start"]
        if start >= len(self.window_ids):
            raise _Reject(ErrorCode.WINDOW_INDEX, start)
        fixed = len(encode_reply(MsgType.WINDOW_DATA, capture_no=0, start=0, count=0, total=0, pixel_format=0))
        size, wins = fixed, []
        for wi in range(start, len(self.window_ids)):
            px = self.pixels[self.window_slices[wi]]
            need = _WIN_HEADER + pixel_bytes(len(px), fmt)
            if size + need > MAX_PAYLOAD:
                break
            wins.append(WindowPixels(self.window_ids[wi], self.sums[wi], px))
            size += need
        head = encode_reply(MsgType.WINDOW_DATA, capture_no=self.capture_no, start=start, count=len(wins),
                            total=len(self.window_ids), pixel_format=fmt)
        return head + encode_windows_tail(wins, fmt)

    def _full_frame(self, q: bytes) -> bytes:
        self._need(MsgType.FULL_FRAME, len(q))
        self._not_streaming()
        f = self._fields(MsgType.FULL_FRAME, q)
        fmt, plane, count, off = f["pixel_format"], f["plane"], f["count"], f["offset"]
        if fmt > PixelFormat.PACKED10:
            raise _Reject(ErrorCode.PIXEL_FORMAT, fmt)
        if plane > Plane.DARK:
            raise _Reject(ErrorCode.BAD_PLANE, plane)
        if plane == Plane.DARK:
            raise _Reject(ErrorCode.DARK_UNAVAILABLE)
        if count == 0 or count > LIMITS["frame_chunk_max"]:
            raise _Reject(ErrorCode.CHUNK_SIZE, count)
        if off + count > self.width * self.height:
            raise _Reject(ErrorCode.FRAME_RANGE, off)
        if self._full is None or self._full[0] != self.sensor_frame:
            t_host = self.clock.now()
            q_start, omega = self.scene.at(t_host)
            img, _ = self._sky_for(self.exposure_us).render_frame(q_start, omega, frame=self.sensor_frame,
                                                                 noise=self.noise, t_s=self._env_time(t_host))
            self.full_renders += 1
            self._full = (self.sensor_frame, np.minimum(img.ravel(), 0x3FF).astype(np.uint16))
        px = self._full[1][off:off + count]
        return encode_reply(MsgType.FULL_FRAME, sensor_frame=self.sensor_frame, offset=off, count=count,
                            pixel_format=fmt, plane=plane) + encode_pixels(px, fmt)

    def _find_spots(self, q: bytes) -> bytes:
        """FIND_SPOTS: expose and render the whole frame, find its spots as the firmware does
        (:mod:`gyrostar.mocks.spot_finder`), make their windows the set and read them."""
        from .spot_finder import check_settings, find_spots

        self._need(MsgType.FIND_SPOTS, len(q))
        self._not_streaming()
        f = self._fields(MsgType.FIND_SPOTS, q)
        if f["reserved"] or f["reserved2"]:
            raise _Reject(ErrorCode.RESERVED_NONZERO, f["reserved"])
        bad = check_settings(f["n_sigma_x16"], f["max_spots"], f["box"])
        if bad:
            raise _Reject(ErrorCode.SPOT_SETTINGS, bad)
        if self.width > LIMITS["spot_width_max"]:
            raise _Reject(ErrorCode.SENSOR_TOO_WIDE, self.width)
        t0_host = self.clock.now()
        t0 = self.mcu_us(t0_host)
        q_start, omega = self.scene.at(t0_host)
        self.sensor_frame += 1
        img, _ = self._sky_for(self.exposure_us).render_frame(q_start, omega, frame=self.sensor_frame,
                                                             noise=self.noise, t_s=self._env_time(t0_host))
        self.full_renders += 1
        img = np.minimum(img, 0x3FF).astype(np.uint16).reshape(self.height, self.width)
        self._full = (self.sensor_frame, img.ravel())
        remaining = t0_host + self.exposure_us * 1e-6 - self.clock.now()
        if remaining > 0:
            self.clock.sleep(remaining)
        t1_host = self.clock.now()
        self.last_exposure_host = (t0_host, t1_host)
        found = find_spots(img, f["n_sigma_x16"], f["max_spots"], f["box"])
        spans = found["spans"]
        self.spans, self.window_ids, self.window_slices = self._validate_spans(spans)[:3]
        self.pixels = (np.concatenate([img[r, c0:c1] for _, r, c0, c1 in spans.tolist()]) if len(spans)
                       else np.zeros(0, np.uint16))
        self.sums = _window_sums(self.pixels, self.window_slices)
        self.has_capture = True
        self.capture_no += 1
        return encode_reply(MsgType.FIND_SPOTS, encode_spots(found["spots"]), capture_no=self.capture_no,
                            sensor_frame=self.sensor_frame, t_start_us=t0, t_end_us=self.mcu_us(t1_host),
                            exposure_us=self.exposure_us, gain_x16=self.gain_x16,
                            n_windows=len(self.window_ids), n_pixels=len(self.pixels),
                            candidates=found["candidates"], background_x16=found["background_x16"],
                            sigma_x16=found["sigma_x16"], threshold_x16=found["threshold_x16"])

    # --- streaming ------------------------------------------------------------------------------
    def _start_stream(self, q: bytes, seq: int, rx_us: int) -> bytes:
        self._need(MsgType.START_STREAM, len(q))
        f = self._fields(MsgType.START_STREAM, q)
        reserved = f["reserved"] | f["reserved2"]
        if reserved:
            raise _Reject(ErrorCode.RESERVED_NONZERO, reserved & 0xFFFF)
        period, expo, fmt = f["period_us"], f["exposure_us"], f["pixel_format"]
        if not LIMITS["exposure_min_us"] <= expo <= LIMITS["exposure_max_us"]:
            raise _Reject(ErrorCode.EXPOSURE_RANGE, expo)
        if not LIMITS["stream_period_min_us"] <= period <= LIMITS["stream_period_max_us"] or period < expo:
            raise _Reject(ErrorCode.STREAM_PERIOD, period)
        if fmt > PixelFormat.PACKED10:
            raise _Reject(ErrorCode.PIXEL_FORMAT, fmt)
        self.exposure_us = expo
        self.frame_no += 1
        t0 = self._host_of_mcu(rx_us)
        self.stream = _Stream(seq, period, expo, fmt, self.frame_no, t0,
                              (self.spans, self.window_ids, self.window_slices))
        return encode_reply(MsgType.START_STREAM, first_frame=self.frame_no, t_first_us=rx_us, period_us=period,
                            exposure_us=expo)

    def _stop_stream(self) -> bytes:
        s = self.stream or self.last_stream
        self.last_stream, self.stream = s, None
        if s is None:
            return encode_reply(MsgType.STOP_STREAM, frames=0, last_frame=0, dropped=0, late_sets=0, backpressure=0)
        s.pending.clear()
        return encode_reply(MsgType.STOP_STREAM, frames=s.frames, last_frame=s.last_frame, dropped=s.dropped,
                            late_sets=s.late_sets, backpressure=s.backpressure)

    def _host_of_mcu(self, mcu_us: int) -> float:
        return (mcu_us - self.mcu_offset_us) * 1e-6 / (1 + self.drift_ppm * 1e-6)

    def tx_backlog(self) -> int:
        """Bytes written to the pty that the other end has not read yet (or what
        ``backlog_source()`` says)."""
        if self.backlog_source is not None:
            return int(self.backlog_source())
        if self.slave is None:
            return 0
        buf = bytearray(4)
        try:
            fcntl.ioctl(self.slave, termios.FIONREAD, buf)
        except OSError:
            return 0
        return int.from_bytes(buf, "little")

    def poll_stream(self, now: float | None = None) -> list[bytes]:
        """The FRAME messages due by host time ``now``; also moves the stream on. Returns the
        encoded messages (to write in order); ``next_due`` then says when to call again."""
        s = self.stream
        if s is None:
            return []
        now = self.clock.now() if now is None else now
        t_end = s.t_start + s.exposure_us * 1e-6
        if now < t_end:
            if s.prepared is None and now >= s.t_start:
                self._prepare(s)
            return []
        out = self._read_stream_frame(s, t_end)
        s.next_frame(self)
        now = self.clock.now()
        while s.t_start + (s.exposure_us + s.period_us) * 1e-6 <= now:
            s.dropped += 1        # more than a period overdue (the emulator was held up): never read
            s.next_frame(self)
        # the next frame is rendered at the next call (``next_due`` is now): this frame's bytes
        # go out first, as the head's UART DMA starts at the readout, not after more work
        return out

    @property
    def next_due(self) -> float | None:
        s = self.stream
        if s is None:
            return None
        return s.t_start if s.prepared is None else s.t_start + s.exposure_us * 1e-6

    def render_windows(self, spans: np.ndarray, t_start: float, frame: int, exposure_us: int) -> np.ndarray:
        """The 10-bit pixels (uint16, span order) of ``spans`` over an exposure of
        ``exposure_us`` starting at host time ``t_start`` (s), sensor frame ``frame`` (its
        noise): the rendering itself, with no emulator state changed but the scene's."""
        q_start, omega = self.scene.at(t_start)
        pixels = self._sky_for(exposure_us).window_pixels(spans, q_start, omega, frame=frame, noise=self.noise,
                                                          t_s=self._env_time(t_start))
        return np.minimum(pixels, 0x3FF).astype(np.uint16)

    def _render(self, s, active) -> np.ndarray:
        """The pixels of the windows ``active`` over frame ``s.frame``'s exposure (the scene is
        known ahead, so this may run while the frame integrates)."""
        return self._resolve(self._render_ahead(s, active))

    def _render_ahead(self, s, active, encode=None):
        """Start rendering ``active`` over frame ``s.frame``'s exposure: the pixels, or (with a
        :attr:`renderer`) its handle for :meth:`_resolve` — the renderer also encodes the
        frame's messages with ``encode`` = (header fields, pixel format, seq) if given."""
        spans, ids, _ = active
        if not ids:
            return np.zeros(0, np.uint16)
        self.sensor_frame += 1
        self.rendered_pixels += int(span_pixel_count(spans))
        if self.renderer is not None:
            return self.renderer.submit(spans, s.t_start, self.sensor_frame, s.exposure_us, encode)
        return self.render_windows(spans, s.t_start, self.sensor_frame, s.exposure_us)

    def _resolve(self, pixels) -> np.ndarray:
        return self._resolve_frame(pixels)[0]

    def _resolve_frame(self, pixels) -> tuple:
        """``(pixels, FRAME messages or None)`` of a render (or its handle)."""
        return (pixels, None) if isinstance(pixels, np.ndarray) else self.renderer.result(pixels)

    def _drop(self, prepared) -> None:
        """A prepared frame that will not be read: its render, if still under way, is not waited for."""
        if prepared is not None and not isinstance(prepared[1], np.ndarray):
            self.renderer.discard(prepared[1])

    def _prepare(self, s) -> None:
        """Render frame ``s.frame`` with the window set due for it as known now, and encode its
        FRAME messages with the counters as they stand (the MCU's DMA buffer, ready at readout).
        With a :attr:`renderer` the render and the encoding (with the header as it stands now)
        go on beside the caller."""
        set_frame, active = s.due()
        self._drop(s.prepared)
        counters = (set_frame, s.late_sets, s.dropped, s.backpressure)
        if self.renderer is None:
            pixels = self._render_ahead(s, active)
            s.prepared = (active, pixels, self._encode_stream_frame(s, active, set_frame, pixels), counters)
        else:
            head = self._frame_head(s, set_frame)
            s.prepared = (active, self._render_ahead(s, active, (head, s.fmt, s.seq)),
                          (head["t_start_us"], head["t_end_us"]), counters)

    def _encode_stream_frame(self, s, active, set_frame: int, pixels: np.ndarray, t_us=None) -> list[bytes]:
        """The FRAME messages (one or more parts) of frame ``s.frame`` read with ``active``
        (``t_us``: the exposure's MCU start and end µs as they were stamped, else now's)."""
        return self.frame_messages(self._frame_head(s, set_frame, t_us), active[1], active[2], pixels, s.fmt, s.seq)

    def _frame_head(self, s, set_frame: int, t_us=None) -> dict:
        """The FRAME header fields of frame ``s.frame`` as they stand (parts aside)."""
        t0_us, t1_us = t_us or (self.mcu_us(s.t_start), self.mcu_us(s.t_start + s.exposure_us * 1e-6))
        return dict(frame=s.frame, set_frame=set_frame, t_start_us=t0_us, t_end_us=t1_us, exposure_us=s.exposure_us,
                    late_sets=s.late_sets, dropped=s.dropped, backpressure=s.backpressure)

    @staticmethod
    def frame_messages(head: dict, ids: list, slices: list, pixels: np.ndarray, fmt: int, seq: int) -> list[bytes]:
        """A stream frame's FRAME messages, encoded and framed (one or more parts, each under
        the payload limit): header fields ``head`` (:meth:`_frame_head`), the windows ``ids``
        whose pixels are ``pixels[slices[j]]``, pixel format ``fmt``, stream ``seq``."""
        px, bounds = _window_pixels(pixels, slices)
        sums = _bounded_sums(px, bounds)
        b = bounds.tolist()
        counts = [b[j + 1] - b[j] for j in range(len(b) - 1)]
        out, start = [], 0
        fixed = struct.calcsize("<" + REPLY_LAYOUT[MsgType.FRAME][0])
        while True:
            size, stop = fixed, start
            while stop < len(ids):
                need = _WIN_HEADER + pixel_bytes(counts[stop], fmt)
                if size + need > MAX_PAYLOAD:
                    break
                size += need
                stop += 1
            part = encode_reply(MsgType.FRAME, **head, n_pixels=len(pixels), start=start, count=stop - start,
                                total=len(ids), pixel_format=fmt)
            tail = encode_windows_arrays(ids[start:stop], sums[start:stop], px, bounds[start:stop + 1], fmt)
            out.append(encode_frame(MsgType.FRAME | REPLY_FLAG, seq, part + tail))
            start = stop
            if start >= len(ids):
                return out

    def window_set(self, spans: np.ndarray) -> tuple[list, list]:
        """``(window ids, pixel slices per window)`` of a valid span set (as the emulator
        checked it when it came)."""
        _, ids, slices, _ = self._validate_spans(spans)
        return ids, slices

    def _read_stream_frame(self, s, t_end: float) -> list[bytes]:
        s.install_due()
        prepared, s.prepared = s.prepared, None
        if self.tx_backlog() > LIMITS["stream_tx_backlog_max"]:
            s.dropped += 1
            s.backpressure += 1
            self._drop(prepared)
            return []
        self.has_capture = False
        self.last_exposure_host = (s.t_start, t_end)
        if prepared is not None and prepared[0][1] is s.active[1]:
            # rendered during the exposure with this very set; encoded then (or now, as it stood
            # then, after a render beside us) unless a counter moved
            same = prepared[3] == (s.set_frame, s.late_sets, s.dropped, s.backpressure)
            pixels, messages = self._resolve_frame(prepared[1])
            if not same:
                out = self._encode_stream_frame(s, s.active, s.set_frame, pixels)
            elif isinstance(prepared[2], list):
                out = prepared[2]
            elif messages is not None:
                out = messages
            else:
                out = self._encode_stream_frame(s, s.active, s.set_frame, pixels, t_us=prepared[2])
        else:
            self._drop(prepared)
            out = self._encode_stream_frame(s, s.active, s.set_frame, self._render(s, s.active))
        s.frames += 1
        s.last_frame = s.frame
        return out

    # --- pty service --------------------------------------------------------------------------
    def start(self) -> str:
        """Open a pty, serve it from a thread; returns the slave path."""
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="head-emulator", daemon=True)
        self._thread.start()
        return self.path

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        fd = self.master
        if fd is None:
            raise OSError("head emulator disconnected")
        while view:
            try:
                k = os.write(fd, view)
            except BlockingIOError:
                select.select([], [self.master], [], 0.05)
                continue
            view = view[k:]

    def _emit(self, data: bytes) -> None:
        if self.faults is not None:
            self.faults.write_through(self._write, data)
        else:
            self._write(data)

    def _serve(self) -> None:
        buf = bytearray()
        fd = self.master
        while not self._stop.is_set():
            try:
                for msg in self.poll_stream():
                    self._emit(msg)
                due = self.next_due
                wait = 0.05 if due is None else min(0.05, max(0.0, due - self.clock.now()))
                r, _, _ = select.select([fd], [], [], wait)
                if not r or self._stop.is_set():
                    continue
                data = os.read(fd, 65536)
            except (OSError, ValueError):
                return
            if not data:
                return
            buf += data
            while True:
                end = buf.find(0)
                if end < 0:
                    if len(buf) > 2 * (MAX_PAYLOAD + 16):
                        buf.clear()
                        self.cnt["overruns"] += 1
                    break
                frame, buf = bytes(buf[:end]), buf[end + 1:]
                if not frame:
                    continue
                try:
                    reply = self.handle(frame, self.mcu_us())
                except Exception:  # noqa: BLE001 - a malformed frame must never stop the head
                    self.cnt["framing_errors"] += 1
                    reply = None
                if reply is not None:
                    try:
                        self._emit(reply)
                    except OSError:
                        return

    def disconnect(self) -> None:
        """The head goes away: the pty master closes (the client's reads fail)."""
        self._stop.set()
        for fd in (self.master, self.slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self.slave = None

    def wait_stopped(self, timeout: float = 1.0) -> None:
        """Wait (up to ``timeout`` s) for the serving thread to end after :meth:`disconnect`."""
        if self._thread is not None:
            self._thread.join(timeout=timeout)

    def stop(self) -> None:
        self.disconnect()
        self.wait_stopped()

    def warm_up(self, q0) -> None:
        """Run every compiled kernel once at the current exposure — rendering (and its
        fixed-pattern noise), the spot finder, the 10-bit packer, the attitude integrator —
        so neither the first CAPTURE of a run nor its first FIND_SPOTS or streamed frame
        compiles (a compile takes seconds of CPU from the loop under test on a shared host)."""
        import numpy as np

        from ..protocol.payloads import encode_windows_arrays, pack10
        from .spot_finder import find_spots
        from .trajectory import Constant, LinearSegments, integrate, integrate_to

        sky = self._sky_for(self.exposure_us)
        img, _ = sky.render_frame(q0, np.zeros(3), frame=0)
        spans = np.array([[0, 10, 10, 16]], np.int32)
        sky.window_pixels(spans, q0, np.zeros(3), frame=0)
        if sky.environment is not None:      # the orbit environment's kernels (and its ephemeris) too
            sky.render_frame(q0, np.zeros(3), frame=0, t_s=0.0)
            sky.window_pixels(spans, q0, np.zeros(3), frame=0, t_s=0.0)
        self._validate_spans(spans)
        for fmt in (PixelFormat.U16, PixelFormat.PACKED10):
            encode_windows_arrays([0], [6], np.ones(6, np.uint16), np.array([0, 6]), fmt)
        find_spots(np.asarray(img)[:64, :64], 96, 8, 7)
        pack10(np.arange(8, dtype=np.uint16))
        integrate(np.asarray(q0, float), Constant((0.0, 0.0, 1e-3)), np.array([0.0, 0.02]), max_step_s=0.01)
        segments = LinearSegments([0.0], [np.inf], [(0.0, 0.0, 1e-3)], [(0.0, 0.0, 1e-3)])
        integrate_to(np.asarray(q0, float), segments, 0.0, 0.02)
        segments.rate(np.array([0.0, 0.01]))

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()


class _Stream:
    """The emulator's stream: timing grid (host s), counters, window sets waiting for frames."""

    def __init__(self, seq, period_us, exposure_us, fmt, frame, t_start, active):
        self.seq, self.period_us, self.exposure_us, self.fmt = seq, period_us, exposure_us, fmt
        self.frame, self.t_start = frame, t_start
        self.active = active            # (spans, ids, slices) in use
        self.set_frame = 0
        self.prepared = None            # (set, pixels, FRAME messages, counters) of the frame integrating now
        self.pending: list = []         # [first frame, named frame, (spans, ids, slices, total)]
        self.frames = self.late_sets = self.dropped = self.backpressure = self.last_frame = 0

    def queue(self, wset, named: int) -> int:
        late = named != 0 and named < self.frame
        first = self.frame if named == 0 or late else named
        keep = [p for p in self.pending if p[0] < first]
        if len(keep) >= LIMITS["stream_pending_sets"]:
            keep = keep[:LIMITS["stream_pending_sets"] - 1]
        self.pending = keep + [[first, named or first, wset]]
        if late:
            self.late_sets += 1
        return first

    def due(self) -> tuple:
        """(named frame, set) frame ``self.frame`` would be read with if no other set came."""
        due = [p for p in self.pending if p[0] <= self.frame]
        return (due[-1][1], due[-1][2][:3]) if due else (self.set_frame, self.active)

    def install_due(self) -> None:
        while self.pending and self.pending[0][0] <= self.frame:
            _, named, wset = self.pending.pop(0)
            self.active = wset[:3]
            self.set_frame = named

    def next_frame(self, emu) -> None:
        emu.frame_no += 1
        self.frame = emu.frame_no
        self.t_start += self.period_us * 1e-6


_SCAN_FAULTS = {1: ErrorCode.SPAN_OUTSIDE, 2: ErrorCode.SPAN_EMPTY, 3: ErrorCode.SPAN_ORDER,
                4: ErrorCode.WINDOW_COUNT, 5: ErrorCode.WINDOW_TOO_LARGE, 6: ErrorCode.PIXEL_BUDGET}


@njit(cache=True)
def _scan_spans(spans, height, width, max_windows, max_window_pixels, pixel_budget):
    """The firmware's window-set checks in span order: ``(fault, span index, window ids (k,),
    window pixel bounds (k + 1,), pixels)``; fault 0 (valid) or a key of ``_SCAN_FAULTS``
    for the first span that breaks a rule (off the sensor, empty, out of order, one window
    too many, a window or the set over its pixel budget)."""
    n = spans.shape[0]
    ids = np.empty(n, np.int64)
    bounds = np.zeros(n + 1, np.int64)
    k = 0
    total = 0
    in_win = 0
    p_wid = -1
    p_row = -1
    for i in range(n):
        wid, row, c0, c1 = spans[i, 0], spans[i, 1], spans[i, 2], spans[i, 3]
        if row >= height or c1 > width:
            return 1, i, ids[:0], bounds[:1], 0
        if c0 >= c1:
            return 2, i, ids[:0], bounds[:1], 0
        if i > 0 and (wid < p_wid or (wid == p_wid and row <= p_row)):
            return 3, i, ids[:0], bounds[:1], 0
        new_window = i == 0 or wid != p_wid
        p_wid = wid
        p_row = row
        if new_window:
            if k + 1 > max_windows:
                return 4, i, ids[:0], bounds[:1], 0
            ids[k] = wid
            bounds[k] = total
            k += 1
            in_win = 0
        in_win += c1 - c0
        total += c1 - c0
        if in_win > max_window_pixels:
            return 5, i, ids[:0], bounds[:1], 0
        if total > pixel_budget:
            return 6, i, ids[:0], bounds[:1], 0
    bounds[k] = total
    return 0, -1, ids[:k].copy(), bounds[:k + 1].copy(), total


def _window_pixels(pixels: np.ndarray, slices: list) -> tuple[np.ndarray, np.ndarray]:
    """``(pixels, bounds (k + 1,))``: the windows' slices of ``pixels`` back to back, window j at
    ``bounds[j]:bounds[j + 1]`` (the frame's own array when its slices tile it in order)."""
    if not slices:
        return pixels[:0], np.zeros(1, np.int64)
    starts = [sl.start for sl in slices]
    if starts[0] == 0 and slices[-1].stop == len(pixels) and all(a.stop == b.start for a, b in zip(slices, slices[1:])):
        return pixels, np.array(starts + [len(pixels)], np.int64)
    parts = [pixels[sl] for sl in slices]
    bounds = np.zeros(len(parts) + 1, np.int64)
    np.cumsum([len(p) for p in parts], out=bounds[1:])
    return np.concatenate(parts), bounds


def _bounded_sums(px: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """int64 (k,): the sum of ``px[bounds[j]:bounds[j + 1]]`` for each window j (empty ones 0),
    from one running sum of the frame."""
    c = np.zeros(len(px) + 1, np.int64)
    np.cumsum(px, dtype=np.int64, out=c[1:])
    return c[bounds[1:]] - c[bounds[:-1]]


def _window_sums(pixels: np.ndarray, slices: list) -> list:
    """Pixel sum (int) of each window's slice of ``pixels``."""
    return _bounded_sums(*_window_pixels(pixels, slices)).tolist()
