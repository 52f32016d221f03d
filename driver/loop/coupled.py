"""The coupled 400/100 Hz loop: gyro FIFO → predict; windows → head → centroid → update.

One :meth:`CoupledLoop.step` (called every gyro period by a scheduler, or as fast as
possible on a simulated clock):

1. read the gyro FIFO (:class:`gyrostar.gyro.GyroDevice`); for every new sample predict
   the attitude MEKF (quaternion + gyro drift, :mod:`gyrostar.core.mekf`) and every tracked
   star's centroid (its catalog vector through the predicted attitude and the camera),
   and emit one output record (:mod:`gyrostar.loop.record`) to the sinks — before any image
   work, so the sample-to-output latency is the predict cost only;
2. image cycle at ``frame_hz`` (through :class:`gyrostar.hil.headport.HeadPort`, a worker
   thread, so the gyro path never waits for an exposure): when the windows' pixels of the
   last exposure arrive, centroid each window (CoG to find the spot, then the smeared-PSF
   fit of :mod:`gyrostar.core.centroid` along the predicted trajectory), carry the
   measured direction from exposure mid-time to now with the gyro-propagated attitude,
   update the MEKF with all stars at once (χ² gated per star), drop stars that keep failing
   the gate (wrong or lost identification); then predict each star's trajectory over the
   next exposure from the latest bias-corrected rate (:mod:`gyrostar.core.motion`, the
   spot motion of paper 000), build its window (union of k×k squares,
   :mod:`gyrostar.core.windows`), command the windows and the next exposure.

Modes: ACQUIRE (full frame → spot detection → Pyramid, :mod:`gyrostar.starid.pyramid`) →
TRACK (≥ ``min_stars`` spots updated by the last image) → COAST (fewer: the spots and the
attitude run on the bias-corrected gyro alone) → TRACK when stars come back, or ACQUIRE
after ``coast_timeout_s``. Stars entering the field are predicted from the catalog with
the current attitude (the gyro-extended field) and tracked from their first window.

Everything the loop depends on is passed in (gyro device, head port, clock, camera, star
index, identifier), so the same code runs on real devices, on mocks, and on the replay
taps of :mod:`gyrostar.recording`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.mekf import mekf_predict
from ..errors import DeviceError, GyrostarError
from ..gyro.convert import FLAG_GAP, FLAG_SATURATED, FLAG_STUCK_AXIS
from ..head.client import HeadTimeoutError
from . import record as R
from .kernels import project_refs

log = logging.getLogger(__name__)

HIST = 2048              # gyro samples of history (5 s at 400 Hz) for delayed measurements
GATE = 13.815510557964274  # χ² 2 dof, P = 0.001
MODEL = 1                # core.motion.MODEL_PINHOLE


@dataclass
class LoopParams:
    """Tuning of the loop (defaults suit the xing2012 preset and a BMI088-class gyro)."""

    frame_hz: float = 100.0
    exposure_s: float = 0.010
    window_k: int = 6
    max_stars: int = 12
    min_stars: int = 2
    coast_timeout_s: float = 5.0
    acquire_every_s: float = 0.5
    mag_limit: float = 6.5
    e_per_dn: float = 5.0             # detector gain, e⁻ per DN (shot noise in centroid variances)
    gyro_noise_density: float = 2.44e-4  # gyro rate noise density, rad/s/√Hz (BMI088: 0.014 °/s/√Hz)
    sigma_bias_rw: float = 1e-6       # drift random walk, rad/s/√s
    psf_sigma_px: float = 0.85        # PSF σ of the optics (px), for the smeared-spot fit
    bias_prior: float = 0.02          # initial drift uncertainty, rad/s (≈ 1.1 °/s: BMI088 offset ±1 °/s)
    min_signal: float = 30.0          # window flux (DN above background) to accept a centroid
    thresh_sigma: float = 4.0         # CoG threshold above the window background, in noise σ
    max_misses: int = 50              # frames without a centroid before a spot is dropped (TRACK)
    pixel_budget: int = 8192          # head limits (GET_INFO)
    max_window_pixels: int = 2048
    max_spans: int = 512
    pyramid_sigma_px: float = 0.5


@dataclass
class Counters:
    gyro_samples: int = 0
    samples_lost: int = 0
    gyro_gaps: int = 0
    gyro_errors: int = 0
    gyro_saturated: int = 0        # samples with an axis at the range limit
    gyro_stuck: int = 0            # samples flagged with a stuck axis (≥ 32 unchanged frames)
    gyro_register_faults: int = 0  # gyro configuration found lost in flight and restored (silent reset)
    frames: int = 0
    frames_failed: int = 0
    frames_unmatched: int = 0      # streamed frames whose window plan was gone (stream mode)
    full_frames: int = 0
    acquisitions: int = 0
    acquisition_failures: int = 0
    updates: int = 0
    rejected_updates: int = 0
    wrong_ids_dropped: int = 0
    head_errors: int = 0
    head_reconnects: int = 0
    outputs: int = 0
    mode_changes: list = field(default_factory=list)


class CoupledLoop:
    """The loop. ``sinks`` get each step's output records (``put(records, t_ns)``)."""

    def __init__(self, params: LoopParams, clock, gyro, head, camera, star_index, identifier, sinks=(),
                 lat_clock=None, irq=None, link_budget=None):
        from ..gyro import GyroSamples

        self.irq = irq           # FIFO-watermark interrupt line: irq.now() = host time of the last edge
        self.p = params
        self.clock = clock
        self.lat_clock = clock if lat_clock is None else lat_clock
        self.t_step_prev: float | None = None
        self.overruns = 0
        self.gyro = gyro
        self.head = head
        self.camera = camera
        self.cam = camera.as_array()
        self.f_px = camera.focal_length_px
        self.index = star_index
        self.identifier = identifier
        self.sinks = list(sinks)
        self.c = Counters()
        self.samples = GyroSamples(256)
        S = R.MAX_STARS
        self.active = np.zeros(S, np.bool_)
        self.ref = np.zeros((S, 3))
        self.star_nav = -np.ones(S, np.int64)      # navigation-star index of each slot
        self.star_id = -np.ones(S, np.int32)       # catalog id
        self.misses = np.zeros(S, np.int64)
        self.rejects = np.zeros(S, np.int64)
        self.seen = np.zeros(S, np.bool_)          # accepted by the filter at least once
        self.uv = np.zeros((S, 2))                 # predicted centroid (col, row) px
        self.hist_t = np.full(HIST, -np.inf)
        self.hist_q = np.zeros((HIST, 4))          # attitude estimate at each gyro sample
        self.h = -1
        self.q = np.array([0.0, 0.0, 0.0, 1.0])   # ACQUIRE: gyro-relative attitude from the start
        self.q_valid = False
        self.bias = np.zeros(3)
        self.P = np.zeros((6, 6))
        self.P[:3, :3] = np.eye(3) * 1e-2
        self.P[3:, 3:] = np.eye(3) * params.bias_prior ** 2
        self.omega = np.zeros(3)
        self.mode = R.MODE_ACQUIRE
        self.t_last: float | None = None
        self.seq = 0
        self.flags_pending = 0
        self.last_image_flags = R.FLAG_FEW_STARS
        self.id_verified = False
        self.coast_since: float | None = None
        self.confirm_failures = 0
        self.next_frame_t = -np.inf
        self.next_acquire_t = -np.inf
        self.pending = None            # the windows in flight: spans and slots
        self.head_down_since: float | None = None
        self.timeouts = 0              # consecutive head jobs without an answer
        self.exposure_lag = 0.002      # s from commanding windows to the exposure start (EMA)
        self.lag_jitter = 0.001        # s, mean deviation of that lag
        self.next_reconnect_t = -np.inf
        self.out_buf = R.empty(256)
        self._blank = R.empty(1)[0]
        self.last_output = None
        self.measuring = None          # (pending, result, future) of the readout being centroided
        self._pool = None
        # streaming head (gyrostar.hil.streamport): plans by stream frame, link budget,
        # exposure → output latency (mid-exposure to the first output holding its update)
        self.streaming = bool(getattr(head, "streaming", False))
        self.budget = link_budget
        self.plans: dict = {}
        self.last_commanded = 0
        self.stream_start_wait = -np.inf
        self._mids: list = []
        self.e2o = np.zeros(1 << 16)
        self.n_e2o = 0
        self.frame_t = [np.nan, np.nan]        # mid-exposure of the first and last frame used
        self.few_run = 0                       # consecutive images that updated too few stars

    # ------------------------------------------------------------------ set-up
    def warm_identifier(self) -> float:
        """Compile/load the identifier's numba code on a synthetic field; returns seconds."""
        import time

        from ..attitude import quat_from_boresight
        from .kernels import project_refs

        t0 = time.perf_counter()
        q = quat_from_boresight(1.0, 0.5, 0.0)
        bore = np.array([np.cos(0.5) * np.cos(1.0), np.cos(0.5) * np.sin(1.0), np.sin(0.5)])
        radius = math.atan(0.5 * self.camera.width_px / self.f_px)
        cand = self.index.cone(bore, radius, self.p.mag_limit)
        if len(cand) >= 3:
            uv, ok = project_refs(self.cam, q, np.ascontiguousarray(self.index.vectors[cand]))
            self.identifier.identify(np.ascontiguousarray(uv[ok][:30]))   # > max_stars: labelling too
        return time.perf_counter() - t0

    def start(self) -> None:
        """Configure and start the devices (head exposure, gyro FIFO)."""
        self.head.start(self.p.exposure_s)
        self.gyro.start()
        self.t_last = None

    # ------------------------------------------------------------------ the step
    def step(self) -> int:
        """One loop step; returns the number of outputs emitted.

        A step that starts more than 1.5 gyro periods after the previous one is an overrun
        (flagged on the next output and counted), judged on the loop's own clock.
        """
        t_step = self.clock.now()
        if self.t_step_prev is not None and self.gyro.odr_hz > 0 \
                and t_step - self.t_step_prev > 1.5 / self.gyro.odr_hz:
            self.overruns += 1
            self.flags_pending |= R.FLAG_OVERRUN
        self.t_step_prev = t_step
        if self.streaming:
            # a streamed frame arrives already measured: its update goes into this step's outputs
            self._image_phase_guarded()
            return self._gyro_phase()
        n_out = self._gyro_phase()
        self._image_phase_guarded()
        return n_out

    def _image_phase_guarded(self) -> None:
        try:
            self._image_phase()
        except DeviceError as exc:
            self._count_head_error(exc)
            self._head_failed(exc)

    def _gyro_phase(self) -> int:
        smp = self.samples
        smp.clear()
        try:
            edge = self.irq.now() if self.irq is not None else None
            self.gyro.read(smp, event_time=edge if edge is not None and edge == edge else None)
        except DeviceError as exc:
            self.c.gyro_errors += 1
            self.flags_pending |= R.FLAG_GYRO_GAP
            log.debug("gyro read failed: %s", exc)
        t_read = self.lat_clock.now()
        self.c.gyro_register_faults += smp.register_faults
        n = smp.n
        if n == 0:
            return 0
        if smp.gap_frames:
            self.c.samples_lost += int(smp.gap_frames)
            self.c.gyro_gaps += int(smp.gaps)
        out = self.out_buf[:n]
        out[:] = self._blank
        period = 1.0 / self.gyro.odr_hz
        act = np.flatnonzero(self.active)
        for i in range(n):
            t = smp.t[i]
            w = smp.rate[i]
            dt = period if self.t_last is None else t - self.t_last
            if not 0.0 < dt < 2.0:      # across a FIFO gap: propagate over it (P grows accordingly)
                dt = period
            self.t_last = t
            mekf_predict(self.q, self.bias, self.P, w, dt, self.p.gyro_noise_density, self.p.sigma_bias_rw)
            self.h = (self.h + 1) % HIST
            self.hist_t[self.h] = t
            self.hist_q[self.h] = self.q
            self.omega = w - self.bias
            flags = self.flags_pending | self.last_image_flags
            self.flags_pending = 0
            if smp.flags[i] & FLAG_GAP:
                flags |= R.FLAG_GYRO_GAP
            if smp.flags[i] & FLAG_SATURATED:
                flags |= R.FLAG_GYRO_SATURATED
            if smp.flags[i] & FLAG_STUCK_AXIS:
                flags |= R.FLAG_GYRO_STUCK
                self.c.gyro_stuck += 1
            if self.q_valid and self.mode != R.MODE_ACQUIRE:
                flags |= R.FLAG_ATTITUDE_VALID
            if self.id_verified:
                flags |= R.FLAG_ID_VERIFIED
            if max(self.P[3, 3], self.P[4, 4], self.P[5, 5]) < (1e-4) ** 2:
                flags |= R.FLAG_BIAS_CONVERGED
            if self.head_down_since is not None:
                flags |= R.FLAG_HEAD_LOST
            o = out[i]
            o["t"] = t
            o["seq"] = self.seq
            self.seq += 1
            o["mode"] = self.mode
            o["flags"] = flags
            o["q"] = self.q
            o["omega"] = self.omega
            o["bias"] = self.bias
            o["cov"] = self.P
            if len(act) and self.q_valid:
                uv, _ = project_refs(self.cam, self.q, self.ref[act])
                self.uv[act] = uv
                k = len(act)
                o["star_id"][:k] = self.star_id[act]
                o["centroid_px"][:k] = uv
                o["n_stars"] = k
        self.c.gyro_samples += n
        self.c.gyro_saturated += int(smp.saturated)
        t_out = self.lat_clock.now()
        out["latency_us"] = (t_out - t_read) * 1e6
        for sink in self.sinks:
            sink.put(out, int(self.t_last * 1e9))
        self.last_output = out[n - 1].copy()
        if self._mids:
            for t_mid in self._mids:
                self.e2o[self.n_e2o % len(self.e2o)] = t_out - t_mid
                self.n_e2o += 1
            self._mids.clear()
        self.c.outputs += n
        return n

    # ------------------------------------------------------------------ images
    def _image_phase(self) -> None:
        now = self.clock.now()
        if self.streaming:
            self._stream_phase(now)
            return
        if self.measuring is not None:
            pend, res, fut = self.measuring
            self.measuring = None
            self._process_windows(pend, res, fut.result(), now)
        res = self.head.poll()
        if res is not None and res.kind == "reconnect":
            if res.error is None:
                self.c.head_reconnects += 1
                log.info("head link back after %.2f s", now - self.head_down_since)
                self.head_down_since = None
                self.timeouts = 0
            else:
                log.debug("head still away: %s", res.error)
            res = None
        if self.head_down_since is not None:
            if not self.head.busy and now >= self.next_reconnect_t:
                self.next_reconnect_t = now + 0.25
                self.pending = None
                self.head.submit_reconnect()
            return
        pend = None
        if res is not None:
            pend, self.pending = self.pending, None
        if res is not None and res.error is None and res.kind == "windows" and pend is not None:
            # centroid the readout on the measuring thread (nogil kernel) while this step
            # plans the next exposure; the update is applied at the next step
            self.measuring = (pend, res, self._measure_pool().submit(self._measure, pend, res.values))
        if res is not None and res.error is None and res.kind == "windows" and self.mode != R.MODE_ACQUIRE \
                and now >= self.next_frame_t - 0.5 / self.p.frame_hz:
            # next exposure first (windows from the prediction), then this image's update:
            # the head exposes while the loop centroids
            self.next_frame_t = max(self.next_frame_t + 1.0 / self.p.frame_hz, now)
            self._command_windows(now)
        if res is not None:
            if res.error is not None:
                self.c.frames_failed += 1
                self.last_image_flags |= R.FLAG_LINK_ERROR
                self._count_head_error(res.error)
                self.timeouts = self.timeouts + 1 if isinstance(res.error, HeadTimeoutError) else 0
                if _link_closed(res.error) or self.timeouts >= 3:
                    self._head_failed(res.error)
                    return
                if res.kind == "windows":
                    self._after_image(now, updated=0)
            elif res.kind == "frame":
                self.timeouts = 0
                self.c.full_frames += 1
                self._acquire(res, now)
            else:
                self.timeouts = 0
        if self.head.busy:
            return
        if self.mode == R.MODE_ACQUIRE and not self.q_valid:
            if now >= self.next_acquire_t:
                self.next_acquire_t = now + self.p.acquire_every_s
                self.head.submit_frame(self._lost_in_space)
            return
        if now >= self.next_frame_t:
            self.next_frame_t = max(self.next_frame_t + 1.0 / self.p.frame_hz, now)
            self._command_windows(now)

    def _stream_phase(self, now: float) -> None:
        """Streaming head: take in the frames the port has measured, command the windows of
        the frame two ahead of the newest one (while the next one integrates)."""
        head = self.head
        while True:
            res = head.poll()
            if res is None:
                break
            if res.kind == "reconnect":
                if res.error is None:
                    self.c.head_reconnects += 1
                    log.info("head link back after %.2f s", now - (self.head_down_since or now))
                    self.head_down_since = None
                    self.timeouts = 0
                else:
                    log.debug("head still away: %s", res.error)
                continue
            if res.error is not None:
                self.c.frames_failed += 1
                self.last_image_flags |= R.FLAG_LINK_ERROR
                self._count_head_error(res.error)
                if res.kind == "frame" or _link_closed(res.error) or isinstance(res.error, HeadTimeoutError):
                    self._head_failed(res.error)
                    return
                continue
            if res.kind == "frame":
                self.c.full_frames += 1
                self._acquire(res, now)
                continue
            pend = self.plans.get(res.set_frame)
            if pend is None or res.measured is None:
                self.c.frames_unmatched += 1
                continue
            self._process_windows(pend, res, res.measured, now)
            self._mids.append(res.t_mid)
            if self.frame_t[0] != self.frame_t[0]:
                self.frame_t[0] = res.t_mid
            self.frame_t[1] = res.t_mid
        if self.head_down_since is not None:
            if not head.busy and now >= self.next_reconnect_t:
                self.next_reconnect_t = now + 0.25
                self.plans.clear()
                self.last_commanded = 0
                head.submit_reconnect()
            return
        if head.busy:
            return
        if self.mode == R.MODE_ACQUIRE and not self.q_valid:
            if now >= self.next_acquire_t:
                self.next_acquire_t = now + self.p.acquire_every_s
                self.plans.clear()
                self.last_commanded = 0
                head.submit_frame(self._lost_in_space)
            return
        frame, t_exp = head.next_target(now)
        if frame == 0:
            if now >= self.stream_start_wait:              # the set that starts the stream
                self.stream_start_wait = now + 0.2
                self.last_commanded = 0
                self._command_windows(now, 0, t_exp)
        elif frame > self.last_commanded:
            self.last_commanded = frame
            self._command_windows(now, frame, t_exp)

    def stream_summary(self) -> dict:
        """Frame rate, exposure → output latency and the link budget's actions (streaming)."""
        out: dict = {}
        n = min(self.n_e2o, len(self.e2o))
        if n:
            lat = self.e2o[:n] * 1e3
            out["exposure_to_output_ms_p50"] = float(np.median(lat))
            out["exposure_to_output_ms_p99"] = float(np.percentile(lat, 99))
        t0, t1 = self.frame_t
        if self.c.frames > 1 and t1 > t0:
            out["frame_rate_hz"] = (self.c.frames - 1) / (t1 - t0)
        if self.budget is not None:
            out["link_budget"] = self.budget.summary()
        return out

    def _count_head_error(self, exc: Exception) -> None:
        self.c.head_errors += 1
        log.debug("head error: %s", exc)

    def _head_failed(self, exc: Exception) -> None:
        """The link is down (closed, no answer after retries): COAST and reconnect."""
        self.pending = None
        if self.head_down_since is None:
            self.head_down_since = self.clock.now()
            self.next_reconnect_t = self.head_down_since + 0.25
            log.info("head link lost: %s", exc)
        self.last_image_flags |= R.FLAG_LINK_ERROR | R.FLAG_FEW_STARS
        if self.mode == R.MODE_TRACK:
            self._set_mode(R.MODE_COAST, self.head_down_since)

    # -- ACQUIRE ----------------------------------------------------------------
    def _lost_in_space(self, image: np.ndarray):
        """Spots of a full frame and their identification: ``(spots, ident or None)``.
        Runs on the head port's worker, off the loop's steps; reads no loop state."""
        from .acquire import detect_spots

        spots = detect_spots(image.astype(np.float64), 6.0, 40, 7)
        if len(spots) < 3:
            return spots, None
        return spots, self.identifier.identify(np.ascontiguousarray(spots[:, :2]))

    def _acquire(self, res, now: float) -> None:
        spots, ident = res.measured          # _lost_in_space ran on the head worker
        self.c.acquisitions += 1
        if ident is None:
            self.c.acquisition_failures += 1
            return
        if not ident.ok or ident.n_identified < 3:
            self.c.acquisition_failures += 1
            log.debug("acquisition failed: %s", ident.status)
            return
        # attitude at exposure mid-time → now along the gyro-propagated attitude history
        from ..attitude import quat_conj, quat_mult, quat_normalize

        q_rel_mid = self._hist_q_at(res.t_mid)
        dq = quat_mult(self.q, quat_conj(q_rel_mid))          # rotation mid → now
        self.q = quat_normalize(quat_mult(dq, np.asarray(ident.q, np.float64)))
        self.q_valid = True
        # error now = error at mid-exposure − Δb·Δt: the unknown drift acted since then
        lag = max(now - res.t_mid, 0.0)
        pbb = self.P[3:, 3:].copy()
        self.P[:3, :3] = np.eye(3) * (2.0 * self.p.pyramid_sigma_px / self.f_px) ** 2 + pbb * lag * lag
        self.P[:3, 3:] = -pbb * lag
        self.P[3:, :3] = -pbb * lag
        self._clear_stars()
        self._add_stars_from_catalog(now)
        log.info("acquired: %d stars identified (p_false %.2g)", ident.n_identified, ident.p_false)
        # the mode turns to TRACK at the first image whose stars pass the filter's gate
        self.confirm_failures = 0
        self.next_frame_t = now

    # -- TRACK / COAST --------------------------------------------------------------
    def _command_windows(self, now: float, frame: int | None = None, t_exp: float | None = None) -> None:
        """Plan and command windows: for the next CAPTURE, or (streaming) for stream frame
        ``frame`` whose exposure starts at host time ``t_exp``."""
        from ..core.motion import substeps_for
        from .image_kernels import plan_windows
        from .kernels import project_refs

        self._add_stars_from_catalog(now)
        act = np.flatnonzero(self.active)
        if not len(act):
            self._after_image(now, updated=0)
            return
        order = act[np.argsort(self._slot_mag(act), kind="stable")]      # brightest first (budget)
        uv, _ = project_refs(self.cam, self.q, self.ref[order])
        # the exposure starts when the head gets CAPTURE, ~lat s from now (measured)
        m = max(1, int(round(self.p.exposure_s * self.gyro.odr_hz)))
        lag = self.exposure_lag if t_exp is None else max(t_exp - now, 0.0)
        m_lat = int(round(lag * self.gyro.odr_hz))
        rates = np.repeat((self.omega + self.bias)[None, :], m + m_lat, axis=0)
        dt = self.p.exposure_s / m
        sub = substeps_for(rates - self.bias, dt, self.f_px, 0.5)
        sig_px = math.sqrt(max(self.P[0, 0], self.P[1, 1])) * self.f_px
        speed = math.sqrt(float(self.omega @ self.omega)) * self.f_px          # px/s near the boresight
        # a streaming head exposes on its own timer: no command-to-exposure jitter to cover
        margin = 3.0 * sig_px + (0.0 if self.streaming else speed * self.lag_jitter)
        k = min(self.p.window_k + 2 * int(math.ceil(margin)), 40)
        pixel_budget, max_spans = self.p.pixel_budget, self.p.max_spans
        if self.budget is not None:
            if not self.budget.margin_allowed():
                k = self.p.window_k                  # degrade step 2: tighter windows
            px, sp = self.budget.limits(len(order))
            pixel_budget, max_spans = min(pixel_budget, px), min(max_spans, sp)
        spans, wins, off, off_start, off_len = plan_windows(
            uv, order.astype(np.int64), rates, dt, self.bias, self.cam, MODEL, sub, m_lat * sub, k,
            self.camera.height_px, self.camera.width_px, pixel_budget, self.p.max_window_pixels,
            max_spans)
        if self.budget is not None:
            div = self.budget.after_plan(now, len(order), len(wins), int(np.sum(spans[:, 3] - spans[:, 2])),
                                         len(spans))
            if div is not None and self.streaming:
                log.info("link %s: frame rate → %.1f Hz", self.budget.link.name, self.budget.frame_hz)
                self.head.set_period(1.0 / self.budget.frame_hz)
        if not len(wins):
            self._after_image(now, updated=0)
            return
        plan = {"spans": spans, "wins": wins, "nav": self.star_nav[wins].copy(), "off": off,
                "off_start": off_start, "off_len": off_len, "t_submit": now}
        if self.streaming:
            self.plans[frame] = plan
            for old in [f for f in self.plans if f < frame - 8]:
                del self.plans[old]
            self.head.submit_windows(spans, frame, lambda values, pl=plan: self._measure(pl, values))
            return
        self.head.submit_windows(spans)
        self.pending = plan

    def _measure_pool(self):
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            from ..realtime import join_realtime

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="loop-measure", initializer=join_realtime)
        return self._pool

    def close(self) -> None:
        """Stop the measuring thread (the devices belong to the caller)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _measure(self, pend: dict, values) -> tuple:
        """Spot directions of a readout (:func:`image_kernels.measure_windows`, nogil)."""
        from .image_kernels import measure_windows

        p = self.p
        vals = np.ascontiguousarray(values, dtype=np.float64)
        return measure_windows(pend["spans"], vals, pend["wins"], pend["off"], pend["off_start"], pend["off_len"],
                               self.cam, p.psf_sigma_px, p.thresh_sigma, p.min_signal, p.e_per_dn, 10, 1e-3)

    def _process_windows(self, pend: dict, res, measured: tuple, now: float) -> None:
        from ..attitude import quat_conj, quat_mult, quat_to_dcm
        from ..core.mekf import mekf_update
        from .image_kernels import MEAS_MISS, MEAS_OK

        self.c.frames += 1
        lag = res.t_start - pend["t_submit"]
        if 0.0 <= lag < 0.1:
            self.lag_jitter = 0.9 * self.lag_jitter + 0.1 * abs(lag - self.exposure_lag)
            self.exposure_lag = 0.9 * self.exposure_lag + 0.1 * lag
        state, b_mid, sig = measured
        wins = pend["wins"]
        live = self.active[wins] & (self.star_nav[wins] == pend["nav"])   # dropped/replaced meanwhile: skip
        self.misses[wins[live & (state == MEAS_MISS)]] += 1
        use = live & (state == MEAS_OK)
        slots = wins[use]
        updated = 0
        if len(slots):
            # rotation body(t_mid) → body(now) from the gyro-propagated attitude history
            q_mid = self._hist_q_at(res.t_mid)
            rot = quat_to_dcm(quat_mult(self.q, quat_conj(q_mid)))
            bvecs = np.ascontiguousarray(b_mid[use] @ rot.T)
            acc = np.zeros(len(slots), np.uint8)
            updated = mekf_update(self.q, self.bias, self.P, bvecs, np.ascontiguousarray(self.ref[slots]),
                                  np.ascontiguousarray(sig[use]), GATE, acc)
            self.c.updates += int(updated)
            good = acc.astype(np.bool_)
            self.misses[slots[good]] = 0
            self.rejects[slots[good]] = 0
            self.seen[slots[good]] = True
            bad = slots[~good]
            self.rejects[bad] += 1
            self.c.rejected_updates += len(bad)
            if updated >= self.p.min_stars:
                for s in bad[self.rejects[bad] >= 5]:
                    self._drop(int(s))
                    self.c.wrong_ids_dropped += 1
        self.id_verified = updated >= 3 and updated == len(slots)
        self._after_image(now, int(updated))

    def _after_image(self, now: float, updated: int) -> None:
        if self.mode == R.MODE_ACQUIRE:
            # confirming a fresh identification: TRACK once an image passes the gate,
            # back to a full frame if none does within 20 images
            if updated >= self.p.min_stars:
                self._set_mode(R.MODE_TRACK, now)
            else:
                self.confirm_failures += 1
                if self.confirm_failures >= 20:
                    self.q_valid = False
                    self._clear_stars()
                    self.c.acquisition_failures += 1
            return
        few = updated < self.p.min_stars
        self.last_image_flags = R.FLAG_IMAGE_UPDATE if updated else 0
        self.few_run = self.few_run + 1 if few else 0
        if few:
            self.last_image_flags |= R.FLAG_FEW_STARS
            # streaming at 100 Hz: one frame read with a late window set is no reason to coast
            if self.mode == R.MODE_TRACK and self.few_run >= (STREAM_FEW_FRAMES if self.streaming else 1):
                self._set_mode(R.MODE_COAST, now)
            elif self.mode == R.MODE_COAST and self.coast_since is not None \
                    and now - self.coast_since > self.p.coast_timeout_s:
                self._set_mode(R.MODE_ACQUIRE, now)
                self._clear_stars()
                self.q_valid = False
                self.next_acquire_t = now
        elif self.mode != R.MODE_TRACK:
            self._set_mode(R.MODE_TRACK, now)
        # drop stars that left the sensor, or were not seen for long while others were
        for s in np.flatnonzero(self.active):
            u, v = self.uv[s]
            off = u < 2 or v < 2 or u > self.camera.width_px - 3 or v > self.camera.height_px - 3
            if off or (self.mode == R.MODE_TRACK and self.misses[s] > self.p.max_misses):
                self._drop(s)

    def _set_mode(self, mode: int, t: float) -> None:
        if mode == self.mode:
            return
        self.c.mode_changes.append((float(t), R.MODE_NAMES[self.mode], R.MODE_NAMES[mode]))
        self.mode = mode
        self.coast_since = t if mode == R.MODE_COAST else None

    # -- star slots ----------------------------------------------------------------
    def _clear_stars(self) -> None:
        self.active[:] = False
        self.seen[:] = False
        self.star_nav[:] = -1
        self.star_id[:] = -1

    def _drop(self, s: int) -> None:
        self.active[s] = False
        self.seen[s] = False
        self.star_nav[s] = -1
        self.star_id[s] = -1

    def _slot_mag(self, slots) -> np.ndarray:
        return np.array([self.index.vmag[self.star_nav[s]] for s in slots]) if len(slots) else np.zeros(0)

    def _add_stars_from_catalog(self, now: float) -> None:
        """Fill free slots with catalog stars the current attitude puts on the sensor
        (the gyro-extended field: the attitude is propagated by the gyro between images)."""
        from ..attitude import quat_to_dcm
        from .kernels import project_refs

        free = [s for s in range(self.p.max_stars) if not self.active[s]]
        if not free or not self.q_valid:
            return
        boresight = quat_to_dcm(self.q)[2]
        radius = math.atan(0.5 * math.hypot(self.camera.width_px, self.camera.height_px) / self.f_px)
        cand = self.index.cone(boresight, radius, self.p.mag_limit)
        if len(cand) == 0:
            return
        cand = cand[np.argsort(self.index.vmag[cand], kind="stable")]
        uv, ok = project_refs(self.cam, self.q, np.ascontiguousarray(self.index.vectors[cand]))
        margin = self.p.window_k + 8
        inside = ok & (uv[:, 0] > margin) & (uv[:, 1] > margin) \
            & (uv[:, 0] < self.camera.width_px - 1 - margin) & (uv[:, 1] < self.camera.height_px - 1 - margin)
        tracked = set(self.star_nav[self.active].tolist())
        fi = 0
        for j in np.flatnonzero(inside):
            if fi >= len(free):
                break
            nav = int(cand[j])
            if nav in tracked:
                continue
            # a neighbour closer than two windows would share pixels: skip the fainter
            if any(abs(uv[j, 0] - self.uv[t, 0]) < 12 and abs(uv[j, 1] - self.uv[t, 1]) < 12
                   for t in np.flatnonzero(self.active)):
                continue
            s = free[fi]
            self.ref[s] = self.index.vectors[nav]
            self.star_nav[s] = nav
            self.star_id[s] = int(self.index.ids[nav])
            self.active[s] = True
            self.seen[s] = False
            self.misses[s] = 0
            self.rejects[s] = 0
            self.uv[s] = uv[j]
            fi += 1

    # -- history --------------------------------------------------------------------
    def _hist_q_at(self, t: float) -> np.ndarray:
        """Attitude estimate at the newest gyro sample at or before ``t`` (history ring)."""
        if self.h < 0:
            return self.q
        masked = np.where(self.hist_t <= t, self.hist_t, -np.inf)
        best = int(np.argmax(masked))
        best_t = masked[best]
        if not np.isfinite(best_t):
            return self.q
        # propagate from that sample to t with the current rate (≤ one gyro period)
        from ..attitude import quat_propagate

        return quat_propagate(self.hist_q[best], self.omega, t - best_t)

    # ------------------------------------------------------------------ summary
    def counters(self) -> dict:
        c = self.c
        return {k: getattr(c, k) for k in c.__dataclass_fields__ if k != "mode_changes"} | {
            "mode_changes": list(c.mode_changes)}


STREAM_FEW_FRAMES = 3       # streaming: consecutive images with too few stars before COAST (30 ms)


def _link_closed(exc: Exception) -> bool:
    """A failure that means the link itself is gone (port closed or failing)."""
    text = str(exc)
    return "closed" in text or "is down" in text or "failed" in text and "write" in text


def warmup() -> dict:
    """Compile or load every numba function the loop (or its head worker) calls from Python,
    with the argument types it uses, timed (see warmup.py). Kernels called only from inside
    other kernels (centroiding, trajectories, windows) come with their callers."""
    from ..attitude import quat_conj, quat_mult, quat_normalize, quat_propagate, quat_to_dcm
    from ..core.mekf import mekf_init, mekf_predict, mekf_update
    from ..core.motion import substeps_for
    from ..gyro.convert import convert_frames
    from ..protocol.payloads import _unpack10_kernel
    from . import acquire, image_kernels, kernels
    from .warmup import warm

    cam = np.array([6666.0, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    ref = np.array([[0.0, 0.0, 1.0], [0.01, 0.0, 0.99995]])
    w = np.zeros(3)
    spans = np.array([[0, 10, 10, 16], [0, 11, 10, 16]], np.int32)
    vals = np.arange(12, dtype=np.float64)
    rates = np.zeros((4, 3))
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    q, b, P = mekf_init(q0, w, 1e-3, 1e-3)
    img = np.zeros((64, 64))
    calls = [
        (mekf_predict, (q, b, P, w, 0.0025, 1e-4, 1e-6)),
        (mekf_update, (q, b, P, ref, ref, np.array([1e-5, 1e-5]), GATE, np.zeros(2, np.uint8))),
        (kernels.project_refs, (cam, q, ref)),
        (quat_propagate, (q, w, 0.001)),
        (quat_mult, (q, q)),          # acquisition and delayed-measurement transfer
        (quat_conj, (q,)),
        (quat_normalize, (q,)),
        (quat_to_dcm, (q,)),
        (_unpack10_kernel, (np.frombuffer(bytes(20), np.uint8), 16)),   # full-frame chunks (head worker)
        (substeps_for, (rates, 0.0025, 6666.0, 0.25)),
        (acquire.detect_spots, (img, 6.0, 40, 7)),
        (convert_frames, (np.frombuffer(bytes(12), np.uint8), 2, 1e-3, np.eye(3), 0.0, 0.0025, 0.0, 0, 0,
                          np.zeros(8, np.int32), np.zeros(4), np.zeros(4, np.int64), np.zeros((4, 3)),
                          np.zeros(4, np.uint8), 0)),
        (image_kernels.plan_windows, (np.array([[20.0, 20.0]]), np.array([0], np.int64), rates, 0.0025, w, cam,
                                      MODEL, 1, 0, 6, 1024, 1024, 8192, 2048, 512)),
        (image_kernels.measure_windows, (spans, vals, np.array([0], np.int64), np.zeros((2, 2)),
                                         np.array([0], np.int64), np.array([2], np.int64), cam, 0.85, 4.0, 30.0,
                                         5.0, 10, 1e-3)),
    ]
    return warm(calls)


class LoopError(GyrostarError):
    """The loop cannot run with the devices given (e.g. the gyro does not start)."""
