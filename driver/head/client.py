"""Head client: request/response over a packet link, built on :mod:`gyrostar.protocol`.

Every request gets a fresh 16-bit sequence number; the reply must carry the same
sequence and the request's type | 0x80 (or be an ERROR frame, which raises the matching
:class:`~gyrostar.protocol.errors.FirmwareError` subclass). Corrupt frames and stale
replies (other sequence numbers, e.g. a late answer to an earlier attempt) are dropped and
counted; a request without a valid reply within ``timeout`` is sent again, at most
``retries`` times, then :class:`HeadTimeoutError` is raised.

Full frames are streamed: FULL_FRAME chunk requests are kept ``depth`` deep in flight and
the replies matched by sequence number, so the link is never idle between chunks.

Window pixels default to U16 on the wire: 1.6× the bytes of PACKED10, but decoding a
10-window reply is ~10× cheaper (``bench/bench_driver.py``), and the link has room.

Times: every reading of the host clock goes through the injected ``clock`` (``now()`` s;
default the monotonic clock), so a simulated or recorded clock drives timeouts and sync.
Captures report MCU microseconds; the client keeps a :class:`~.timesync.ClockSync`
fed by TIME_SYNC exchanges (``sync()``, and automatically every ``sync_every_s``), and
gives each capture's exposure mid-time in host monotonic seconds.

A link may still carry late replies meant for an earlier client (another process, or this
one before a restart). So the first sequence number is random (``first_seq``, else from
the OS's random source), and TIME_SYNC sends the host time (µs) of the request and accepts
only a reply echoing it: a stale TIME_SYNC reply can never enter the clock model.

Streaming (:meth:`start_stream`): the head free-runs exposures and pushes FRAME messages;
:meth:`next_frame` gives them as :class:`~.stream.StreamFrame` (parts assembled, mid-exposure
in host time). :meth:`send_windows` queues a window set for a named frame without waiting
for its reply (the reply, giving the frame it applies to, is taken in by later reads).
"""

from __future__ import annotations

import dataclasses
import logging
import secrets

import numpy as np

from ..clock import MONOTONIC
from ..errors import DeviceError
from ..protocol import MsgType, PixelFormat, Plane
from ..protocol.defs import LIMITS, REPLY_FLAG
from ..protocol.errors import FrameError
from ..protocol.framing import decode_frame, encode_frame
from ..protocol.payloads import decode_reply, encode_request, encode_spans
from ..transport.linkrate import Wire
from .stream import FrameAssembler, FrameQueue, StreamFrame
from .timesync import CLOCK_CHECK_TOL_S, ClockSync

log = logging.getLogger(__name__)

RESYNC_AFTER_STEP = 4     # TIME_SYNC exchanges due at once after the clock model restarts at a step
_NEVER = -1e300           # host s of the last TIME_SYNC before any (a sync is due and overdue)


class HeadTimeoutError(DeviceError):
    """The head did not give a valid reply in time, after every retry."""


class HeadClockError(DeviceError):
    """A capture's MCU times lie outside its own request and reply even after the clock
    model was re-synchronised: no host time can be given to it."""


@dataclasses.dataclass(frozen=True)
class Capture:
    """One exposure: MCU times (µs), its mid-time in host monotonic seconds, and the windows."""

    capture_no: int
    sensor_frame: int
    t_start_us: int
    t_end_us: int
    exposure_us: int
    gain_x16: int
    n_windows: int
    n_pixels: int
    plane: int
    t_mid_host: float        # exposure mid-time, host monotonic s (nan if never synchronised)
    windows: list | None = None  # list of protocol.payloads.WindowPixels when fetched


@dataclasses.dataclass(frozen=True)
class SpotCapture:
    """A FIND_SPOTS exposure: the capture (its windows are the box around each spot, ids
    1..n best first), the spots ((n, 3) int [row, col, flux] in px and DN) and the
    head's background statistics (DN)."""

    capture: Capture
    spots: np.ndarray
    box: int
    spans: np.ndarray        # (m, 4) int [window id, row, col_start, col_stop) of the windows
    background_dn: float
    sigma_dn: float
    threshold_dn: float
    candidates: int


def spot_spans(spots: np.ndarray, box: int, width: int, height: int) -> np.ndarray:
    """The FIND_SPOTS window set: a ``box`` × ``box`` square (clipped to the sensor) around
    each spot [row, col, flux], window ids 1.. in list order, as (m, 4) [id, row, c0, c1)."""
    half = box // 2
    rows = []
    for i, (r, c, _) in enumerate(np.asarray(spots).tolist()):
        c0, c1 = max(c - half, 0), min(c + half + 1, width)
        rows += [(i + 1, rr, c0, c1) for rr in range(max(r - half, 0), min(r + half + 1, height))]
    return np.array(rows, np.int32).reshape(-1, 4)


class HeadClient:
    spot_scan_s = 1.0        # allowance (s) for the head's FIND_SPOTS scan of a whole frame
    def __init__(self, link, timeout: float = 0.5, retries: int = 2, sync: ClockSync | None = None,
                 sync_every_s: float = 1.0, depth: int = 4, first_seq: int | None = None, clock=None,
                 link_preset=None):
        self.link = link
        # the link's line rate (gyrostar.transport.linkrate.LinkPreset, or None: unknown). On a
        # slow wire a TIME_SYNC request waits behind the bytes this client sent before it (a
        # window set), and its reply is longer than it: both would bias the clock offset
        self.link_preset = link_preset
        self._uplink = Wire(link_preset) if link_preset is not None else None
        self.clock = MONOTONIC if clock is None else clock
        self.timeout = timeout
        self.retries = retries
        self.sync_state = sync or ClockSync()
        self.sync_every_s = sync_every_s
        self.depth = depth
        # not 1 after every start: replies to an earlier client must not match ours. A replay
        # link knows the sequence the recorded client drew (recorded_first_seq)
        if first_seq is None:
            first_seq = getattr(link, "recorded_first_seq", lambda: None)()
        self._seq = (secrets.randbits(16) if first_seq is None else int(first_seq) - 1) & 0xFFFF
        self._last_sync = _NEVER
        self._resync = 0          # exchanges still due at once: the model restarted from one exchange
        self.info: dict | None = None
        self.stats = {"requests": 0, "retries": 0, "corrupt": 0, "stale": 0, "pipeline_fallbacks": 0,
                      "sync_echo_mismatch": 0, "tx_bytes": 0, "rx_bytes": 0, "window_sets_rejected": 0,
                      "clock_steps": 0, "capture_clock_resyncs": 0}
        self._stream_seq: int | None = None
        self._assembler = FrameAssembler()
        self._frames = FrameQueue()
        self._async: dict[int, int] = {}          # seq -> type of requests sent without waiting
        self.window_set_replies: list = []         # (seq, fields or exception) of send_windows

    # --- plumbing ---------------------------------------------------------------------------
    @property
    def seq(self) -> int:
        """The last sequence number sent (``first_seq`` − 1 before the first request)."""
        return self._seq

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFFFF
        return self._seq

    def _send(self, msg_type: int, payload: bytes) -> tuple[int, float]:
        seq = self._next_seq()
        data = encode_frame(msg_type, seq, payload)
        t = self.link.send(data)
        if self._uplink is not None:
            self._uplink.transmit(len(data), t)
        self.stats["requests"] += 1
        self.stats["tx_bytes"] += len(data)
        return seq, t

    def _take_unasked(self, frame, t_rx: float, n_bytes: int) -> bool:
        """A pushed FRAME part of our stream or the reply to a request sent without waiting:
        taken in here (True), else False."""
        if frame.type == (MsgType.FRAME | REPLY_FLAG) and frame.seq == self._stream_seq:
            try:
                f = decode_reply(frame, expect=MsgType.FRAME)
            except DeviceError:
                self.stats["corrupt"] += 1
                return True
            done = self._assembler.add(f, t_rx, n_bytes, self._to_host)
            if done is not None:
                self._frames.put(done)
            return True
        want = self._async.pop(frame.seq, None)
        if want is None:
            return False
        if frame.type not in (want | REPLY_FLAG, MsgType.ERROR):
            self._async[frame.seq] = want
            return False
        try:
            self.window_set_replies.append((frame.seq, decode_reply(frame, expect=want)))
        except DeviceError as exc:
            self.stats["window_sets_rejected"] += 1
            self.window_set_replies.append((frame.seq, exc))
        del self.window_set_replies[:-16]
        return True

    def _to_host(self, mcu_us: float) -> float:
        return self.sync_state.mcu_to_host(mcu_us) if self.sync_state.ready else float("nan")

    def _await(self, pending: dict, deadline: float):
        """Next reply matching one of ``pending`` {seq: type} before ``deadline``: (frame, t_rx) or None."""
        while True:
            left = deadline - self.clock.now()
            if left <= 0:
                return None
            got = self.link.recv(left)
            if got is None:
                return None
            t_rx, packet = got
            self.stats["rx_bytes"] += len(packet) + 1
            try:
                frame = decode_frame(packet)
            except FrameError:
                self.stats["corrupt"] += 1
                continue
            if self._take_unasked(frame, t_rx, len(packet) + 1):
                if not pending and len(self._frames):
                    return None           # next_frame: a streamed frame is complete
                continue
            want = pending.get(frame.seq)
            if want is None or frame.type not in (want | REPLY_FLAG, MsgType.ERROR):
                self.stats["stale"] += 1
                continue
            return frame, t_rx

    def request(self, msg_type: int, payload: bytes = b"", timeout: float | None = None,
                retries: int | None = None):
        """Send one request and return ``(fields, t_send, t_recv)`` (host monotonic s)."""
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        for attempt in range(retries + 1):
            if attempt:
                self.stats["retries"] += 1
            seq, t_send = self._send(msg_type, payload)
            got = self._await({seq: int(msg_type)}, self.clock.now() + timeout)
            if got is not None:
                frame, t_rx = got
                return decode_reply(frame, expect=msg_type), t_send, t_rx
        raise HeadTimeoutError(
            f"head on {getattr(self.link, 'url', '?')}: no valid reply to {MsgType(msg_type).name} after "
            f"{retries + 1} attempt(s) of {timeout * 1e3:.0f} ms ({self.stats['corrupt']} corrupt and "
            f"{self.stats['stale']} stale frames so far)")

    # --- commands -----------------------------------------------------------------------------
    def ping(self, echo: bytes = b"") -> float:
        """Round trip time (s) of a PING; checks the echo."""
        fields, t0, t1 = self.request(MsgType.PING, bytes(echo))
        if fields["echo"] != bytes(echo):
            raise DeviceError(f"PING echo differs: sent {len(echo)} bytes, got {len(fields['echo'])}")
        return t1 - t0

    def get_info(self) -> dict:
        self.info = self.request(MsgType.GET_INFO)[0]
        return self.info

    def set_exposure(self, exposure_us: int) -> int:
        us = self.request(MsgType.SET_EXPOSURE, encode_request(MsgType.SET_EXPOSURE,
                                                               exposure_us=exposure_us))[0]["exposure_us"]
        self._exposure_s = us * 1e-6
        return us

    def set_gain(self, gain_x16: int) -> int:
        return self.request(MsgType.SET_GAIN, encode_request(MsgType.SET_GAIN, gain_x16=gain_x16))[0]["gain_x16"]

    def set_windows(self, spans, frame: int = 0) -> dict:
        """Replace the window set with row spans (N×4 ``[window_id, row, col_start, col_stop)``);
        while streaming, from stream frame ``frame`` on (reply ``frame``: the first frame using it)."""
        return self.request(MsgType.SET_WINDOWS, encode_spans(spans, frame=frame))[0]

    # --- streaming ------------------------------------------------------------------------------
    def start_stream(self, period_us: int, exposure_us: int, pixel_format: int = PixelFormat.PACKED10) -> dict:
        """Free-running exposures every ``period_us`` (µs) of ``exposure_us``; frames come from
        :meth:`next_frame`. Returns the reply (``first_frame``, ``t_first_us``, …)."""
        self.maybe_sync()
        payload = encode_request(MsgType.START_STREAM, period_us=period_us, exposure_us=exposure_us,
                                 pixel_format=pixel_format)
        for _ in range(self.retries + 1):
            seq, _ = self._send(MsgType.START_STREAM, payload)
            self._stream_seq = seq            # its pushed frames may come before the reply
            self._assembler = FrameAssembler()
            got = self._await({seq: int(MsgType.START_STREAM)}, self.clock.now() + self.timeout)
            if got is not None:
                f = decode_reply(got[0], expect=MsgType.START_STREAM)
                self._exposure_s = f["exposure_us"] * 1e-6
                return f
            self.stats["retries"] += 1
        self._stream_seq = None
        raise HeadTimeoutError(f"head on {getattr(self.link, 'url', '?')}: START_STREAM unanswered")

    def stop_stream(self) -> dict:
        """End the stream; returns its counters (frames, last_frame, dropped, late_sets, backpressure)."""
        f = self.request(MsgType.STOP_STREAM)[0]
        self._stream_seq = None
        return f

    def send_windows(self, spans, frame: int) -> int:
        """SET_WINDOWS for stream frame ``frame`` without waiting for the reply; returns its seq.
        Replies (or the firmware error of a rejected set) land in ``window_set_replies``."""
        seq, _ = self._send(MsgType.SET_WINDOWS, encode_spans(spans, frame=frame))
        self._async[seq] = int(MsgType.SET_WINDOWS)
        if len(self._async) > 64:                 # replies lost on the link: forget the oldest
            del self._async[next(iter(self._async))]
        return seq

    def next_frame(self, timeout: float) -> StreamFrame | None:
        """The next complete streamed frame, or None after ``timeout`` s without one."""
        fr = self._frames.get()
        if fr is not None:
            return fr
        self._await({}, self.clock.now() + timeout)   # takes in pushed parts and async replies
        return self._frames.get()

    @property
    def stream_stats(self) -> dict:
        """Client-side stream counters: frames given up (parts lost), bad parts, queue overflow."""
        a = self._assembler
        return {"given_up": a.given_up, "bad_parts": a.bad_parts, "queue_overflow": self._frames.overflow}

    def sync(self, n: int = 8) -> ClockSync:
        """``n`` TIME_SYNC exchanges into the clock model."""
        for _ in range(n):
            self._sync_once()
        return self.sync_state

    def _sync_once(self) -> None:
        host_us = int(self.clock.now() * 1e6) & 0xFFFFFFFFFFFFFFFF
        request = encode_request(MsgType.TIME_SYNC, host_us=host_us)
        queued_until = self.uplink_idle_at          # the request's first byte goes out after these
        seq, t_write = self._send(MsgType.TIME_SYNC, request)
        t1 = max(t_write, queued_until)
        deadline = self.clock.now() + self.timeout
        while True:
            got = self._await({seq: int(MsgType.TIME_SYNC)}, deadline)
            if got is None:
                return  # a lost exchange is just not used
            frame, t4 = got
            f = decode_reply(frame, expect=MsgType.TIME_SYNC)
            if f["host_us"] == host_us:
                break
            # the seq matched but the echo is another request's: a late reply to someone else
            self.stats["sync_echo_mismatch"] += 1
            self.stats["stale"] += 1
        asym_us = 0.0
        if self.link_preset is not None:   # the two frames' serialisation times, as sent (µs)
            # same framing both ways (header, CRC, one COBS byte below 254 B): the payloads differ
            asym_us = (len(frame.payload) - len(request)) / self.link_preset.bytes_per_s * 1e6
        s = self.sync_state
        steps, before = s.steps, (s.offset_at(t4) if s.ready else 0.0)
        s.add(t1, f["mcu_rx_us"], f["mcu_tx_us"], t4, asym_us)
        if s.steps != steps:
            # the model now rests on this one exchange, one-sided more often than not on a busy
            # link: the next few are due at once (a streaming caller sends each in a quiet gap)
            self._resync = RESYNC_AFTER_STEP
            self.stats["clock_steps"] += 1
            log.warning("head on %s: its clock stepped by %+.3f s against the host's; clock model restarted",
                        getattr(self.link, "url", "?"), (s.offset_at(t4) - before) * 1e-6)
        elif self._resync:
            self._resync -= 1
        self._last_sync = self.clock.now()

    @property
    def uplink_idle_at(self) -> float:
        """When the bytes this client has sent are all on the wire (host s; -inf with no
        link preset: unknown, taken as at once)."""
        return self._uplink.busy_until if self._uplink is not None else float("-inf")

    def request_sync(self) -> None:
        """Make a TIME_SYNC due (and overdue) now: a caller that found an MCU time it cannot
        believe (a frame stamped after it arrived) wants the clock model checked at once."""
        self._last_sync = _NEVER

    def sync_due(self, t: float) -> bool:
        """:meth:`maybe_sync` at client time ``t`` (s) would exchange TIME_SYNCs (at once
        after a clock step, for :data:`RESYNC_AFTER_STEP` exchanges)."""
        return t - self._last_sync >= (0.0 if self._resync else self.sync_every_s)

    def maybe_sync(self, n: int = 2) -> None:
        if self.sync_due(self.clock.now()):
            self.sync(n)

    @property
    def frames_waiting(self) -> int:
        """Complete streamed frames :meth:`next_frame` returns without reading the link."""
        return len(self._frames)

    def capture(self, fetch: bool = True, pixel_format: int = PixelFormat.U16, dark: bool = False) -> Capture:
        """Expose (CAPTURE, or DARK), then fetch every window's pixels (WINDOW_DATA pages)."""
        self.maybe_sync()
        msg = MsgType.DARK if dark else MsgType.CAPTURE
        # A lost reply means another exposure on retry: the new capture_no tells them apart.
        f, t_sent, t_rx = self.request(msg, timeout=self.timeout + self._exposure_s)
        windows = self.window_data(pixel_format, f["capture_no"]) if fetch else None
        return self._capture_of(f, windows, t_sent, t_rx)

    def capture_windows(self, spans, pixel_format: int = PixelFormat.U16) -> Capture:
        """SET_WINDOWS, CAPTURE and the first WINDOW_DATA page sent back to back, then their
        replies: the head serves requests in order, so the link never idles for a round trip
        between them. The capture is used only when all three replies came and agree (the
        new window set was applied, then captured, then read); a lost, late or rejected reply
        falls back to :meth:`set_windows` + :meth:`capture`, request by request (a rejected
        window set raises its firmware error there)."""
        self.maybe_sync()
        seqs = {}
        for msg, payload in ((MsgType.SET_WINDOWS, encode_spans(spans)), (MsgType.CAPTURE, b""),
                             (MsgType.WINDOW_DATA, encode_request(MsgType.WINDOW_DATA, start=0,
                                                                  pixel_format=pixel_format))):
            seq, t_write = self._send(msg, payload)
            seqs[seq] = int(msg)
            if msg == MsgType.CAPTURE:
                t_sent = t_write
        pending = dict(seqs)
        replies = {}
        t_rx = float("nan")
        deadline = self.clock.now() + self.timeout + self._exposure_s
        while pending:
            got = self._await(pending, deadline)
            if got is None:
                break
            frame, t_got = got
            msg = pending.pop(frame.seq)
            if msg == MsgType.CAPTURE:
                t_rx = t_got
            try:
                replies[msg] = decode_reply(frame, expect=msg)
            except DeviceError:
                break
        s, c, w = (replies.get(int(m)) for m in (MsgType.SET_WINDOWS, MsgType.CAPTURE, MsgType.WINDOW_DATA))
        if s is None or c is None or w is None or (s["n_windows"], s["n_pixels"]) != (c["n_windows"], c["n_pixels"]) \
                or w["capture_no"] != c["capture_no"] or w["start"] != 0 or w["count"] == 0:
            self.stats["pipeline_fallbacks"] += 1
            self.set_windows(spans)
            return self.capture(fetch=True, pixel_format=pixel_format)
        windows = list(w["windows"])
        if w["count"] < w["total"]:
            windows += self.window_data(pixel_format, c["capture_no"], start=w["count"])
        return self._capture_of(c, windows, t_sent, t_rx)

    def find_spots(self, n_sigma: float = 6.0, max_spots: int = 40, box: int = 7,
                   pixel_format: int = PixelFormat.PACKED10) -> SpotCapture:
        """FIND_SPOTS, then the spots' windows (WINDOW_DATA pages): a lost-in-space image in
        a few kB whatever the link. ``n_sigma`` sets the threshold above the background
        (rounded to 1/16), ``box`` the window side (px, odd)."""
        self.maybe_sync()
        req = encode_request(MsgType.FIND_SPOTS, n_sigma_x16=int(round(n_sigma * 16)), max_spots=max_spots, box=box)
        f, t_sent, t_rx = self.request(MsgType.FIND_SPOTS, req,
                                       timeout=self.timeout + self._exposure_s + self.spot_scan_s)
        f = dict(f, plane=Plane.LIGHT)
        windows = self.window_data(pixel_format, f["capture_no"]) if f["n_windows"] else []
        ids = [w.window_id for w in windows]
        if ids != list(range(1, f["n_windows"] + 1)):
            raise DeviceError(f"FIND_SPOTS: window ids {ids[:6]} are not 1..{f['n_windows']}")
        info = self.info or self.get_info()
        spans = spot_spans(f["spots"], box, info["width"], info["height"])
        for w in windows:
            rows = spans[spans[:, 0] == w.window_id]
            if int(np.sum(rows[:, 3] - rows[:, 2])) != len(w.pixels):
                raise DeviceError(f"FIND_SPOTS: window {w.window_id} has {len(w.pixels)} pixels, its box "
                                  f"{int(np.sum(rows[:, 3] - rows[:, 2]))}")
        return SpotCapture(self._capture_of(f, windows, t_sent, t_rx), f["spots"], box, spans,
                           f["background_x16"] / 16.0, f["sigma_x16"] / 16.0, f["threshold_x16"] / 16.0,
                           f["candidates"])

    def _capture_of(self, f: dict, windows, t_sent: float, t_rx: float) -> Capture:
        """The capture of reply ``f`` to a request sent at ``t_sent`` and answered at
        ``t_rx`` (host s), its mid-time mapped to the host clock."""
        self._exposure_s = f["exposure_us"] * 1e-6
        t_mid = self._mid_within(f, t_sent, t_rx)
        return Capture(f["capture_no"], f["sensor_frame"], f["t_start_us"], f["t_end_us"], f["exposure_us"],
                       f["gain_x16"], f["n_windows"], f["n_pixels"], f["plane"], t_mid, windows)

    def _mid_within(self, f: dict, t_sent: float, t_rx: float) -> float:
        """Host mid-time (s) of the capture ``f`` (nan before any time sync). Its MCU times
        must map between its request and its reply: a model that puts them elsewhere is
        stale (a head clock step the 1 Hz exchanges have not seen yet), so the client
        re-synchronises at once, on a link that is idle between requests, and maps again;
        :class:`HeadClockError` if they still fall outside."""
        s = self.sync_state
        if not s.ready:
            return float("nan")
        t0_us, t1_us = f["t_start_us"], f["t_end_us"]

        def inside() -> bool:
            return (s.mcu_to_host(t0_us) >= t_sent - CLOCK_CHECK_TOL_S
                    and s.mcu_to_host(t1_us) <= t_rx + CLOCK_CHECK_TOL_S)

        if not inside():
            self.stats["capture_clock_resyncs"] += 1
            off = s.mcu_to_host(t0_us) - t_sent
            self.request_sync()
            self.sync(2)
            if not inside():
                raise HeadClockError(
                    f"head on {getattr(self.link, 'url', '?')}: capture {f['capture_no']} was stamped "
                    f"{off:+.3f} s from its request, and still {s.mcu_to_host(t0_us) - t_sent:+.3f} s "
                    "after a time sync")
        return s.mcu_to_host(0.5 * (t0_us + t1_us))

    _exposure_s = LIMITS["exposure_default_us"] * 1e-6

    def window_data(self, pixel_format: int = PixelFormat.U16, capture_no: int | None = None,
                    start: int = 0) -> list:
        """The windows of the last capture from window index ``start`` on (as many
        WINDOW_DATA pages as needed)."""
        out = []
        while True:
            f = self.request(MsgType.WINDOW_DATA, encode_request(MsgType.WINDOW_DATA, start=start,
                                                                 pixel_format=pixel_format))[0]
            if capture_no is not None and f["capture_no"] != capture_no:
                raise DeviceError(f"WINDOW_DATA belongs to capture {f['capture_no']}, expected {capture_no}")
            if f["count"] == 0:
                raise DeviceError(f"WINDOW_DATA page at window {start} is empty")
            out.extend(f["windows"])
            start += f["count"]
            if start >= f["total"]:
                return out

    def full_frame(self, plane: int = Plane.LIGHT, pixel_format: int = PixelFormat.PACKED10,
                   chunk: int | None = None) -> tuple[np.ndarray, int]:
        """The whole sensor, streamed in FULL_FRAME chunks kept ``depth`` deep in flight.

        Returns ``(image uint16 (H, W), sensor_frame)``; raises :class:`DeviceError` when the
        chunks come from different sensor frames twice in a row.
        """
        info = self.info or self.get_info()
        w, h = info["width"], info["height"]
        chunk = chunk or info["frame_chunk_max"]
        for _ in range(2):
            img, frames = self._stream_frame(w, h, chunk, plane, pixel_format)
            if len(frames) == 1:
                return img.reshape(h, w), frames.pop()
        raise DeviceError(f"full frame: chunks came from sensor frames {sorted(frames)[:4]}… (frame kept changing)")

    def _stream_frame(self, w, h, chunk, plane, pixel_format):
        total = w * h
        img = np.empty(total, np.uint16)
        todo = list(range(0, total, chunk))
        attempts = dict.fromkeys(todo, 0)
        inflight: dict[int, int] = {}  # seq -> offset
        frames = set()
        while todo or inflight:
            while todo and len(inflight) < self.depth:
                off = todo.pop(0)
                n = min(chunk, total - off)
                payload = encode_request(MsgType.FULL_FRAME, offset=off, count=n, pixel_format=pixel_format,
                                         plane=plane)
                seq, _ = self._send(MsgType.FULL_FRAME, payload)
                inflight[seq] = off
            got = self._await(dict.fromkeys(inflight, int(MsgType.FULL_FRAME)), self.clock.now() + self.timeout)
            if got is None:  # every chunk still in flight is re-requested (bounded)
                for off in inflight.values():
                    attempts[off] += 1
                    if attempts[off] > self.retries:
                        raise HeadTimeoutError(f"full frame: chunk at pixel {off} unanswered after "
                                               f"{self.retries + 1} attempts")
                    self.stats["retries"] += 1
                    todo.insert(0, off)
                inflight.clear()
                continue
            frame, _ = got
            off = inflight.pop(frame.seq)
            f = decode_reply(frame, expect=MsgType.FULL_FRAME)
            if f["offset"] != off:
                raise DeviceError(f"FULL_FRAME reply for pixel {f['offset']}, asked {off}")
            img[off:off + f["count"]] = f["pixels"]
            frames.add(f["sensor_frame"])
        return img, frames

    def telemetry(self) -> dict:
        return self.request(MsgType.TELEMETRY)[0]

    def reset(self) -> None:
        self.request(MsgType.RESET)
