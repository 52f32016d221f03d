"""The coupled 400/100 Hz loop: gyro FIFO → predict; windows → head → centroid → update.

The loop composes one stage per job:

* :mod:`~gyrostar.loop.attitude_filter` — MEKF state and attitude history; every FIFO batch
  in one numba call (:func:`gyrostar.loop.kernels.predict_batch`) that predicts each sample
  and writes each output record (two when a streamed frame's update falls inside the batch:
  the samples stamped before its arrival, then the rest);
* :mod:`~gyrostar.loop.outputs` — latency stamp and the sinks;
* :mod:`~gyrostar.loop.tracks` — tracked stars and the next exposure's windows;
* :mod:`~gyrostar.loop.image` — centroiding on a measuring thread, lost-in-space;
* :mod:`~gyrostar.loop.modes` — the pure mode machine (ACQUIRE → TRACK ⇄ COAST → ACQUIRE);
* :mod:`~gyrostar.loop.mode_keeper` — the mode and the outputs' image flags from each frame's
  outcome (:mod:`~gyrostar.loop.stream_images`: which streamed outcomes it hears);
* :mod:`~gyrostar.loop.step_schedule` — when to step (FIFO watermark, a frame's arrival);
* :mod:`~gyrostar.loop.head_link` — the head link up or down, unanswered jobs, reconnects;
* :mod:`~gyrostar.loop.stream_plans` — the window plans of a streaming head's frames;
* :mod:`~gyrostar.loop.meters` — host time in the 400 Hz path, sample age, exposure → output.

One :meth:`CoupledLoop.step` (every gyro period, from a real-time scheduler or the
lock-step runner of ``gyrostar run --fast``):

1. apply the readout centroided on the measuring thread since the last step (at its
   mid-exposure time, carried to now along the gyro history): the first gyro step after
   the pixels arrived updates the filter before its samples are predicted;
2. read the gyro FIFO and push the batch through the filter's kernel, emit the outputs;
3. image cycle through the head port (a worker thread, so the gyro path never waits for
   an exposure): command the next exposure's windows at once when a readout arrives and
   hand the readout to the measuring thread; in ACQUIRE take full frames whose
   identification runs on the head worker; a lost link (:class:`gyrostar.errors.LinkLostError`,
   or ``head_timeouts_lost`` timeouts in a row) coasts and reconnects.

Everything the loop depends on is passed in (gyro device, head port, clock, camera, star
index, identifier), so the same code runs on real devices, on mocks, in lock-step, and on
the replay taps of :mod:`gyrostar.recording`.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import DeviceError, GyrostarError, LinkLostError
from ..head.client import HeadTimeoutError
from . import modes
from . import record as R
from .attitude_filter import GATE, QD_MARGIN, SMOOTH_GAP_S, AttitudeFilter, fix_covariance
from .floor import FloorInputs, pointing_bias_arcsec
from .frame_kernel import N_ACCEPTED, N_CONSISTENT, N_MEASURED, N_USED, apply_frame
from .head_link import HeadLink
from .image import ImagePipeline
from .image_kernels import MEAS_ABSENT, MEAS_BRIGHT, MEAS_HIT
from .meters import LoopMeters
from .mode_keeper import Heard, ModeKeeper
from .outputs import OutputStage
from .step_schedule import StepSchedule
from .stream_plans import StreamPlans
from .tracks import MODEL, StarTracks

log = logging.getLogger(__name__)
# Which measured stars agree with each other, whatever the prior says: with ≥ 3 stars, QUEST
# over them and iterative rejection of the worst residual beyond CONSISTENT_SIGMA × the median
# centroid σ (at least CONSISTENT_MIN_PX). A window that caught another star, a hot pixel or a
# smeared neighbour is dropped before the χ² gates see it: right after an acquisition those
# gates are wide enough to take it.
CONSISTENT_SIGMA = 6.0     # a star this many median centroid σ off the others' attitude is dropped
CONSISTENT_MIN_PX = 1.5    # ... but never for less than this (px)
CONFIRM_MIN_STARS = 4      # consistent stars the first image after a lost-in-space fix needs to confirm it
CONFIRM_PRIOR_PX = 3.0     # ... and a regain from COAST with an attitude σ above this (px, cross-boresight)

ARCSEC = math.pi / 180.0 / 3600.0


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
    gyro_arw: float = 1.7277e-4       # gyro angle random walk N, rad/√s (BMI088: 0.014 °/s/√Hz one-sided / √2)
    gyro_delay_s: float = 0.0         # group delay of the gyro's low-pass filter, s (compensated)
    gyro_lowpass_hz: float = 47.0     # the gyro's 2nd-order low-pass cut-off, Hz (BMI088 at 400 Hz ODR: 47)
    sigma_bias_rw: float = 1e-6       # drift random walk, rad/s/√s
    gyro_rate_error: float = 0.0      # rate-proportional gyro error after calibration (scale, misalignment), 1σ
    psf_sigma_px: float = 0.85        # PSF σ of the optics (px), for the smeared-spot fit
    bias_prior: float = 0.02          # initial drift uncertainty, rad/s (≈ 1.1 °/s: BMI088 offset ±1 °/s)
    min_signal: float = 30.0          # window flux (DN above background) to accept a centroid
    adc_max_dn: float = 1023.0        # the head's full scale (DN; GET_INFO bits): a background near it is blinding
    thresh_sigma: float = 4.0         # CoG threshold above the window background, in noise σ
    max_misses: int = 50              # frames without a centroid before a spot is dropped (TRACK)
    pixel_budget: int = 8192          # head limits (GET_INFO)
    max_window_pixels: int = 2048
    max_spans: int = 512
    pyramid_sigma_px: float = 0.5
    camera_sigma_px: float = 0.0      # camera-model uncertainty added to every centroid σ (px; 0: exact model)
    camera_bias_px: tuple = (0.0, 0.0)  # 1σ of the camera's principal point (column, row), px: a pointing bias
                                        # common to every star, reported beside the covariance (loop.floor)
    confirm_images: int = 20          # ACQUIRE: images that may fail to confirm an identification
    wrong_id_rejects: int = 5         # gate rejections in a row that drop a star (wrong or lost id)
    neighbour_sep_px: float = 12.0    # a catalog star closer than this (px, per axis) to a tracked one is skipped
    max_track_rate: float = 0.349     # rad/s (20 °/s): faster, the smeared spots are not measured (coast)
    reconnect_every_s: float = 0.25   # s between reconnection attempts while the head is away
    head_timeouts_lost: int = 3       # head jobs in a row without an answer that mean the link is lost
    stream_few_frames: int = 3        # streaming, tracking: images in a row with too few stars before COAST
    stream_gap_frames: int = 3        # streaming: frame periods without a frame before each further one is starless

    def mode_params(self) -> modes.ModeParams:
        return modes.ModeParams(min_stars=self.min_stars, confirm_images=self.confirm_images,
                                coast_timeout_s=self.coast_timeout_s)


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
    frames_stale_windows: int = 0  # streamed frames read with an earlier frame's windows, not used
    full_frames: int = 0
    acquisitions: int = 0
    acquisition_failures: int = 0
    updates: int = 0
    rejected_updates: int = 0
    wrong_ids_dropped: int = 0
    inconsistent_stars: int = 0      # measured stars dropped before the update: off the others' attitude
    frames_blinded: int = 0          # images not measured: background near full scale in most windows (or frame)
    windows_bright: int = 0          # windows whose background was near full scale
    spots_rejected_hit: int = 0      # spots not taken: one-pixel shape or flux far above their star's (hits, glare)
    head_errors: int = 0
    head_reconnects: int = 0
    outputs: int = 0


class CoupledLoop:
    """The loop. ``sinks`` get each step's output records (``put(records, t_ns)``)."""

    def __init__(self, params: LoopParams, clock, gyro, head, camera, star_index, identifier, sinks=(),
                 lat_clock=None, irq=None, link_budget=None, blended=None, cpu_clock=time.thread_time):
        from ..gyro import GyroSamples

        # the gyro path's CPU meter (s): the loop thread's CPU time; a run whose loop and devices
        # share one thread with nothing else running (lock-step) may pass its wall clock, the
        # same reading there without a system call each time
        self.cpu_clock = cpu_clock

        self.irq = irq           # FIFO-watermark interrupt line: irq.now() = host time of the last edge
        self.p = params
        self.clock = clock
        self.lat_clock = clock if lat_clock is None else lat_clock
        self.t_step_prev: float | None = None
        self._t_read = 0.0             # latency-clock time of this step's FIFO read
        self._out = None               # this step's output rows (OutputStage.batch), emitted in order
        self.meters = LoopMeters()     # host time in the 400 Hz path, sample ages, exposure → output
        self._split = 0                # streaming: samples of this step already predicted
        self.schedule = StepSchedule()      # when to step: last step, newest sample, newest frame
        self.overruns = 0
        self.gyro = gyro
        self.head = head
        self.camera = camera
        self.cam = camera.as_array()
        self.f_px = camera.focal_length_px
        self.index = star_index
        self.c = Counters()
        self.samples = GyroSamples(256)
        self.filter = AttitudeFilter(params.gyro_arw, params.sigma_bias_rw, params.bias_prior,
                                     1.0 / gyro.odr_hz if gyro.odr_hz else 0.0025, params.gyro_delay_s,
                                     params.gyro_lowpass_hz, params.gyro_rate_error)
        self.tracks = StarTracks(params, camera, star_index, blended)
        self.image = ImagePipeline(params, camera, identifier)
        self.outputs = OutputStage(sinks, self.lat_clock)
        self.flags_pending = 0
        self.id_verified = False
        self.stars_seen = 0          # stars the newest image updated (0: it saw none, or frames stopped)
        self.next_frame_t = -np.inf
        self.next_acquire_t = -np.inf
        self.pending = None            # the windows in flight: plan + time commanded
        self.link = HeadLink(params.reconnect_every_s, params.head_timeouts_lost)   # up / down, reconnects
        self.exposure_lag = 0.002      # s from commanding windows to the exposure start (EMA)
        self.lag_jitter = 0.001        # s, mean deviation of that lag
        self.floor = FloorInputs()     # what the run's attitude floor depends on (per update)
        # streaming head (gyrostar.hil.streamport): plans by stream frame, link budget,
        # exposure → output latency (mid-exposure to the first output holding its update)
        self.streaming = bool(getattr(head, "streaming", False))
        self.budget = link_budget
        self.plans = StreamPlans()
        self.updates_owed: list = []         # mid-exposure times of applied frame updates no output holds yet
        # the mode and the outputs' image flags, from each frame's outcome (streamed ones as StreamImages says)
        self.mode_keeper = ModeKeeper(params.mode_params(), self.streaming, params.stream_few_frames,
                                      params.stream_gap_frames)
        self.image_reason = R.REASON_ACQUIRING   # why the last image did not update (record.REASON_*)

    # ------------------------------------------------------------------ views
    @property
    def mode(self) -> int:
        return self.mode_keeper.mode

    @property
    def last_output(self):
        return self.outputs.last

    @property
    def out_buf(self):
        return self.outputs.buf

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
            self.image.identifier.identify(np.ascontiguousarray(uv[ok][:30]))   # > max_stars: labelling too
        return time.perf_counter() - t0

    def start(self) -> None:
        """Configure and start the devices (head exposure, gyro FIFO)."""
        self.head.start(self.p.exposure_s)
        self.gyro.start()

    def close(self) -> None:
        """Hand the last outputs to the keeping sinks; stop the measuring thread (the devices
        and the sinks belong to the caller)."""
        self.outputs.flush()
        self.image.close()

    # ------------------------------------------------------------------ the step
    @property
    def step_period_s(self) -> float:
        """Longest time between steps (s): one FIFO watermark of gyro samples."""
        return max(1, getattr(self.gyro, "watermark", 1)) / self.gyro.odr_hz

    def step_due(self, now: float) -> bool:
        """Whether a runner that ticks every gyro period should step at ``now`` (its clock, s).

        A step is due when a FIFO watermark of samples has come in since the last due step
        (:attr:`step_period_s`; it waits one tick for a streamed frame expected by then:
        :meth:`StepSchedule.watermark_due`); when an applied update has no output yet (its
        frame arrived after the newest sample of the last step) or a request-mode readout
        waits to be applied; when a request-mode frame is due; when the head port has
        something for the loop (a job finished; a streamed frame measured, once the first
        gyro sample after its arrival is due: :meth:`StepSchedule.arrival_due` — a port
        without arrival times steps at once); and before the first step. A True answer
        counts as that step's start. With a watermark of 1 every tick is a step.
        Reads no clock, logs nothing: a replay steps through the logged steps whatever the
        ticks between them were.
        """
        tick = 1.0 / self.gyro.odr_hz if self.gyro.odr_hz else 0.0025
        sched = self.schedule
        frame_period = getattr(self.head, "period_s", 0.0) if self.streaming else 0.0
        due = (sched.watermark_due(now, tick, self.step_period_s, frame_period) or bool(self.updates_owed)
               or self.image.busy
               or (not self.streaming and self.link.up and now >= self.next_frame_t)
               or self._result_due(now, tick))
        if due:
            sched.stepped(now)
        return due

    def _result_due(self, now: float, tick: float) -> bool:
        """The head port's waiting result is worth a step at ``now`` (s): its arrival time
        (``ready_since``) goes to :meth:`StepSchedule.arrival_due`; a port without arrival
        times steps whenever it is ``ready``."""
        since = getattr(self.head, "ready_since", None)
        if since is None:
            ready = getattr(self.head, "ready", None)
            return ready is not None and ready()
        return self.schedule.arrival_due(now, tick, since())

    def step(self) -> int:
        """One loop step; returns the number of outputs emitted.

        A step that starts more than 1.5 gyro periods after the previous one is an overrun
        (flagged on the next output and counted), judged on the loop's own clock.
        """
        t_step = self.clock.now()
        if self.t_step_prev is not None and self.gyro.odr_hz > 0 \
                and t_step - self.t_step_prev > 1.5 * self.step_period_s:
            self.overruns += 1
            self.flags_pending |= R.FLAG_OVERRUN
        self.t_step_prev = t_step
        if self.streaming:
            # the FIFO batch, with the updates of the frames the stream port has measured put
            # in before the first sample stamped after each frame's arrival (every output
            # holds the frames that had arrived by its sample's time, however many samples
            # a step takes); the next windows are planned after the outputs (off the
            # exposure → output path) and from the newest sample
            n = self._read_gyro()
            self._split = 0
            self._guarded(self._stream_take, t_step)
            self._frames_missing(t_step)
            self._outputs(self._split, n)
            self._note_ages(n)
            self._guarded(self._stream_command, t_step)
            return n
        done = self.image.result()       # the readout handed over last step: apply it before this
        if done is not None:             # step's samples, so their outputs are the first to carry it
            self._process_windows(*done, t_step)
        n_out = self._gyro_phase()
        try:
            self._image_phase()
        except DeviceError as exc:
            self._count_head_error(exc)
            self._head_failed(exc)
        return n_out

    def _guarded(self, phase, now: float) -> None:
        try:
            phase(now)
        except DeviceError as exc:
            self._count_head_error(exc)
            self._head_failed(exc)

    def _gyro_phase(self) -> int:
        n = self._read_gyro()
        n_out = self._outputs(0, n)
        self._note_ages(n)
        return n_out

    def _read_gyro(self) -> int:
        """Read the gyro's FIFO into :attr:`samples`; returns the sample count."""
        smp = self.samples
        smp.clear()
        try:
            # the watermark edge's time is read by the driver after the FIFO level
            self.gyro.read(smp, event_clock=self.irq)
        except DeviceError as exc:
            self.c.gyro_errors += 1
            self.flags_pending |= R.FLAG_GYRO_GAP
            log.debug("gyro read failed: %s", exc)
        self._t_read = self.lat_clock.now()
        if smp.n:
            self.schedule.sample_read(float(smp.t[smp.n - 1]))
        self.c.gyro_register_faults += smp.register_faults
        if smp.n and smp.gap_frames:
            self.c.samples_lost += int(smp.gap_frames)
            self.c.gyro_gaps += int(smp.gaps)
        if smp.n:
            self._out = self.outputs.batch(smp.n)     # this step's output rows, written by _predict
        return smp.n

    def _predict_through(self, t_arrival: float) -> None:
        """Streaming: predict and emit this step's samples stamped up to ``t_arrival`` (host
        s, a frame's arrival) before its update goes in (their outputs leave at once)."""
        smp = self.samples
        k = int(np.searchsorted(smp.t[:smp.n], t_arrival, side="right"))
        if k > self._split:
            self._outputs(self._split, k)       # out before the update: they need nothing from it
            self._split = k

    def _note_ages(self, n: int) -> None:
        """Keep how old this step's ``n`` samples were when it began (s, the loop's clock): the
        wait in the FIFO that a watermark above 1 adds to every output but the newest. Once
        per step, after its outputs (off the 400 Hz path's metered time)."""
        if n:
            self.meters.sample_ages(self.t_step_prev - self.samples.t[:n])

    def _outputs(self, lo: int, hi: int) -> int:
        """Predict samples ``lo:hi`` of this step and emit their outputs; the 400 Hz path's
        host time (:meth:`LoopMeters.add_path`) is metered here, once per
        call. Returns the outputs emitted."""
        if hi <= lo:
            return 0
        w0 = time.perf_counter()
        c0 = self.cpu_clock()
        self._predict(lo, hi)
        n = self._emit(lo, hi)
        cpu = self.cpu_clock() - c0
        self.meters.add_path(time.perf_counter() - w0, cpu)
        return n

    def _predict(self, lo: int, hi: int) -> None:
        """Predict samples ``lo:hi`` of :attr:`samples` into rows ``lo:hi`` of this step's
        output batch (one compiled call)."""
        smp = self.samples
        f = self.filter
        base = self.mode_keeper.flags | (self.reason() << R.REASON_SHIFT)
        if f.valid and self.mode != R.MODE_ACQUIRE:
            base |= R.FLAG_ATTITUDE_VALID
        if self.id_verified:
            base |= R.FLAG_ID_VERIFIED
        if not self.link.up:
            base |= R.FLAG_HEAD_LOST
        if f.valid:
            refs, ids, slots = self.tracks.kernel_stars()
        else:
            refs, ids, slots = _NO_REFS, _NO_IDS, _NO_SLOTS
        # the tracked stars' predicted centroids go straight into the tracks' table (uv)
        self.c.gyro_stuck += f.predict(smp, self.flags_pending, base, self.mode, refs, ids, self.cam, slots,
                                       self.tracks.uv, self._out[lo:hi], lo, hi)
        if self.mode == R.MODE_COAST:
            # the tracked stars are only predicted: n_stars is how many the newest image still saw
            n_stars = self._out["n_stars"][lo:hi]
            np.minimum(n_stars, self.stars_seen, out=n_stars)
        self.flags_pending = 0

    def reason(self) -> int:
        """The outputs' reason code now (:data:`gyrostar.loop.record.REASON_NAMES`): why they are
        not a tracked, image-updated attitude, 0 when they are."""
        if not self.link.up:
            return R.REASON_HEAD_LOST
        r = self.image_reason
        if self.mode == R.MODE_ACQUIRE:
            return R.REASON_BLINDED if r == R.REASON_BLINDED else R.REASON_ACQUIRING
        if self.mode == R.MODE_COAST and r in (R.REASON_NONE, R.REASON_ACQUIRING):
            return R.REASON_FEW_STARS
        return r

    def _emit(self, lo: int, hi: int) -> int:
        """Emit outputs ``lo:hi`` of this step (predicted by :meth:`_predict`; parts in order)."""
        n = hi - lo
        smp = self.samples
        self.c.gyro_samples += n
        if lo == 0:
            self.c.gyro_saturated += int(smp.saturated)
        self.outputs.emit(self._out[lo:hi], self._t_read, float(smp.t[hi - 1]))
        self.c.outputs += n
        if self.updates_owed:            # streamed frames whose update these outputs are the first to hold
            # on the loop's clock, the frames' own timeline (the latency clock is the same clock
            # in real time; on a simulated clock it measures host compute, which takes no time there)
            self.meters.exposure_to_output(self.clock.now() - np.asarray(self.updates_owed))
            self.updates_owed.clear()
        return n

    # ------------------------------------------------------------------ images
    def _image_phase(self) -> None:
        now = self.clock.now()
        res = self.head.poll()
        if res is not None and res.kind == "reconnect":
            if res.error is None:
                self.c.head_reconnects += 1
                log.info("head link back after %.2f s", self.link.back(now))
            else:
                log.debug("head still away: %s", res.error)
            res = None
        if not self.link.up:
            if self.link.reconnect_due(now, self.head.busy):
                self.pending = None
                self.head.submit_reconnect()
            return
        pend = None
        if res is not None:
            pend, self.pending = self.pending, None
        ok_windows = res is not None and res.error is None and res.kind == "windows"
        if ok_windows and pend is not None:
            # centroid the readout on the measuring thread (nogil kernel) while this step
            # plans the next exposure; the update is applied at the next step
            self.image.submit(pend, res)
        if ok_windows and self.mode != R.MODE_ACQUIRE and now >= self.next_frame_t - 0.5 / self.p.frame_hz:
            # next exposure first (windows from the prediction), then this image's update:
            # the head exposes while the loop centroids
            self.next_frame_t = max(self.next_frame_t + 1.0 / self.p.frame_hz, now)
            self._command_windows(now)
        if res is not None:
            if res.error is not None:
                self.c.frames_failed += 1
                self.mode_keeper.link_error()
                self._count_head_error(res.error)
                unanswered = self.link.job_failed(isinstance(res.error, HeadTimeoutError))
                if isinstance(res.error, LinkLostError) or unanswered:
                    self._head_failed(res.error)
                    return
                if res.kind == "windows":
                    self._after_image(now, 0)
            elif res.kind == "frame":
                self.link.answered()
                self.c.full_frames += 1
                self._acquire(res, now)
            else:
                self.link.answered()
        if self.head.busy:
            return
        if self.mode == R.MODE_ACQUIRE and not self.filter.valid:
            if now >= self.next_acquire_t:
                self.next_acquire_t = now + self.p.acquire_every_s
                self.head.submit_frame(self.image.lost_in_space)
            return
        if now >= self.next_frame_t:
            self.next_frame_t = max(self.next_frame_t + 1.0 / self.p.frame_hz, now)
            self._command_windows(now)

    def _stream_take(self, now: float) -> None:
        """Streaming head: take in the frames the port has measured (their updates)."""
        head = self.head
        while True:
            res = head.poll()
            if res is None:
                break
            if res.kind == "reconnect":
                if res.error is None:
                    self.c.head_reconnects += 1
                    log.info("head link back after %.2f s", self.link.back(now))
                    self.mode_keeper.restart_stream(now)   # the stream restarts: its first frame takes a while
                else:
                    log.debug("head still away: %s", res.error)
                continue
            if res.error is not None:
                self.c.frames_failed += 1
                self.mode_keeper.link_error()
                self._count_head_error(res.error)
                if res.kind == "frame" or isinstance(res.error, (LinkLostError, HeadTimeoutError)):
                    self._head_failed(res.error)
                    return
                continue
            if res.kind == "frame":
                self.link.answered()
                self.c.full_frames += 1
                self._acquire(res, now)
                continue
            self.schedule.frame_taken(getattr(res, "t_rx", -math.inf))
            pend = self.plans.get(res.set_frame)
            if pend is None or res.measured is None:
                self.c.frames_unmatched += 1
                continue
            self._predict_through(getattr(res, "t_rx", -math.inf))
            # read with an earlier frame's windows (its own set came late): the stars have moved
            # since; past half a pixel a window may clip its star and bias the centroid
            late = res.frame - res.set_frame if res.set_frame else 0
            speed = math.sqrt(float(self.filter.omega @ self.filter.omega)) * self.f_px
            if late > 0 and late * head.period_s * speed > 0.5:
                self.c.frames_stale_windows += 1
                self._after_image(now, 0)
                continue
            self._process_windows(pend, res, res.measured, now)
            self.updates_owed.append(res.t_mid)
            self.meters.frame_used(res.t_mid)

    def _stream_command(self, now: float) -> None:
        """Streaming head: reconnect or acquire when due, else command the windows of the
        frame two ahead of the newest one (while the next one integrates)."""
        head = self.head
        if not self.link.up:
            if self.link.reconnect_due(now, head.busy):
                self.plans.restart()
                head.submit_reconnect()
            return
        if head.busy:
            return
        if self.mode == R.MODE_ACQUIRE and not self.filter.valid:
            if now >= self.next_acquire_t:
                self.next_acquire_t = now + self.p.acquire_every_s
                self.plans.restart()
                head.submit_frame(self.image.lost_in_space)
            return
        frame, t_exp = head.next_target(now)
        if frame == 0:
            if self.plans.start_due(now):              # the set that starts the stream
                self.mode_keeper.restart_stream(now)      # no frame can come before this set's exposure
                self._command_windows(now, 0, t_exp)
        elif self.plans.target_new(frame):
            self._command_windows(now, frame, t_exp)

    def stream_summary(self) -> dict:
        """Frame rate, exposure → output latency, how old a sample is at the step that emits
        it (``sample_age_at_step_ms``: the FIFO wait of the watermark) and the link budget's
        actions (streaming)."""
        out = self.meters.summary(self.c.frames)
        if self.budget is not None:
            out["link_budget"] = self.budget.summary()
        return out

    def _count_head_error(self, exc: Exception) -> None:
        self.c.head_errors += 1
        log.debug("head error: %s", exc)

    def _head_failed(self, exc: Exception) -> None:
        """The link is down (lost, no answer after retries): COAST and reconnect."""
        self.pending = None
        if self.link.up:
            self.link.lost(self.clock.now())
            log.info("head link lost: %s", exc)
        self.mode_keeper.head_lost(self.link.down_since)

    # -- ACQUIRE ----------------------------------------------------------------
    def _acquire(self, res, now: float) -> None:
        spots, ident, blinded = res.measured   # ImagePipeline.lost_in_space ran on the head worker
        self.c.acquisitions += 1
        self.image_reason = R.REASON_BLINDED if blinded else R.REASON_ACQUIRING
        if blinded:
            self.c.frames_blinded += 1
        if ident is None:
            self.c.acquisition_failures += 1
            return
        if not ident.ok or ident.n_identified < 3:
            self.c.acquisition_failures += 1
            log.debug("acquisition failed: %s", ident.status)
            return
        used = np.flatnonzero(ident.index >= 0)
        body = self.camera.unproject(np.ascontiguousarray(spots[used, :2], np.float64))
        cov = fix_covariance(body, 2.0 * self.p.pyramid_sigma_px / self.f_px)
        self.filter.set_attitude(ident.q, res.t_mid, now, cov)
        self.tracks.clear()
        self.tracks.fill_from_catalog(self.filter.q, now)
        log.info("acquired: %d stars identified (p_false %.2g)", ident.n_identified, ident.p_false)
        # the mode turns to TRACK at the first image whose stars pass the filter's gate
        self.mode_keeper.acquired(now)
        self.next_frame_t = now

    # -- TRACK / COAST --------------------------------------------------------------
    def _command_windows(self, now: float, frame: int | None = None, t_exp: float | None = None) -> None:
        """Plan and command windows: for the next CAPTURE, or (streaming) for stream frame
        ``frame`` whose exposure starts at host time ``t_exp`` (on the head's own timer: no
        command-to-exposure jitter to cover)."""
        f = self.filter
        if f.valid:
            self.tracks.fill_from_catalog(f.q, now)
        sig = math.sqrt(max(f.P[0, 0], f.P[1, 1]))
        if self.streaming:
            lag, jitter = max(t_exp - now, 0.0), 0.0
        else:
            lag, jitter = self.exposure_lag, self.lag_jitter
        plan = self.tracks.plan(f.q, f.omega, f.b, sig, lag, jitter, self.gyro.odr_hz, budget=self.budget)
        if plan is None:
            self._after_image(now, 0)
            return
        plan["t_submit"] = now
        if self.budget is not None:
            sp = plan["spans"]
            div = self.budget.after_plan(now, plan["n_stars"], len(plan["wins"]), int(np.sum(sp[:, 3] - sp[:, 2])),
                                         len(sp))
            if div is not None and self.streaming:
                log.info("link %s: frame rate → %.1f Hz", self.budget.link.name, self.budget.frame_hz)
                self.head.set_period(1.0 / self.budget.frame_hz)
        if self.streaming:
            self.plans.add(frame, plan)
            self.head.submit_windows(plan["spans"], frame, lambda values, pl=plan: self.image.measure(pl, values))
            return
        self.head.submit_windows(plan["spans"])
        self.pending = plan

    def _process_windows(self, pend: dict, res, measured: tuple, now: float) -> None:
        self.c.frames += 1
        lag = res.t_start - pend["t_submit"]
        if 0.0 <= lag < 0.1:
            self.lag_jitter = 0.9 * self.lag_jitter + 0.1 * abs(lag - self.exposure_lag)
            self.exposure_lag = 0.9 * self.exposure_lag + 0.1 * lag
        state, b_mid, sig = measured
        tr = self.tracks
        f = self.filter
        w = f.omega
        # the first image after a lost-in-space fix confirms it: only stars that checked each
        # other (:func:`gyrostar.starid.verify.consistent`) may, and at least 4 — the fix's
        # wide prior lets a wrong centroid (a blend, a star at a window's edge) through every
        # gate, and with 3 stars the attitude's three angles absorb most of two such errors
        # (Monte Carlo seed 100120: two of three centroids 3.5 and 4.8 px off passed the
        # check); two stars alone would be fitted exactly, attitude and bias (through their
        # cross-covariance) alike. The same holds for a regain after a COAST that left the
        # attitude uncertain by more than CONFIRM_PRIOR_PX (seed 100194: after a 21.6 °/s
        # tumble, σ ≈ 35 px, two windows each caught the next star of a row of three)
        wide = self.mode == R.MODE_ACQUIRE or (
            self.mode == R.MODE_COAST
            and math.sqrt(max(f.P[0, 0], f.P[1, 1])) * self.f_px > CONFIRM_PRIOR_PX)
        min_used = max(CONFIRM_MIN_STARS, self.p.min_stars) if wide else self.p.min_stars
        # blinded (most windows read at a background near full scale: Sun or Earth glare, the
        # Moon): nothing is measured, no miss is counted, the attitude coasts on the gyro
        n_read = int(np.count_nonzero(state != MEAS_ABSENT))
        n_bright = int(np.count_nonzero(state == MEAS_BRIGHT))
        blinded = n_bright > 0 and 2 * n_bright >= n_read
        self.c.windows_bright += n_bright
        self.c.frames_blinded += blinded
        self.c.spots_rejected_hit += int(np.count_nonzero(state == MEAS_HIT))
        too_fast = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) > self.p.max_track_rate
        # one compiled call: windows whose slot was dropped or refilled meanwhile are skipped,
        # spots smeared past what the centroid model holds are not taken (coast on the gyro),
        # stars that disagree with the others are dropped, the rest update the filter at
        # mid-exposure and the gate's verdict goes to the tracks
        counts, info, wrong = apply_frame(
            pend["wins"], pend["nav"], state, b_mid, sig, tr.active, tr.nav, tr.misses, tr.rejects, tr.ref,
            (self.p.camera_sigma_px / self.f_px) ** 2 if self.p.camera_sigma_px > 0 else 0.0,
            too_fast or blinded,
            CONSISTENT_SIGMA, CONSISTENT_MIN_PX / self.f_px, *f.update_operands,
            float(res.t_mid), int(min_used), GATE, QD_MARGIN, SMOOTH_GAP_S, self.p.wrong_id_rejects)
        n_measured = int(counts[N_MEASURED])
        updated = int(counts[N_USED])
        if n_measured:
            self.c.inconsistent_stars += n_measured - int(counts[N_CONSISTENT])
            self.c.updates += updated
            if updated:
                self.flags_pending |= R.FLAG_UPDATE_APPLIED
                # its first output: the next sample's stamp
                t_next = (f.t_last or now) + f.prm[0] + self.p.gyro_delay_s
                self.floor.add(res.t_mid, t_next, 1.0 / info, updated)
            self.c.rejected_updates += n_measured - int(counts[N_ACCEPTED])
            if updated >= self.p.min_stars:
                for s in wrong:
                    tr.drop_wrong(int(s), now)
                    self.c.wrong_ids_dropped += 1
        self.id_verified = updated >= 3 and updated == n_measured
        self.image_reason = (R.REASON_NONE if updated >= self.p.min_stars else R.REASON_BLINDED if blinded
                             else R.REASON_RATE if too_fast else R.REASON_FEW_STARS)
        self._after_image(now, updated)

    def _frames_missing(self, now: float) -> None:
        """Streaming: frames that stopped coming count as starless images, one per period
        (:meth:`ModeKeeper.frame_missing`)."""
        period = 1.0 / (self.budget.frame_hz if self.budget is not None else self.p.frame_hz)
        self.stars_seen = 0
        self._heard(self.mode_keeper.frame_missing(now, period, self.link.up), now)

    def _after_image(self, now: float, updated: int) -> None:
        """An image at ``now`` updated ``updated`` stars (0: it failed): to the mode keeper."""
        self.stars_seen = updated
        self._heard(self.mode_keeper.image(now, updated), now)

    def _heard(self, heard: Heard | None, now: float) -> None:
        """Carry out what an image's outcome asked (:class:`ModeKeeper`), if it was heard."""
        if heard is None:
            return
        if heard.action & modes.Action.ACQUISITION_FAILED:
            self.c.acquisition_failures += 1
        if heard.action & modes.Action.LOSE_ATTITUDE:
            self.filter.valid = False
            self.tracks.clear()
        if heard.action & modes.Action.ACQUIRE_NOW:
            self.next_acquire_t = now
        if heard.check_tracks:
            self.tracks.drop_lost(tracking=heard.tracking)

    # ------------------------------------------------------------------ summary
    def counters(self) -> dict:
        c = self.c
        return {k: getattr(c, k) for k in c.__dataclass_fields__} | {"mode_changes": list(self.mode_keeper.changes)}

    def floor_summary(self) -> dict:
        """The steady-state floor for this run's gyro ARW, star noise, star count and timing,
        and beside it the camera model's pointing bias (1σ about camera x and y, arcsec: a
        constant error outside the floor and the covariance; :mod:`gyrostar.loop.floor`)."""
        res = self.floor.summary(self.p.gyro_arw, self.filter.kappa)
        res["pointing_bias_arcsec_1sigma"] = pointing_bias_arcsec(self.p.camera_bias_px, self.f_px)
        return res

    def host_us_per_gyro_sample(self) -> float | None:
        """Host CPU µs per gyro sample in the 400 Hz path after the FIFO read (filter kernel,
        output stage, sinks), on the loop's thread: what the path costs."""
        return self.meters.us_per_sample(self.c.gyro_samples)

    def host_us_per_gyro_sample_wall(self) -> float | None:
        """The same path in wall-clock µs per sample: its cost plus the turns other threads of
        the process (head worker, link reader, measuring thread) took inside it."""
        return self.meters.us_per_sample(self.c.gyro_samples, wall=True)



_NO_REFS = np.zeros((0, 3))
_NO_IDS = np.zeros(0, np.int32)
_NO_SLOTS = np.zeros(0, np.int64)


def warmup() -> dict:
    """Compile or load every numba function the loop (or its head worker) calls from Python,
    with the argument types it uses, timed (see warmup.py). Kernels called only from inside
    other kernels (centroiding, trajectories, windows, the image update's selection, check, MEKF
    update and verdicts inside the frame kernel) come with their callers."""
    from ..attitude import quat_conj, quat_mult, quat_normalize, quat_propagate, quat_to_dcm
    from ..camera import unproject_many
    from ..core.mekf import mekf_init
    from ..core.motion import substeps_for
    from ..gyro.convert import convert_frames
    from ..gyro.timebase import polygon_centroid
    from ..head.timesync import drift_fit
    from ..protocol.payloads import unpack10_kernel, windows_tail_decode
    from . import acquire, frame_kernel, image_kernels, kernels, update_kernel
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
    af = AttitudeFilter(1e-4, 1e-6, 1e-3, 0.0025)
    calls = [
        (kernels.predict_batch, (np.zeros(4), np.zeros((4, 3)), np.zeros(4, np.uint8), 1, af.q, af.b, af.P, af.ts,
                                 af.hist_t, af.hist_q, af.ih, af.prm, 0, 0, 0, ref, ref[:, 0].astype(np.int32), cam,
                                 np.arange(2), np.zeros((R.MAX_STARS, 2)), af.mid, af.smoothed, R.empty(4))),
        (kernels.project_refs, (cam, q, ref)),
        (quat_propagate, (q, w, 0.001)),
        (quat_mult, (q, q)),          # acquisition and delayed-measurement transfer
        (quat_conj, (q,)),
        (quat_normalize, (q,)),
        (quat_to_dcm, (q,)),
        (unpack10_kernel, (np.frombuffer(bytes(20), np.uint8), 16)),   # full-frame chunks (head worker)
        (windows_tail_decode, (np.frombuffer(bytes(8), np.uint8), 1, False)),   # every streamed frame
        (substeps_for, (rates, 0.0025, 6666.0, 0.25)),
        (drift_fit, (np.array([-0.5, 0.5]), np.zeros(2), np.zeros(2), 0.1, 0.02, 2000.0)),   # each TIME_SYNC
        (acquire.detect_spots, (img, 6.0, 40, 7)),
        (acquire.window_moments, (spans.astype(np.int64), vals, 1, 2.0, 1.0)),    # the head's spot list
        (convert_frames, (np.frombuffer(bytes(12), np.uint8), 2, 1e-3, np.eye(3), 0.0, 0.0025, 0.0, 0, 0,
                          np.zeros(8, np.int32), np.zeros(4), np.zeros(4, np.int64), np.zeros((4, 3)),
                          np.zeros(4, np.uint8), 0)),
        (image_kernels.plan_windows, (np.array([[20.0, 20.0]]), np.array([0], np.int64), rates, 0.0025, w, cam,
                                      MODEL, 1, 0, 6, 1024, 1024, 8192, 2048, 512)),
        (image_kernels.plan_tracked, (np.ones(2, np.bool_), np.array([0, 1], np.int64), np.array([5.0, 6.0]), ref, q,
                                      af.ts[1:4], w, 4, 0.0025, 0.0025, cam, MODEL, 6, 1024, 1024, 8192, 2048, 512)),
        (image_kernels.measure_windows, (spans, vals, np.array([0], np.int64), np.zeros((2, 2)),
                                         np.array([0], np.int64), np.array([2], np.int64), cam, 0.85, 4.0, 30.0,
                                         5.0, 10, 1e-3, np.full(1, 5.0), 767.0)),
        (update_kernel.q_at_history, (af.q, af.ts, af.hist_t, af.hist_q, af.ih, 0.0)),
        (unproject_many, (cam, np.zeros((2, 2)))),                            # lost-in-space spots (head worker)
        (polygon_centroid, (np.arange(4.0), np.arange(4.0) * 0.0025, 0.0024, 0.0026)),   # gyro timebase, no irq
        (image_kernels.lost_slots, (np.ones(2, np.bool_), np.zeros((2, 2)), np.zeros(2, np.int64), 1024, 1024, 3,
                                    True)),
        (frame_kernel.apply_frame, (np.array([0], np.int64), np.array([0], np.int64), np.ones(1, np.int8),   # missed
                                    np.zeros((1, 3)), np.ones(1), np.ones(1, np.bool_), np.zeros(1, np.int64),
                                    np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros((1, 3)), 0.0, False, 6.0,
                                    1e-4, *af.update_operands, 0.0, 1, GATE, QD_MARGIN,
                                    SMOOTH_GAP_S, 5)),
    ]
    return warm(calls)


class LoopError(GyrostarError):
    """The loop cannot run with the devices given (e.g. the gyro does not start)."""
