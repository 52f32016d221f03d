"""The loop's access to a streaming camera head: frames pushed by the head, window sets
commanded for named frames, all on a worker thread.

A streaming head (START_STREAM) free-runs its exposures; the worker reads the pushed frames
(:meth:`gyrostar.head.HeadClient.next_frame`), measures each with the callback the loop gave
with the window set it used (the measurement runs here, off the loop's steps), and queues
the result; ``poll()`` hands results to the loop one per call. ``submit_windows(spans,
frame, post)`` sends the window set for stream frame ``frame`` at once (the head queues it;
its reply comes back among the frames). :meth:`next_target` says which frame the loop should
command next and when that exposure starts (host s): two frames after the newest one
received, so while frame n+1 integrates the loop commands n+2 — two sets in flight.

Fast mode (``inline``, the lock-step schedule of :mod:`gyrostar.hil.lockstep`) has no
worker: each window set is sent at once, as part of the loop step that commands it, and
the frames that have arrived by a step are taken in at that step's ``poll()`` — each turn
on its own simulated time line (:meth:`Lockstep.run_job`), so a request inside it (start,
time sync) never moves the loop's clock; a result is handed over only once the loop's
time has reached its frame's arrival.

Lost-in-space full frames stop the stream (full frames are request/response), as do
reconnects; the next ``submit_windows`` starts it again with that set. ``set_period``
changes the frame period (the stream restarts with it): the loop lowers the frame rate this
way when the link cannot carry its windows (:mod:`gyrostar.loop.linkbudget`).
Recording/replay at the port's boundary: a stream's timing depends on threads, so the log
holds what the loop saw — every ``poll()`` answer (results with their pixels; a full frame's
lost-in-space outcome, not its image), every ``next_target`` answer and GET_INFO — and a
replay serves them back without a link or a worker; the loop's measurement of each frame is
recomputed from the logged pixels, and each window set the loop commands is checked against
the logged one.
"""

from __future__ import annotations

import collections
import json
import math
import pickle
import queue
import struct
import threading
import zlib

import numpy as np

from ..errors import DeviceError
from ..head.timesync import CLOCK_CHECK_TOL_S
from ..loop.linkbudget import time_sync_bytes, windows_bytes
from .headport import POLL, HeadPort, ImageResult

CH_STREAM_POLL = 7      # log channels of a streaming port (kind POLL)
CH_STREAM_TARGET = 8
CH_STREAM_INFO = 9
CH_STREAM_SETS = 10
_TARGET = struct.Struct("<Id")
_READ_ARRIVED_S = 1e-6   # fast mode: a stream turn's read of what has arrived (its own time moves 1 µs)


class StreamReplay:
    """The logged answers of a streaming port (deques of record payloads per channel)."""

    def __init__(self, records):
        by = collections.defaultdict(collections.deque)
        for r in records:
            if r.kind == POLL and r.channel in (CH_STREAM_POLL, CH_STREAM_TARGET, CH_STREAM_INFO, CH_STREAM_SETS):
                by[r.channel].append(bytes(r.payload))
        self.polls, self.targets = by[CH_STREAM_POLL], by[CH_STREAM_TARGET]
        self.info, self.sets = by[CH_STREAM_INFO], by[CH_STREAM_SETS]

    def take(self, q: collections.deque, what: str) -> bytes:
        if not q:
            from ..recording.taps import ReplayExhausted

            raise ReplayExhausted(what)
        return q.popleft()


def _pack_result(res: ImageResult) -> bytes:
    values = b"" if res.values is None else np.ascontiguousarray(res.values, np.uint16).tobytes()
    meta = (res.kind, res.t_start, res.t_end, res.t_mid, getattr(res, "frame", 0), getattr(res, "set_frame", 0),
            res.error, res.measured if res.kind == "frame" else None, getattr(res, "t_rx", None))
    blob = pickle.dumps(meta, protocol=4)
    return b"\x01" + struct.pack("<I", len(blob)) + blob + values


def unpack_result(payload: bytes) -> ImageResult:
    """The :class:`ImageResult` of a logged poll answer (kind POLL, channel ``CH_STREAM_POLL``,
    payload starting with 0x01)."""
    (n,) = struct.unpack_from("<I", payload, 1)
    meta = pickle.loads(payload[5:5 + n])
    kind, t0, t1, tm, frame, set_frame, error, measured = meta[:8]
    values = np.frombuffer(payload[5 + n:], np.uint16).copy() if kind == "windows" and error is None else None
    res = ImageResult(kind, t0, t1, tm, values=values, error=error, measured=measured)
    res.frame, res.set_frame = frame, set_frame
    if len(meta) > 8 and meta[8] is not None:      # the frame's arrival (logs before 2026-11-26 lack it)
        res.t_rx = meta[8]
    return res


# the frame a window set is commanded for: two after the newest received, or later while the
# set's wire time (the last set's bytes on the port's link) plus this margin (s: the plan and
# hand-over on the host) does not fit before its exposure starts; at most MAX_FRAMES_AHEAD
# after the newest received (the head holds sets for its next two frames, and on a slow link
# the frame after the newest received is already integrating)
SET_LEAD_MARGIN_S = 1e-3
MAX_FRAMES_AHEAD = 3
# A TIME_SYNC exchange while streaming goes right after a frame has arrived, when the head's
# downlink is idle until the next readout: a reply queued behind frame bytes would make the
# exchange one-sided (its delay all on the way down), and on a busy UART nearly every
# exchange was. It waits for such a gap while this much overdue (s), then goes anyway.
SYNC_OVERDUE_S = 2.0
SYNC_GAP_MARGIN_S = 1e-3   # the gap must hold both wire times plus this (host and head turnaround)
# A frame's exposure ends before its bytes arrive (by the readout and the wire time: ≤ ~0.1 s
# for the largest window set on the slowest link). Mapped through the clock model, an end more
# than CLOCK_CHECK_TOL_S after the arrival or FRAME_AGE_MAX_S before it means the model no longer
# fits the head's clock (it stepped): the frame is not used and a time sync goes at once. (A host
# that stalls the reading for longer loses its frames to this too; they would be a second old.)
FRAME_AGE_MAX_S = 1.0


class StreamPort(HeadPort):
    streaming = True

    def __init__(self, link, clock, pixel_format: int = 1, frame_hz: float = 100.0, link_preset=None,
                 replay: StreamReplay | None = None, stream_clock=None, **kw):
        super().__init__(link, clock, link_preset=link_preset, **kw)
        self.replay = replay
        # the stream's timing clock, kept off the recorded head clock: host monotonic, or in
        # fast mode the lock-step schedule's simulated time
        self.stream_clock = stream_clock
        self.pixel_format = pixel_format
        self.period_us = int(round(1e6 / frame_hz))
        self._results: collections.deque = collections.deque()
        self._sends: queue.SimpleQueue = queue.SimpleQueue()
        self._quiet_of = self._quiet = None          # (link, its quiet_until) for _turn_idle
        self._sets: dict[int, tuple] = {}          # named frame -> (spans, post)
        self._lock = threading.Lock()
        self.on = False                            # the head streams
        self._want_period: int | None = None
        self.first_frame = 0
        self.t_first_host = float("nan")
        self.last_frame = 0                        # newest frame received
        self.last_target = 0                       # newest frame commanded
        self.head_counters = {"dropped": 0, "late_sets": 0, "backpressure": 0}
        self.frames_received = 0
        self.frames_unmatched = 0                  # frames whose window set the loop no longer has
        self.unmatched_why = collections.Counter()
        self.stream_starts = 0
        self.wire_bytes = 0                        # FRAME bytes received (head → host)
        self.sent_bytes = 0                        # SET_WINDOWS bytes sent while streaming (host → head)
        self.last_set_bytes = 0                    # the last set's bytes on the wire (its successor's estimate)
        # first and last frame's mid-exposure (host s, from the head's clock: host scheduling
        # cannot bunch it) and the first frame's bytes (they arrived before the span began)
        self._t_mid = [float("nan"), float("nan")]
        self._first_bytes = 0
        self._arrival = np.zeros(1 << 14)          # mid-exposure → frame received (s), ring
        self._n_arrival = 0
        self._start_key = 0
        self._holding = False

    # ------------------------------------------------------------------ loop side
    def start(self, exposure_s: float | None = None) -> None:
        if exposure_s:
            self.exposure_s = exposure_s
        if self.replay is not None:
            self.info = json.loads(self.replay.take(self.replay.info, "head info"))
            return
        super().start(exposure_s)
        # the stream's own timing stays off the recorded head clock: a replay serves the
        # port's answers, not the client's clock readings (1000 a second while streaming)
        from ..clock import MONOTONIC

        self.client.clock = self.stream_clock if self.stream_clock is not None else MONOTONIC
        self._log(CH_STREAM_INFO, json.dumps(self.info).encode())

    def _log(self, channel: int, payload: bytes) -> None:
        if self._poll_log is not None:
            self._poll_log.append(POLL, payload, channel)

    @property
    def busy(self) -> bool:
        """A full frame or reconnect is in flight (window sets never make the port busy)."""
        return self._job is not None

    @property
    def period_s(self) -> float:
        return self.period_us * 1e-6

    def next_target(self, now: float) -> tuple[int, float]:
        """(frame to command, its exposure start in host s); frame 0: the stream is not
        running, the set starts it (its first exposure starts about now)."""
        if self.replay is not None:
            return _TARGET.unpack(self.replay.take(self.replay.targets, "stream targets"))
        with self._lock:
            if not self.on or self.t_first_host != self.t_first_host:
                k, t = 0, now + 0.002
            else:
                k = self.last_frame + 2
                t = self.t_first_host + (k - self.first_frame) * self.period_s
                if self.link_preset is not None:
                    # the set must reach the head before frame k's exposure starts: on a slow
                    # link (a UART) a set's bytes take longer than two frames ahead leave, and
                    # a late set is read with the frame before's windows (stale when moving)
                    need = self.link_preset.wire_time(self.last_set_bytes) + SET_LEAD_MARGIN_S
                    while t - now < need and k < self.last_frame + MAX_FRAMES_AHEAD:
                        k += 1
                        t += self.period_s
        self._log(CH_STREAM_TARGET, _TARGET.pack(k, t))
        return k, t

    def submit_windows(self, spans: np.ndarray, frame: int = 0, post=None) -> int:
        """Send ``spans`` for stream frame ``frame`` (0: start the stream with them); ``post(values)``
        measures that frame's pixels (span order) on the worker. Returns ``frame``."""
        with self._lock:
            self.last_target = max(self.last_target, frame)
            self._sets[frame] = (spans, post)
            for old in [k for k in self._sets if k and k < frame - 8]:
                del self._sets[old]
        digest = struct.pack("<II", frame, zlib.crc32(np.ascontiguousarray(spans, np.int32).tobytes()))
        if self.replay is not None:
            if self.replay.take(self.replay.sets, "window sets") != digest:
                from ..recording.taps import ReplayDivergence

                raise ReplayDivergence(f"replay: the loop commanded other windows for frame {frame} than logged")
            return frame
        self._log(CH_STREAM_SETS, digest)
        self.last_set_bytes = windows_bytes(len(spans))
        self.sent_bytes += self.last_set_bytes
        self._sends.put((spans, frame))
        if self.inline is not None:
            self._inline_turn()
            return frame
        self._start_worker()
        self._jobs.put(("wake", None))
        return frame

    def set_period(self, period_s: float) -> None:
        """New frame period (s): the stream restarts with it at the next window set."""
        self._want_period = int(round(period_s * 1e6))
        if self.replay is None and self.inline is None:
            self._jobs.put(("wake", None))

    def _submit(self, kind, arg) -> None:
        if self.replay is not None:           # full frame / reconnect: its result is in the log
            self._job = (kind, arg)
            return
        super()._submit(kind, arg)

    def _waiting(self) -> str | None:
        """What :meth:`poll` hands over now: ``"job"`` (a full frame or reconnect finished),
        ``"frame"`` (a streamed frame measured; fast mode: one that has arrived by now — the
        stream turn that reads it runs here) or None."""
        if self.inline is not None and self.on and self._job is None and not self._turn_idle():
            self._inline_turn()                # the frames that arrived by now
        if self._job is not None and self.job_done and not self._results:
            return "job"
        if self._results and (self.inline is None
                              or getattr(self._results[0], "t_rx", -float("inf")) <= self.inline.now()):
            return "frame"
        return None

    def ready(self) -> bool:
        """A result waits for :meth:`poll` (the loop's runner steps for it). Logs nothing; a
        replay has no runner to ask."""
        return self.ready_since() is not None

    def ready_since(self) -> float | None:
        """What waits for :meth:`poll`, for the loop's step schedule: the oldest measured
        frame's arrival (host s), −inf for a finished job, None for nothing (and in a replay).
        Logs nothing."""
        if self.replay is None:
            what = self._waiting()
            if what == "frame":
                return getattr(self._results[0], "t_rx", -math.inf)
            if what == "job":
                return -math.inf
        return None

    def poll(self) -> ImageResult | None:
        if self.replay is not None:
            payload = self.replay.take(self.replay.polls, "head polls")
            if payload[:1] != b"\x01":
                return None
            res = unpack_result(payload)
            if res.kind != "windows":
                self._job = None
            elif res.error is None:
                got = self._sets.get(res.set_frame)
                if got is not None and got[1] is not None:
                    res.measured = got[1](res.values)       # the loop's measurement, recomputed
            return res
        res = None
        what = self._waiting()
        if what == "job":
            res = self._result
            self._job = self._result = None
            self._ready_at = None
        elif what == "frame":
            res = self._results.popleft()
        self._log(CH_STREAM_POLL, b"\x00" if res is None else _pack_result(res))
        return res

    def stats(self) -> dict:
        """What the stream did (for the run summary)."""
        out = {"frames_received": self.frames_received, "frames_unmatched": self.frames_unmatched,
               "unmatched_why": dict(self.unmatched_why),
               "stream_starts": self.stream_starts, "period_ms": self.period_us * 1e-3,
               "frame_wire_bytes": self.wire_bytes}
        out.update({f"head_{k}": v for k, v in self.head_counters.items()})
        n = min(self._n_arrival, len(self._arrival))
        if n:
            out["arrival_ms_p50"] = float(np.median(self._arrival[:n])) * 1e3   # mid-exposure → received
        t0, t1 = self._t_mid
        if self.frames_received > 1 and t1 > t0:
            # the frames after the first, over the head time they span: a rate the host's
            # reading schedule (frames read in a burst on a loaded host) cannot inflate
            span = t1 - t0
            down, up = (self.wire_bytes - self._first_bytes) / span, self.sent_bytes / span
            out["down_bytes_per_s"], out["up_bytes_per_s"] = down, up
            out["down_bytes_per_frame"] = self.wire_bytes / self.frames_received
            if self.link_preset is not None:
                out["link"] = self.link_preset.name
                out["link_utilisation"] = max(down, up) / self.link_preset.bytes_per_s
        if self.client is not None:
            out.update(self.client.stream_stats)
        return out

    # ------------------------------------------------------------------ worker side
    def _work(self) -> None:
        from ..realtime import join_realtime

        join_realtime()
        while True:
            try:
                job = self._jobs.get(timeout=None if not self.on else 0.0)
            except queue.Empty:
                job = ("wake", None)
            if job is None:
                self._stop_stream_quietly()
                return
            kind, arg = job
            if kind == "wake":
                # not behind the step gate: a frame waits for no slot between steps (its decode
                # and measurement hold the interpreter lock ~0.1 ms; the centroiding is nogil)
                self._stream_turn()
                continue
            gate = self.step_gate
            if gate is not None:
                gate.worker_enter()
                self._holding = True
            try:
                self._run_job(kind, arg)
            finally:
                if gate is not None:
                    self._holding = False
                    gate.worker_exit()

    def _turn_idle(self) -> bool:
        """Fast mode: a stream turn now would do nothing — no set or period change to send,
        no frame waiting, no byte arriving and no head stream step by the end of its read
        (:data:`_READ_ARRIVED_S`), no time sync overdue (one that is only due goes with a
        frame, :meth:`sync_fits`), no head fault or eclipse that its wait
        would switch (``Lockstep.on_time_due``) — so it is not run. Its only trace would be
        the link tap's timeout record."""
        c = self.client
        if c.link is not self._quiet_of:             # the link's quiet_until, looked up once per link
            self._quiet_of, self._quiet = c.link, getattr(c.link, "quiet_until", None)
        quiet = self._quiet
        if quiet is None:
            return False
        lk = self.inline
        end = lk.now() + _READ_ARRIVED_S
        if quiet() <= end or c.frames_waiting or not self._sends.empty() or c.sync_due(end - SYNC_OVERDUE_S) or (
                self._want_period is not None and self._want_period != self.period_us):
            return False
        return lk.on_time is None or (lk.on_time_due is not None and not lk.on_time_due(end))

    def _inline_turn(self) -> None:
        """Fast mode: one stream turn at once, on its own simulated time line."""
        self.inline.run_job(self._stream_turn)

    def _gate_held(self) -> bool:
        """The worker holds the step gate only inside a full-frame or reconnect job."""
        return self._holding and threading.current_thread() is self._thread

    def _run_job(self, kind, arg) -> None:
        """Full frame / reconnect: the stream stops first (both are request/response)."""
        self._stop_stream_quietly()
        post, spans = (arg, None) if kind == "frame" else (None, arg)
        try:
            self._result = self._do(kind, spans)
        except Exception as exc:  # noqa: BLE001 - back to the loop as a result
            self._result = ImageResult(kind, np.nan, np.nan, np.nan, error=exc)
        res = self._result
        src = None if res is None else (res.image if res.image is not None else res.spots)
        if post is not None and res is not None and res.error is None and src is not None:
            try:
                res.measured = post(src)
            except Exception as exc:  # noqa: BLE001
                res.error = exc
        self._done.set()

    def _stop_stream_quietly(self) -> None:
        if self.on and self.client is not None:
            try:
                self.client.stop_stream()
            except DeviceError:
                pass
        with self._lock:
            self.on = False
            self.t_first_host = float("nan")

    def _stream_turn(self) -> None:
        """Send waiting window sets (starting the stream if needed), then take in frames
        until a set waits to be sent or ~one period passed."""
        c = self.client
        try:
            if self._want_period is not None and self._want_period != self.period_us:
                self.period_us = self._want_period
                self._stop_stream_quietly()
            while True:
                try:
                    spans, frame = self._sends.get_nowait()
                except queue.Empty:
                    break
                if not self.on:
                    self._start(spans, frame)
                else:
                    c.send_windows(spans, frame)
            if not self.on:
                return
            # short: a window set waits at most 1 ms (fast mode: what has arrived by now — a
            # wait of 1 µs of the turn's own time reads the link once)
            more = _READ_ARRIVED_S if self.inline is not None else 0.0
            fr = c.next_frame(more if self.inline is not None else min(0.001, self.period_s))
            took = fr is not None
            while fr is not None:
                self._take(fr)
                if not self._sends.empty():
                    break
                fr = c.next_frame(more)
            now = c.clock.now()
            if c.sync_due(now) and ((took and self.sync_fits(now)) or c.sync_due(now - SYNC_OVERDUE_S)):
                c.sync(1)
        except Exception as exc:  # noqa: BLE001 - the link failed: the loop sees an error result
            with self._lock:
                self.on = False
            self._results.append(ImageResult("windows", np.nan, np.nan, np.nan, error=exc))

    def sync_fits(self, now: float) -> bool:
        """A TIME_SYNC exchange started at ``now`` (host s, once this client's queued bytes
        are on the wire) ends before the head reads out the frame after the newest received."""
        with self._lock:
            t_first, n = self.t_first_host, self.last_frame + 1 - self.first_frame
        if t_first != t_first:
            return False
        readout = t_first + n * self.period_s + self.exposure_s
        wire = self.link_preset.wire_time(time_sync_bytes()) if self.link_preset is not None else 0.0
        return readout - max(now, self.client.uplink_idle_at) >= wire + SYNC_GAP_MARGIN_S

    def _start(self, spans, frame: int) -> None:
        """Start the stream with the set the loop planned for ``frame`` (0 or a frame of a
        stream that stopped meanwhile): its frames report set_frame 0."""
        c = self.client
        with self._lock:
            self._start_key = frame       # frames read with the starting set report set_frame 0
        c.set_windows(spans)
        rep = c.start_stream(self.period_us, int(round(self.exposure_s * 1e6)), self.pixel_format)
        with self._lock:
            self.first_frame = rep["first_frame"]
            self.t_first_host = c.sync_state.mcu_to_host(rep["t_first_us"]) if c.sync_state.ready \
                else float("nan")
            self.last_frame = self.first_frame - 1
            self.last_target = self.first_frame
            self.on = True
        self.stream_starts += 1

    def _take(self, fr) -> None:
        """A received frame → result (pixels in the span order of the set it used, measured)."""
        with self._lock:
            self.last_frame = max(self.last_frame, fr.frame)
            key = fr.set_frame or self._start_key
            got = self._sets.get(key)
        self.frames_received += 1
        self.wire_bytes += fr.wire_bytes
        if fr.t_mid_host == fr.t_mid_host:
            age = fr.t_rx - (fr.t_mid_host + 0.5 * fr.exposure_us * 1e-6)      # exposure end → arrival (s)
            if not -CLOCK_CHECK_TOL_S <= age <= FRAME_AGE_MAX_S:
                self.frames_unmatched += 1
                self.unmatched_why["clock"] += 1
                self.client.request_sync()
                return
        t_mid = fr.t_mid_host if fr.t_mid_host == fr.t_mid_host else fr.t_rx     # nan before time sync
        if self._t_mid[0] != self._t_mid[0]:
            self._t_mid[0] = t_mid
            self._first_bytes = fr.wire_bytes
        self._t_mid[1] = t_mid
        self._arrival[self._n_arrival % len(self._arrival)] = fr.t_rx - fr.t_mid_host
        self._n_arrival += 1
        self.head_counters = {"dropped": fr.dropped, "late_sets": fr.late_sets, "backpressure": fr.backpressure}
        if got is None:
            self.frames_unmatched += 1
            self.unmatched_why["no set"] += 1
            return
        spans, post = got
        order = {w.window_id: w.pixels for w in fr.windows}
        ids = list(dict.fromkeys(spans[:, 0].tolist()))      # the set's window ids, in span order
        if any(w not in order for w in ids):
            self.frames_unmatched += 1
            self.unmatched_why["windows differ"] += 1
            return
        values = np.concatenate([order[w] for w in ids]) if ids else np.zeros(0, np.uint16)
        t0 = fr.t_mid_host - 0.5 * fr.exposure_us * 1e-6
        res = ImageResult("windows", t0, t0 + fr.exposure_us * 1e-6, fr.t_mid_host, values=values)
        res.frame, res.set_frame, res.t_rx = fr.frame, key, fr.t_rx
        if post is not None:
            try:
                res.measured = post(values)
            except Exception as exc:  # noqa: BLE001
                res.error = exc
        self._results.append(res)
