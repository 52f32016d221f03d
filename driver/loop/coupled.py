"""The coupled 400/100 Hz loop: gyro FIFO → predict; windows → head → centroid → update.

One :meth:`CoupledLoop.step` (called every gyro period by a scheduler, or as fast as
possible on a simulated clock):

1. read the gyro FIFO (:class:`gyrostar.gyro.GyroDevice`); for every new sample predict
   every tracked spot's EKF (paper 000, :mod:`gyrostar.core.spot_ekf`) and the attitude,
   and emit one output record (:mod:`gyrostar.loop.record`) to the sinks — before any image
   work, so the sample-to-output latency is the predict cost only;
2. image cycle at ``frame_hz``: when the exposure commanded one cycle earlier has ended,
   fetch its windows' pixels, centroid each window (:mod:`gyrostar.core.centroid`), bring
   the centroid from exposure mid-time to now along the spot's predicted path, update the
   spot EKF (χ² gated), verify the identifications by their QUEST residuals; then predict
   each spot's trajectory over the next exposure from the latest bias-corrected rate
   (:mod:`gyrostar.core.motion`), build its window (union of k×k squares,
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

from ..errors import DeviceError, GyrostarError
from . import record as R

log = logging.getLogger(__name__)

HIST = 256               # gyro samples of history (0.64 s at 400 Hz) for delayed measurements
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
    gyro_noise_density: float = 2.44e-4  # gyro rate noise density, rad/s/√Hz (BMI088: 0.014 °/s/√Hz);
    #                                      per-sample σ in the spot EKF is density/√Δt (angle random walk)
    sigma_bias_rw: float = 1e-6       # drift random walk, rad/s/√s
    bias_prior: float = 0.02          # initial drift uncertainty, rad/s (≈ 1.1 °/s: BMI088 offset ±1 °/s)
    min_signal: float = 30.0          # window flux (DN above background) to accept a centroid
    thresh_sigma: float = 4.0         # CoG threshold above the window background, in noise σ
    residual_px: float = 1.5          # identification check: residual after QUEST (px)
    max_misses: int = 50              # frames without a centroid before a spot is dropped (TRACK)
    pixel_budget: int = 8192          # head limits (GET_INFO)
    max_window_pixels: int = 2048
    max_spans: int = 512
    chunks_per_step: int = 64         # full-frame chunks fetched per loop step (ACQUIRE)
    pyramid_sigma_px: float = 0.5


@dataclass
class Counters:
    gyro_samples: int = 0
    samples_lost: int = 0
    gyro_gaps: int = 0
    gyro_errors: int = 0
    frames: int = 0
    frames_failed: int = 0
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
                 lat_clock=None):
        from ..gyro import GyroSamples

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
        self.X = np.zeros((S, 5))
        self.P = np.zeros((S, 5, 5))
        self.active = np.zeros(S, np.bool_)
        self.valid = np.zeros(S, np.bool_)
        self.ref = np.zeros((S, 3))
        self.star_nav = -np.ones(S, np.int64)      # navigation-star index of each slot
        self.star_id = -np.ones(S, np.int32)       # catalog id
        self.misses = np.zeros(S, np.int64)
        self.rejects = np.zeros(S, np.int64)
        self.hist_t = np.full(HIST, -np.inf)
        self.hist_xy = np.zeros((S, HIST, 2))
        self.hist_q = np.zeros((HIST, 4))          # attitude estimate (or gyro-relative attitude)
        self.h = -1
        self.q = np.array([0.0, 0.0, 0.0, 1.0])   # ACQUIRE: gyro-relative attitude from the start
        self.q_valid = False
        self.bias = np.zeros(3)
        self.bias_cov = np.eye(3) * params.bias_prior ** 2
        self.att_cov = np.eye(3) * 1e-2
        self.omega = np.zeros(3)
        self.mode = R.MODE_ACQUIRE
        self.t_last: float | None = None
        self.seq = 0
        self.flags_pending = 0
        self.last_image_flags = R.FLAG_FEW_STARS
        self.id_verified = False
        self.coast_since: float | None = None
        self.next_frame_t = -np.inf
        self.next_acquire_t = -np.inf
        self.pending = None            # dict describing the exposure in flight
        self.head_down_since: float | None = None
        self.next_reconnect_t = -np.inf
        self.out_buf = R.empty(256)
        self._blank = R.empty(1)[0]
        self.last_output = None

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
            self.identifier.identify(np.ascontiguousarray(uv[ok][:12]))
        return time.perf_counter() - t0

    def start(self) -> None:
        """Configure and start the devices (gyro FIFO, head exposure)."""
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
        n_out = self._gyro_phase()
        try:
            self._image_phase()
        except DeviceError as exc:
            self._count_head_error(exc)
            self._head_failed(exc)
        return n_out

    def _gyro_phase(self) -> int:
        from .kernels import attitude_from_stars, coast_attitude, fuse_bias, predict_stars

        smp = self.samples
        smp.clear()
        try:
            self.gyro.read(smp)
        except DeviceError as exc:
            self.c.gyro_errors += 1
            self.flags_pending |= R.FLAG_GYRO_GAP
            log.debug("gyro read failed: %s", exc)
        t_read = self.lat_clock.now()
        n = smp.n
        if n == 0:
            return 0
        if smp.gap_frames:
            self.c.samples_lost += int(smp.gap_frames)
            self.c.gyro_gaps += int(smp.gaps)
        out = self.out_buf[:n]
        out[:] = self._blank
        period = 1.0 / self.gyro.odr_hz
        for i in range(n):
            t = smp.t[i]
            w = smp.rate[i]
            dt = period if self.t_last is None else t - self.t_last
            if not 0.0 < dt < 0.1:
                dt = period
            self.t_last = t
            self.h = (self.h + 1) % HIST
            self.hist_t[self.h] = t
            predict_stars(self.X, self.P, self.active, w, dt, self.f_px, self.p.gyro_noise_density / math.sqrt(dt),
                          self.p.sigma_bias_rw,
                          MODEL, self.hist_xy, self.h)
            use = self.active & self.valid
            q_prev = self.q
            if np.count_nonzero(use) >= 2:
                b, bcov = fuse_bias(self.X, self.P, use, self.bias, self.p.bias_prior ** 2)
                self.bias, self.bias_cov = b, bcov
                q, cov, _ = attitude_from_stars(self.X, self.P, use, self.ref, self.cam)
                if np.all(np.isfinite(q)):
                    if np.dot(q, q_prev) < 0:
                        q = -q
                    self.q, self.att_cov = q, cov
                else:
                    self.q = coast_attitude(q_prev, w, self.bias, dt)
            else:
                self.q = coast_attitude(q_prev, w, self.bias, dt)
                self.att_cov = self.att_cov + np.eye(3) * self.p.gyro_noise_density ** 2 * dt
            self.hist_q[self.h] = self.q
            self.omega = w - self.bias
            flags = self.flags_pending | self.last_image_flags
            self.flags_pending = 0
            if smp.flags[i] & 0x08:
                flags |= R.FLAG_GYRO_GAP
            if smp.flags[i] & 0x07:
                flags |= R.FLAG_GYRO_SATURATED
            if self.q_valid:
                flags |= R.FLAG_ATTITUDE_VALID
            if self.id_verified:
                flags |= R.FLAG_ID_VERIFIED
            if np.max(np.diag(self.bias_cov)) < (1e-4) ** 2:
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
            cov = o["cov"]
            cov[:3, :3] = self.att_cov
            cov[3:, 3:] = self.bias_cov
            k = 0
            for s in np.flatnonzero(self.active):
                o["star_id"][k] = self.star_id[s]
                o["centroid_px"][k, 0] = self.X[s, 0] + self.cam[1]
                o["centroid_px"][k, 1] = self.X[s, 1] + self.cam[2]
                k += 1
            o["n_stars"] = k
        self.c.gyro_samples += n
        t_out = self.lat_clock.now()
        out["latency_us"] = (t_out - t_read) * 1e6
        for sink in self.sinks:
            sink.put(out, int(self.t_last * 1e9))
        self.last_output = out[n - 1].copy()
        self.c.outputs += n
        return n

    # ------------------------------------------------------------------ images
    def _image_phase(self) -> None:
        now = self.clock.now()
        if self.head_down_since is not None:
            if now < self.next_reconnect_t:
                return
            self.next_reconnect_t = now + 0.25
            try:
                self.head.reconnect()
            except DeviceError as exc:
                log.debug("head still away: %s", exc)
                return
            self.c.head_reconnects += 1
            log.info("head link back after %.2f s", now - self.head_down_since)
            self.head_down_since = None
        res = self.head.poll()
        if res is not None:
            if res.error is not None:
                self.c.frames_failed += 1
                self.last_image_flags |= R.FLAG_LINK_ERROR
                self._count_head_error(res.error)
                if _link_down(res.error):
                    self._head_failed(res.error)
                    return
                if res.kind == "windows":
                    self._after_image(now, updated=0)
            elif res.kind == "frame":
                self.c.full_frames += 1
                self._acquire(res, now)
            else:
                self._process_windows(self.pending, res, now)
            self.pending = None
        if self.head.busy:
            return
        if self.mode == R.MODE_ACQUIRE:
            if now >= self.next_acquire_t:
                self.next_acquire_t = now + self.p.acquire_every_s
                self.head.submit_frame()
            return
        if now >= self.next_frame_t:
            self.next_frame_t = max(self.next_frame_t + 1.0 / self.p.frame_hz, now)
            self._command_windows(now)

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
    def _acquire(self, res, now: float) -> None:
        from .acquire import detect_spots

        spots = detect_spots(res.image.astype(np.float64), 6.0, 40, 7)
        self.c.acquisitions += 1
        if len(spots) < 3:
            self.c.acquisition_failures += 1
            return
        ident = self.identifier.identify(np.ascontiguousarray(spots[:, :2]))
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
        self.att_cov = np.eye(3) * (self.p.pyramid_sigma_px / self.f_px) ** 2
        self._clear_stars()
        self._add_stars_from_catalog(now, sigma_px=3.0)
        log.info("acquired: %d stars identified (p_false %.2g)", ident.n_identified, ident.p_false)
        self._set_mode(R.MODE_TRACK, now)
        self.next_frame_t = now

    # -- TRACK / COAST --------------------------------------------------------------
    def _command_windows(self, now: float) -> None:
        from ..core.motion import predict_trajectory, substeps_for
        from ..core.windows import concat_windows, span_pixel_count, trajectory_window

        self._add_stars_from_catalog(now, sigma_px=None)
        m = max(1, int(round(self.p.exposure_s * self.gyro.odr_hz)))
        rates = np.repeat((self.omega + self.bias)[None, :], m, axis=0)
        dt = self.p.exposure_s / m
        sub = substeps_for(rates - self.bias, dt, self.f_px, 0.25)
        parts = []
        slots = []
        budget = self.p.pixel_budget
        n_spans = 0
        order = np.flatnonzero(self.active)
        order = order[np.argsort(self._slot_mag(order))]
        for s in order:
            sig = math.sqrt(max(self.P[s, 0, 0], self.P[s, 1, 1]))
            k = self.p.window_k + 2 * int(math.ceil(3.0 * sig))
            k = min(k, 40)
            traj = predict_trajectory(self.X[s, 0], self.X[s, 1], rates, dt, self.bias, self.f_px, MODEL, sub)
            traj[:, 0] += self.cam[1]
            traj[:, 1] += self.cam[2]
            spans = trajectory_window(traj, k, self.camera.height_px, self.camera.width_px, int(s))
            npx = span_pixel_count(spans)
            if len(spans) == 0 or npx > self.p.max_window_pixels or npx > budget \
                    or n_spans + len(spans) > self.p.max_spans:
                continue
            budget -= npx
            n_spans += len(spans)
            parts.append(spans)
            slots.append(s)
        if not parts:
            self._after_image(now, updated=0)
            return
        spans = concat_windows(parts)
        self.head.submit_windows(spans)
        self.pending = {"spans": spans, "slots": slots}

    def _process_windows(self, pend: dict, res, now: float) -> None:
        from ..core.centroid import centroid_variance, cog, window_background, window_spans_of
        from .kernels import star_residuals

        self.c.frames += 1
        spans = pend["spans"]
        vals = np.asarray(res.values, dtype=np.float64)
        t_mid = res.t_mid
        hm = self._hist_index(t_mid)
        updated = 0
        for s in pend["slots"]:
            if not self.active[s]:
                continue
            a, b, v0 = window_spans_of(spans, s)
            if b <= a:
                continue
            sp = spans[a:b]
            npx = int(np.sum(sp[:, 3] - sp[:, 2]))
            wv = vals[v0: v0 + npx]
            bg, noise = window_background(wv, 3.0)
            thr = bg + self.p.thresh_sigma * noise
            u, v, flux, npix = cog(sp, wv, bg, thr)
            if npix < 2 or flux < self.p.min_signal:
                self.misses[s] += 1
                continue
            var_u, var_v = centroid_variance(sp, wv, bg, thr, u, v, noise, self.p.e_per_dn)
            var_u = max(var_u, 0.03 ** 2)
            var_v = max(var_v, 0.03 ** 2)
            # measured at t_mid: carry it to now along the spot's predicted path
            if hm >= 0:
                zx = u - self.cam[1] + (self.X[s, 0] - self._hist_xy_at(s, t_mid, hm)[0])
                zy = v - self.cam[2] + (self.X[s, 1] - self._hist_xy_at(s, t_mid, hm)[1])
            else:
                zx, zy = u - self.cam[1], v - self.cam[2]
            if not self.valid[s]:
                d2 = (zx - self.X[s, 0]) ** 2 + (zy - self.X[s, 1]) ** 2
                lim = 9.0 * (self.P[s, 0, 0] + self.P[s, 1, 1]) + 4.0
                if d2 > lim:
                    self.rejects[s] += 1
                    self.c.rejected_updates += 1
                    continue
                from ..core.spot_ekf import spot_ekf_reset

                spot_ekf_reset(self.X[s], self.P[s], zx, zy, var_u, var_v)
                self.valid[s] = True
                ok = True
            else:
                from ..core.spot_ekf import spot_ekf_update

                ok, _nis = spot_ekf_update(self.X[s], self.P[s], zx, zy, var_u, var_v, GATE)
            if ok:
                updated += 1
                self.c.updates += 1
                self.misses[s] = 0
                self.rejects[s] = 0
            else:
                self.rejects[s] += 1
                self.c.rejected_updates += 1
                if self.rejects[s] >= 5:
                    self.valid[s] = False   # re-acquire this spot from its next window
        # verify identifications: residuals after QUEST over the valid spots
        use = self.active & self.valid
        self.id_verified = False
        if np.count_nonzero(use) >= 3:
            from .kernels import attitude_from_stars

            q, _, _ = attitude_from_stars(self.X, self.P, use, self.ref, self.cam)
            if np.all(np.isfinite(q)):
                res = star_residuals(self.X, use, self.ref, self.cam, q) * self.f_px
                bad = np.flatnonzero(use & (np.nan_to_num(res, nan=0.0) > self.p.residual_px))
                if len(bad) and len(bad) < np.count_nonzero(use) / 2:
                    worst = bad[np.argmax(res[bad])]
                    self._drop(worst)
                    self.c.wrong_ids_dropped += 1
                else:
                    self.id_verified = len(bad) == 0
        self._after_image(now, updated)

    def _after_image(self, now: float, updated: int) -> None:
        few = updated < self.p.min_stars
        self.last_image_flags = R.FLAG_IMAGE_UPDATE if updated else 0
        if few:
            self.last_image_flags |= R.FLAG_FEW_STARS
            if self.mode == R.MODE_TRACK:
                self._set_mode(R.MODE_COAST, now)
            elif self.mode == R.MODE_COAST and self.coast_since is not None \
                    and now - self.coast_since > self.p.coast_timeout_s:
                self._set_mode(R.MODE_ACQUIRE, now)
                self._clear_stars()
                self.q_valid = False
                self.next_acquire_t = now
        else:
            if self.mode != R.MODE_TRACK:
                self._set_mode(R.MODE_TRACK, now)
        # drop spots that left the sensor or were not seen for long
        for s in np.flatnonzero(self.active):
            u = self.X[s, 0] + self.cam[1]
            v = self.X[s, 1] + self.cam[2]
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
        self.valid[:] = False
        self.star_nav[:] = -1
        self.star_id[:] = -1

    def _drop(self, s: int) -> None:
        self.active[s] = False
        self.valid[s] = False
        self.star_nav[s] = -1
        self.star_id[s] = -1

    def _slot_mag(self, slots) -> np.ndarray:
        return np.array([self.index.vmag[self.star_nav[s]] for s in slots]) if len(slots) else np.zeros(0)

    def _add_stars_from_catalog(self, now: float, sigma_px: float | None) -> None:
        """Fill free slots with catalog stars the current attitude puts on the sensor."""
        from ..attitude import quat_to_dcm
        from .kernels import project_refs

        free = np.flatnonzero(~self.active[: self.p.max_stars])
        if not len(free) or not self.q_valid:
            return
        a = quat_to_dcm(self.q)
        boresight = a[2]
        radius = math.atan(0.5 * math.hypot(self.camera.width_px, self.camera.height_px) / self.f_px)
        cand = self.index.cone(boresight, radius, self.p.mag_limit)
        if len(cand) == 0:
            return
        cand = cand[np.argsort(self.index.vmag[cand])]
        uv, ok = project_refs(self.cam, self.q, np.ascontiguousarray(self.index.vectors[cand]))
        margin = self.p.window_k + 4
        inside = ok & (uv[:, 0] > margin) & (uv[:, 1] > margin) \
            & (uv[:, 0] < self.camera.width_px - 1 - margin) & (uv[:, 1] < self.camera.height_px - 1 - margin)
        tracked = set(self.star_nav[self.active].tolist())
        if sigma_px is None:
            sigma_px = math.sqrt(max(np.max(np.diag(self.att_cov)), 0.0)) * self.f_px + 0.5
        sigma_px = min(sigma_px, 10.0)
        from ..core.spot_ekf import spot_ekf_init

        fi = 0
        for j in np.flatnonzero(inside):
            if fi >= len(free):
                break
            nav = int(cand[j])
            if nav in tracked:
                continue
            # keep spots apart so that windows hold one star each
            s = free[fi]
            X, P = spot_ekf_init(uv[j, 0] - self.cam[1], uv[j, 1] - self.cam[2], self.bias, sigma_px,
                                 math.sqrt(max(np.max(np.diag(self.bias_cov)), 1e-14)))
            self.X[s] = X
            self.P[s] = P
            self.P[s, 2:, 2:] = self.bias_cov
            self.ref[s] = self.index.vectors[nav]
            self.star_nav[s] = nav
            self.star_id[s] = int(self.index.ids[nav])
            self.active[s] = True
            self.valid[s] = False
            self.misses[s] = 0
            self.rejects[s] = 0
            self.hist_xy[s, :, 0] = X[0]
            self.hist_xy[s, :, 1] = X[1]
            fi += 1

    # -- history --------------------------------------------------------------------
    def _hist_index(self, t: float) -> int:
        """Ring index of the newest sample at or before ``t`` (-1 if out of the history)."""
        if self.h < 0:
            return -1
        best = -1
        best_t = -np.inf
        for i in range(HIST):
            ti = self.hist_t[i]
            if best_t < ti <= t:
                best, best_t = i, ti
        return best

    def _hist_xy_at(self, s: int, t: float, i: int) -> np.ndarray:
        j = (i + 1) % HIST
        ti, tj = self.hist_t[i], self.hist_t[j]
        if tj > ti and tj >= t:
            f = (t - ti) / (tj - ti)
            return (1 - f) * self.hist_xy[s, i] + f * self.hist_xy[s, j]
        return self.hist_xy[s, i]

    def _hist_q_at(self, t: float) -> np.ndarray:
        i = self._hist_index(t)
        return self.hist_q[i] if i >= 0 else self.q

    # ------------------------------------------------------------------ summary
    def counters(self) -> dict:
        c = self.c
        return {k: getattr(c, k) for k in c.__dataclass_fields__ if k != "mode_changes"} | {
            "mode_changes": list(c.mode_changes)}


def _link_down(exc: Exception) -> bool:
    """A failure that means the link is gone (closed port, no answer after every retry)."""
    name = type(exc).__name__
    text = str(exc)
    return name == "HeadTimeoutError" or "closed" in text or "is down" in text


def warmup() -> dict:
    """Compile or load every numba function of the loop's hot path, timed (see warmup.py)."""
    from ..core.centroid import centroid_variance, cog, window_background, window_spans_of
    from ..core.motion import predict_trajectory, substeps_for
    from ..core.spot_ekf import spot_ekf_init, spot_ekf_reset, spot_ekf_update
    from ..core.windows import trajectory_window
    from . import acquire, kernels
    from .warmup import warm

    S = R.MAX_STARS
    X = np.zeros((S, 5))
    X[:, 0] = np.arange(S) * 10.0
    P = np.tile(np.eye(5), (S, 1, 1))
    act = np.ones(S, np.bool_)
    ref = np.tile(np.array([0.0, 0.0, 1.0]), (S, 1))
    ref[:, 0] = np.arange(S) * 1e-3
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    cam = np.array([6666.0, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    hist = np.zeros((S, HIST, 2))
    w = np.zeros(3)
    spans = np.array([[0, 10, 10, 16], [0, 11, 10, 16]], np.int32)
    vals = np.arange(12, dtype=np.float64)
    rates = np.zeros((4, 3))
    q = np.array([0.0, 0.0, 0.0, 1.0])
    img = np.zeros((64, 64))
    x0, p0 = spot_ekf_init(0.0, 0.0, w, 1.0, 1e-3)
    calls = [
        (kernels.predict_stars, (X, P, act, w, 0.0025, 6666.0, 1e-4, 1e-6, MODEL, hist, 0)),
        (kernels.fuse_bias, (X, P, act, w, 1e-4)),
        (kernels.attitude_from_stars, (X, P, act, ref, cam)),
        (kernels.star_residuals, (X, act, ref, cam, q)),
        (kernels.coast_attitude, (q, w, w, 0.0025)),
        (kernels.project_refs, (cam, q, ref)),
        (substeps_for, (rates, 0.0025, 6666.0, 0.25)),
        (predict_trajectory, (0.0, 0.0, rates, 0.0025, w, 6666.0, MODEL, 1)),
        (trajectory_window, (np.zeros((3, 2)) + 20.0, 6, 1024, 1024, 0)),
        (window_background, (vals, 3.0)),
        (cog, (spans, vals, 0.0, 1.0)),
        (centroid_variance, (spans, vals, 0.0, 1.0, 12.0, 10.5, 1.0, 1.0)),
        (window_spans_of, (spans, 0)),
        (spot_ekf_update, (x0, p0, 0.1, 0.1, 0.01, 0.01, GATE)),
        (spot_ekf_reset, (x0, p0, 0.1, 0.1, 0.01, 0.01)),
        (acquire.detect_spots, (img, 6.0, 40, 7)),
    ]
    return warm(calls)


class LoopError(GyrostarError):
    """The loop cannot run with the devices given (e.g. the gyro does not start)."""
