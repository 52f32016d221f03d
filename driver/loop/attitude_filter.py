"""Attitude filter and history: the MEKF state the loop carries between gyro samples.

State (frames of :mod:`gyrostar.attitude`): ``q`` ICRS → body, gyro drift ``b`` (rad/s),
``P`` the 6×6 covariance of [δθ body rad, Δb rad/s]. Every FIFO batch goes through one
numba call (:func:`gyrostar.loop.kernels.predict_batch`) that predicts each sample and
writes each output record; the attitude of every sample is kept in a ring (``HIST``
samples, 20 s at 400 Hz) so an image, which arrives after its exposure, is applied at its
mid-exposure time: the measured directions are carried to now along the gyro-propagated
attitude (:meth:`update`).

Gyro delay: ``delay_s`` τ, the group delay of the gyro's low-pass filter: a sample stamped
t measured the rate at t − τ, so the filter, its history and the image updates run on
t − τ and each output's attitude is carried on to t (:func:`~gyrostar.loop.kernels.predict_batch`).

Process noise: ``arw`` is the gyro's angle random walk N (rad/√s, the IEEE coefficient:
σ²(angle) = N² t); a one-sided rate noise density n gives N = n/√2 (white noise
band-limited to the internal rate's Nyquist frequency).
"""

from __future__ import annotations

import math

import numpy as np

from ..attitude import quat_conj, quat_mult, quat_normalize
from . import record as R
from .kernels import predict_batch
from .update_kernel import q_at_history, update_at_mid

QD_MARGIN = 1.1          # the prior at t_mid, P − Q_Δ, is used when P exceeds Q_Δ by this factor on every axis
HIST = 8192              # gyro samples of history (20 s at 400 Hz) for delayed measurements: a lost-in-
                         # space full frame takes 14 s to come over a 921.6 kBd UART (1.3 MB packed)
GATE = 13.815510557964274  # χ² 2 dof, P = 0.001
SMOOTH_GAP_S = 0.1       # s: frames further apart than this are not smoothed together


class AttitudeFilter:
    def __init__(self, arw: float, sigma_bias_rw: float, bias_prior: float, period_s: float, delay_s: float = 0.0,
                 lowpass_hz: float = 0.0, rate_error: float = 0.0):
        self.q = np.array([0.0, 0.0, 0.0, 1.0])   # ACQUIRE: gyro-relative attitude from the start
        self.b = np.zeros(3)
        self.P = np.zeros((6, 6))
        self.P[:3, :3] = np.eye(3) * 1e-2
        self.P[3:, 3:] = np.eye(3) * bias_prior ** 2
        # [t of the last sample, ω̂ (3), t of the last fix: the newest applied update's mid-exposure]
        self.ts = np.array([np.nan, 0.0, 0.0, 0.0, np.nan])
        self.hist_t = np.full(HIST, -np.inf)
        self.hist_q = np.zeros((HIST, 4))
        # [ring head, output seq, writes out of time order]: while the last is 0 the ring's
        # times increase from its oldest entry to its head, and searches walk back from the head
        self.ih = np.array([HIST - 1, 0, 0], np.int64)
        # rate-proportional gyro error left after calibration (scale factor and misalignment,
        # 1σ per axis, rad per rad): a constant error, so the angle it adds since the last fix
        # grows linearly, variance (σ_s |ω̂| τ)² at τ after the fix (kernels.predict_batch)
        self.prm = np.array([period_s, arw, sigma_bias_rw, (1e-4) ** 2, delay_s, rate_error ** 2])
        # the gyro's 2nd-order low-pass takes the rate noise above f_c out of every finite
        # window: the angle walk over Δ is N²(Δ − κ), κ = 1/(2√2 π f_c) (Δ ≫ 1/f_c)
        self.kappa = 1.0 / (2.0 * math.sqrt(2.0) * math.pi * lowpass_hz) if lowpass_hz > 0 else 0.0
        self.valid = False                            # q is an identified attitude
        self.mid = np.full(R.MID_N, np.nan)           # [t_mid, q_mid, cov_mid]: the newest frame's product
        self.smoothed = np.full(R.MID_N, np.nan)      # the frame before it, smoothed with the newest
        # the arrays the compiled predict and update work on in place, in their argument order
        self.state_arrays = (self.q, self.b, self.P, self.ts, self.hist_t, self.hist_q, self.ih, self.prm)
        # ... and what the compiled delayed update takes after them (update_kernel.update_at_mid)
        self.update_operands = self.state_arrays + (self.kappa, self.mid, self.smoothed)

    @property
    def omega(self) -> np.ndarray:
        """Bias-corrected body rate at the last sample (rad/s)."""
        return self.ts[1:4]

    @property
    def t_last(self) -> float | None:
        """Time of the filter state (s): the last sample's stamp less the gyro delay."""
        t = self.ts[0]
        return None if t != t else float(t)

    def predict(self, smp, flags_first: int, flags_base: int, mode: int, refs, ids, cam, slots, uv_track, out,
                lo: int = 0, hi: int | None = None) -> int:
        """Predict samples ``lo:hi`` (default: all) of a FIFO batch and write their output
        records into ``out`` (its first ``hi − lo`` rows; one numba call); returns the count
        of stuck-axis samples. ``refs`` (k, 3), ``ids`` (k,): the tracked stars, in track
        ``slots`` (k,); rows ``slots`` of ``uv_track`` (S, 2) get their centroids (px) at the
        batch's last sample."""
        hi = smp.n if hi is None else hi
        t, rate, flags = (smp.t, smp.rate, smp.flags) if lo == 0 else (smp.t[lo:], smp.rate[lo:], smp.flags[lo:])
        return predict_batch(t, rate, flags, hi - lo, *self.state_arrays, flags_first, flags_base, mode, refs, ids, cam,
                             slots, uv_track, self.mid, self.smoothed, out)

    def q_at(self, t: float) -> np.ndarray:
        """Attitude estimate at host time ``t`` (s): the newest sample at or before it,
        propagated to ``t`` with the current rate (≤ one gyro period)."""
        return q_at_history(self.q, self.ts, self.hist_t, self.hist_q, self.ih, float(t))

    def update(self, t_mid: float, b_mid, refs, sigmas, accepted, min_used: int = 1) -> int:
        """Star directions measured at mid-exposure ``t_mid`` (body unit vectors (n, 3)),
        catalog vectors (n, 3), σ (n,) rad, applied now (χ² gated per star; ``accepted``
        (n,) uint8 written). Returns the count used; an image in which fewer than
        ``min_used`` stars pass their gates is not applied at all (returns 0): one star
        alone, at speed, can carry a smeared or confused centroid that its gate admits.

        A delayed measurement: the state now is the state at ``t_mid`` carried by the gyro
        (rotation R from the attitude history) plus the gyro's random walk since then,
        Q_Δ = N² Δ I (Δ = now − t_mid), which the measurement knows nothing of. So the
        update runs on P − Q_Δ (the prior at ``t_mid`` seen from now) with the directions
        rotated to now, and the walk since ``t_mid`` is added back after it: P⁺ = Φ P⁺_mid Φᵀ
        + N²(Δ − κ) I (exact for this linear structure; adding Q_Δ to the star noise instead
        would ignore that the same random walk is in the state). κ: the gyro low-pass's
        share of the walk over a finite window (``lowpass_hz``; 0: white rate noise).

        Also sets the mid-exposure product (:attr:`mid`): the updated attitude carried back
        to ``t_mid`` along R, with the attitude block of Φ P⁺_mid Φᵀ rotated back to the body
        axes at ``t_mid``.

        One compiled call (:func:`gyrostar.loop.update_kernel.update_at_mid`), the history
        corrected from ``t_mid`` on included (a frame whose mid-exposure falls before an update
        applied after it — frame n − 1's pixels arriving later than frame n's mid-exposure,
        as at speed on the streaming head — would otherwise apply the same correction twice).
        The smoothed product (:attr:`smoothed`) is the previous frame's mid-exposure attitude
        smoothed with this frame (one-lag Rauch–Tung–Striebel on the attitude error; frames
        more than ``SMOOTH_GAP_S`` apart are not combined)."""
        return int(update_at_mid(*self.update_operands, float(t_mid),
                                 np.ascontiguousarray(b_mid, np.float64), np.ascontiguousarray(refs, np.float64),
                                 np.ascontiguousarray(sigmas, np.float64),
                                 accepted, int(min_used), GATE, QD_MARGIN, SMOOTH_GAP_S))

    def set_attitude(self, q_ident, t_mid: float, now: float, cov_rad2: np.ndarray) -> None:
        """A lost-in-space attitude ``q_ident`` measured at ``t_mid`` with covariance ``cov_rad2``
        (3×3, rad², body axes; :func:`fix_covariance`): carried to now along the history; its
        covariance adds the drift's unknown action since then."""
        dq = quat_mult(self.q, quat_conj(self.q_at(t_mid)))          # rotation mid → now
        self.q[:] = quat_normalize(quat_mult(dq, np.asarray(q_ident, np.float64)))
        self.valid = True
        self.ts[4] = t_mid                            # a fix: the rate-proportional error restarts
        lag = max(now - t_mid, 0.0)
        pbb = self.P[3:, 3:].copy()
        self.P[:3, :3] = np.asarray(cov_rad2, np.float64).reshape(3, 3) + pbb * lag * lag
        self.P[:3, 3:] = -pbb * lag
        self.P[3:, :3] = -pbb * lag

    def bias_converged(self) -> bool:
        return max(self.P[3, 3], self.P[4, 4], self.P[5, 5]) < self.prm[3]


def fix_covariance(body: np.ndarray, sigma_rad: float) -> np.ndarray:
    """Covariance (3×3, rad², body axes) of an attitude solved from the unit star directions
    ``body`` (n, 3), each measured with ``sigma_rad`` per axis: the QUEST/Shuster measurement
    model P = σ² [Σ (I − b bᵀ)]⁻¹. It carries the field's geometry: about the boresight (roll)
    it grows as the stars crowd the centre, and a sparse field of close stars is uncertain
    about every axis. A degenerate set (fewer than two distinct directions) gets a 1 rad σ on
    its unobserved axis."""
    info = np.zeros((3, 3))
    for b in np.asarray(body, np.float64).reshape(-1, 3):
        info += np.eye(3) - np.outer(b, b)
    w, v = np.linalg.eigh(info)
    w = np.maximum(w, sigma_rad ** 2)          # an unobserved axis: σ = 1 rad
    return (v / w) @ v.T * sigma_rad ** 2
