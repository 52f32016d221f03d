"""The loop's non-blocking access to the camera head: a worker thread runs the head client.

A CAPTURE takes the exposure time (10 ms) plus the transfers, far longer than a gyro
period (2.5 ms), so the loop never calls the head client itself: it submits a job
(windows + capture, or a full frame) and polls for the result on later steps while the
gyro path keeps running. The worker uses :class:`gyrostar.head.HeadClient` unchanged.

Replay: the worker's link traffic is recorded on the head channel, the client's reads of
the host clock on channel ``CH_HEAD_CLOCK`` (the port gives the client ``head_clock``; it
times its timeouts and time-sync schedule with it), and every poll's answer on
``CH_POLL``; a replayed poll that was "done" waits for the replayed worker to finish the
same job, so the loop sees the same results at the same steps.
"""

from __future__ import annotations

import logging
import queue
import struct
import threading
from dataclasses import dataclass

import numpy as np

from ..errors import DeviceError, GyrostarError
from ..loop.image import LIS_BOX, LIS_HEAD_SPOTS, LIS_SIGMA
from ..recording import logfile as lf

log = logging.getLogger(__name__)

CH_HEAD_CLOCK = 3
CH_POLL = 4
CH_RECONNECT = 6
POLL = 10
lf.KIND_NAMES[POLL] = "poll"


@dataclass
class ImageResult:
    kind: str                 # "windows" | "frame" | "reconnect"
    t_start: float            # exposure start, host s
    t_end: float              # exposure end, host s
    t_mid: float
    values: np.ndarray | None = None   # windows: pixels in span order
    image: np.ndarray | None = None    # frame: (H, W) (full-frame acquisition)
    spots: object = None               # frame: the head's FIND_SPOTS result (gyrostar.head.SpotCapture)
    error: Exception | None = None
    measured: object = None            # frame: what the job's ``post(image or spots)`` returned


def _exposure_times(cap) -> tuple[float, float, float]:
    """Host (start, end, mid) of the integration: it starts at ``t_start_us`` and lasts
    ``exposure_us``; ``t_end_us`` also holds the readout/reply delay, so it is not used."""
    t_start = cap.t_mid_host - 0.5 * (cap.t_end_us - cap.t_start_us) * 1e-6
    t_end = t_start + cap.exposure_us * 1e-6
    return t_start, t_end, 0.5 * (t_start + t_end)


class _GatedLink:
    """The link as the head client sees it when the port has a step gate: a blocking
    receive on the worker leaves the gate meanwhile, so the worker's Python work (encode,
    decode, record) runs between loop steps, never inside one or just before one."""

    def __init__(self, link, port):
        self._link = link
        self._port = port

    def recv(self, timeout: float):
        held = self._port._gate_held()
        if held:
            self._port.step_gate.worker_exit()
        try:
            return self._link.recv(timeout)
        finally:
            if held:
                self._port.step_gate.worker_enter()

    def __getattr__(self, name):
        return getattr(self._link, name)


class HeadPort:
    """Jobs for the head on a worker thread; ``poll()`` returns finished results."""

    def __init__(self, link, clock, timeout_s=0.05, retries=2, exposure_s=0.010, gain=1, reconnect=None,
                 head_clock=None, poll_log=None, replay_polls=None, replay_reconnects=None, inline=None,
                 acquire: str = "spots", link_preset=None):
        self.link = link
        self.link_preset = link_preset         # gyrostar.transport.linkrate.LinkPreset, or None
        self.clock = clock
        self.head_clock = head_clock if head_clock is not None else clock
        self.timeout_s = timeout_s
        self.retries = retries
        self.exposure_s = exposure_s
        self.gain = gain
        self._reconnect = reconnect
        self._poll_log = poll_log              # LogWriter when recording
        self._replay_polls = replay_polls      # deque of recorded poll answers when replaying
        self._replay_reconnects = replay_reconnects
        self.client = None
        self.info = None
        self._job = None
        self._thread = None
        self._done = threading.Event()
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._result: ImageResult | None = None
        # real-time runs: the loop's StepGate (gyrostar.loop.scheduler; see _GatedLink); None: off
        self.step_gate = None
        # fast mode: the lock-step schedule (gyrostar.hil.lockstep.Lockstep) runs each job at
        # once, no worker thread, on the job's own simulated time line (``run_job(fn)`` →
        # finish time, ``now()``); its result is polled from that finish time on
        self.inline = inline
        self.acquire = acquire                 # lost-in-space image: "spots" (FIND_SPOTS) | "full_frame"
        self.spots_unsupported = False         # the firmware answered FIND_SPOTS with UNKNOWN_TYPE
        self._ready_at: float | None = None

    # ------------------------------------------------------------------ set-up
    def start(self, exposure_s: float | None = None) -> None:
        from ..head import HeadClient

        if exposure_s:
            self.exposure_s = exposure_s
        link = _GatedLink(self.link, self) if self.step_gate is not None else self.link
        # first sequence number from the (recorded) clock, not a random draw: a new client
        # still differs from the last one, and a replay sends the same bytes
        first = (int(self.head_clock.now() * 1e6) & 0xFFFF) or 1
        self.client = HeadClient(link, timeout=1.0, retries=self.retries, clock=self.head_clock,   # set-up: patient
                                 first_seq=first, link_preset=self.link_preset)
        self.info = self.client.get_info()
        if getattr(self, "streaming", False):
            self.client.stop_stream()     # a head that kept streaming for an earlier client stops
        self.client.set_exposure(int(round(self.exposure_s * 1e6)))
        self.client.sync(8)
        self.client.timeout = self.timeout_s + 0.2
        if self.inline is None and threading.current_thread() is not self._thread:
            self._start_worker()          # now, not inside the loop's first step

    def limits(self) -> dict:
        i = self.info or {}
        return {k: i.get(k) for k in ("width", "height", "max_windows", "max_spans", "max_window_pixels",
                                      "pixel_budget", "frame_chunk_max")}

    def submit_reconnect(self) -> None:
        """Reopen the link and redo the set-up, on the worker (the loop keeps running).
        The result is a job of kind "reconnect" (``error`` set while the head is away)."""
        self._submit("reconnect", None)

    def _reconnect_now(self) -> None:
        if self._replay_reconnects is not None:
            if not self._replay_reconnects:
                from ..recording.taps import ReplayExhausted

                raise ReplayExhausted("head reconnects")
            if not self._replay_reconnects.popleft():
                raise DeviceError("head still away (replayed reconnect failure)")
        elif self._reconnect is not None:
            try:
                link = self._reconnect()
            except DeviceError:
                self._log_reconnect(0)
                raise
            self._log_reconnect(1)
            if link is not None:
                self.link = link
        self.start(self.exposure_s)

    def _log_reconnect(self, value: int) -> None:
        if self._poll_log is not None:
            self._poll_log.append(POLL, struct.pack("<B", value), CH_RECONNECT)

    def _log_poll(self, value: int) -> None:
        if self._poll_log is not None:
            self._poll_log.append(POLL, struct.pack("<B", value), CH_POLL)

    def _wait_idle(self, timeout: float) -> None:
        if self._job is not None:
            self._done.wait(timeout)

    def close(self) -> None:
        t = self._thread
        if t is not None and t.is_alive():
            self._wait_idle(2.0)
            self._jobs.put(None)
            t.join(timeout=2.0)

    # ------------------------------------------------------------------ jobs
    @property
    def busy(self) -> bool:
        return self._job is not None

    @property
    def job_done(self) -> bool:
        """The job in flight has finished (its result waits for :meth:`poll`)."""
        return self._done.is_set() and (self._ready_at is None or self.inline.now() >= self._ready_at)

    def ready(self) -> bool:
        """A result waits for :meth:`poll` (the loop's runner steps for it). Logs nothing."""
        return self._job is not None and self._replay_polls is None and self.job_done

    def submit_windows(self, spans: np.ndarray) -> None:
        self._submit("windows", spans)

    def submit_frame(self, post=None) -> None:
        """A lost-in-space image: the spot windows the head finds itself (FIND_SPOTS, when
        ``acquire == "spots"`` and the firmware has it) or a full frame; ``post(image or
        spots)`` (optional, e.g. spot centroids and identification) runs on the worker after
        the read, outside the step gate, and its return value comes back as
        ``ImageResult.measured``."""
        self._submit("frame", post)

    def _submit(self, kind, spans) -> None:
        if self._job is not None:
            raise GyrostarError("head port: a job is already in flight")
        self._job = (kind, spans)
        self._done.clear()
        self._result = None
        if self.inline is not None:
            self._ready_at = self.inline.run_job(lambda: self._run_job(kind, spans))
            return
        self._start_worker()
        self._jobs.put((kind, spans))

    def _start_worker(self) -> None:
        if self._thread is None or not self._thread.is_alive():
            self._jobs = queue.SimpleQueue()
            self._thread = threading.Thread(target=self._work, name="head-port", daemon=True)
            self._thread.start()

    def _work(self) -> None:
        from ..realtime import join_realtime

        join_realtime()
        while True:
            job = self._jobs.get()
            if job is None:
                return
            self._run_job(*job)

    def _run_job(self, kind, spans) -> None:
        """One job (on the worker, or at once in fast mode): its result, then done."""
        post = None
        if kind == "frame":
            post, spans = spans, None
        gate = self.step_gate
        if gate is not None:
            gate.worker_enter()
        try:
            self._result = self._do(kind, spans)
        except Exception as exc:  # noqa: BLE001 - every failure goes back to the loop as a result
            self._result = ImageResult(kind, np.nan, np.nan, np.nan, error=exc)
        finally:
            if gate is not None:
                gate.worker_exit()
        res = self._result
        src = None if res is None else (res.image if res.image is not None else res.spots)
        if post is not None and res is not None and res.error is None and src is not None:
            try:
                res.measured = post(src)
            except Exception as exc:  # noqa: BLE001 - reported to the loop like a device failure
                res.error = exc
        self._done.set()

    def _gate_held(self) -> bool:
        """Inside a job the worker holds the gate (set-up on the loop's thread does not)."""
        return self.step_gate is not None and threading.current_thread() is self._thread

    def _do(self, kind, spans) -> ImageResult:
        if kind == "reconnect":
            self._reconnect_now()
            return ImageResult("reconnect", np.nan, np.nan, np.nan)
        c = self.client
        if kind == "windows":
            cap = c.capture_windows(spans)      # SET_WINDOWS, CAPTURE, WINDOW_DATA back to back
            order = {w.window_id: w.pixels for w in cap.windows}
            ids = []
            for wid in spans[:, 0]:
                if not ids or ids[-1] != wid:
                    ids.append(int(wid))
            missing = [w for w in ids if w not in order]
            if missing:
                raise DeviceError(f"WINDOW_DATA lacks windows {missing[:4]}")
            values = np.concatenate([order[w] for w in ids]) if ids else np.zeros(0, np.uint16)
            n = int(np.sum(spans[:, 3] - spans[:, 2]))
            if len(values) != n:
                raise DeviceError(f"window data has {len(values)} pixels, the spans {n}")
            t0, t1, tm = _exposure_times(cap)
            return ImageResult("windows", t0, t1, tm, values=values)
        if self.acquire == "spots" and not self.spots_unsupported:
            from ..protocol.errors import UnknownTypeError

            try:
                sc = c.find_spots(LIS_SIGMA, LIS_HEAD_SPOTS, LIS_BOX)
            except UnknownTypeError:
                self.spots_unsupported = True
                log.warning("the head's firmware has no FIND_SPOTS: acquiring from full frames")
            else:
                t0, t1, tm = _exposure_times(sc.capture)
                return ImageResult("frame", t0, t1, tm, spots=sc)
        # full frame: one small window keeps CAPTURE legal; the frame is read in chunks
        w, h = int(self.info["width"]), int(self.info["height"])
        c.set_windows(np.array([[0, h // 2, w // 2, w // 2 + 1]], np.int32))
        cap = c.capture(fetch=False)
        saved, c.timeout = c.timeout, max(c.timeout, 2.0)   # the first chunk waits for a full render
        try:
            img, _ = c.full_frame()
        finally:
            c.timeout = saved
        t0, t1, tm = _exposure_times(cap)
        return ImageResult("frame", t0, t1, tm, image=img)

    def poll(self) -> ImageResult | None:
        """The finished job's result (and the port is free again), or None while in flight."""
        if self._job is None:
            return None
        if self._replay_polls is not None:
            if not self._replay_polls:
                from ..recording.taps import ReplayExhausted

                raise ReplayExhausted("head polls")
            done = self._replay_polls.popleft()
            if done:
                self._done.wait()
        else:
            done = self.job_done
            self._log_poll(int(done))
        if not done:
            return None
        res = self._result
        self._job = None
        self._result = None
        self._ready_at = None
        return res
