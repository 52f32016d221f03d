"""Gyro truth and error model: true body rate → BMI088-like int16 samples at 400 Hz.

Model (body axes; ω in rad/s internally, parameters in the units their names carry)::

    ω_s(t) = (I + diag(s)) (I + [m]) ω(t) + b₀ + b_gm(t) + b_rw(t) + n(t)

* ``b₀`` constant bias (fixed per axis, or drawn per run with ``bias_sigma_dps``);
* ``b_gm`` bias instability, first-order Gauss–Markov (σ ``bias_instability_dph``,
  correlation time ``bias_tau_s``), the usual stand-in for the flicker floor;
* ``b_rw`` rate random walk (``rrw_dps_per_rts``, °/s/√s);
* ``n`` white rate noise: density ``noise_density_dps_rthz`` (°/s/√Hz, one-sided) gives
  σ = N·√(f_int/2) at the internal rate f_int, plus ``white_sigma_dph`` (°/h per output
  sample, paper 001's "random drift");
* ``s`` scale-factor errors, ``m`` small misalignment angles (drawn per run);
* the sensor samples at ``internal_hz``, low-pass filters at ``filter_hz`` (2nd-order
  Butterworth, bilinear) and decimates to ``odr_hz`` (BMI088 bandwidth 0x03: 400 Hz / 47 Hz);
* output ``raw = clip(round(ω_s[°/s] / LSB), −32768, 32767)`` with LSB = range/32768
  (quantisation and saturation at the configured range; ``range_dps = 0`` means ideal).

Parameter sets (:func:`gyro_params`): ``xing2012`` (paper 000: drift 0.02 °/s per axis,
BMI088-class noise and sampling), ``qian2015`` (paper 001: 1 °/h constant + 0.5 °/h random,
ideal sampling), ``bmi088`` (datasheet class). The hot loop is numba.

:func:`simulate_gyro` gives a fixed span at once; :class:`GyroStream` gives the same model for
a run of any length, generated in chunks on demand (a flatsat run, a soak).
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import OrderedDict

import numpy as np
from gyrostar.errors import ConfigError
from numba import njit

from .trajectory import RateProfile

DEG = math.pi / 180.0
DPH = DEG / 3600.0


@dataclasses.dataclass(frozen=True)
class GyroErrorParams:
    """Gyro error parameters (see the module docstring for the model)."""

    name: str
    bias_dps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bias_sigma_dps: float = 0.0
    bias_instability_dph: float = 0.0
    bias_tau_s: float = 100.0
    rrw_dps_per_rts: float = 0.0
    noise_density_dps_rthz: float = 0.0
    white_sigma_dph: float = 0.0
    scale_factor_sigma_ppm: float = 0.0
    misalignment_sigma_mrad: float = 0.0
    odr_hz: float = 400.0
    internal_hz: float = 1600.0
    filter_hz: float = 47.0       # 0: no filter
    range_dps: float = 2000.0     # 0: no quantisation / saturation

    def validate(self) -> None:
        if self.odr_hz <= 0 or self.internal_hz < self.odr_hz:
            raise ConfigError("gyro internal_hz must be >= odr_hz > 0")
        ratio = self.internal_hz / self.odr_hz
        if abs(ratio - round(ratio)) > 1e-9:
            raise ConfigError("gyro internal_hz must be an integer multiple of odr_hz")
        if self.filter_hz < 0 or self.filter_hz >= self.internal_hz / 2:
            raise ConfigError("gyro filter_hz must be in [0, internal_hz/2)")
        if self.range_dps < 0 or self.bias_tau_s <= 0:
            raise ConfigError("gyro range_dps must be >= 0 and bias_tau_s > 0")

    @property
    def lsb_dps(self) -> float:
        """°/s per LSB at the configured range (0 if ideal)."""
        return self.range_dps / 32768.0


GYRO_PARAMS = {
    # paper 000: "gyro drift 0.02 deg/s"; eta (white noise) unspecified -> BMI088 class.
    # Range +-125 deg/s: the paper's rates stay below 10 deg/s, and it is the finest LSB.
    "xing2012": GyroErrorParams("xing2012", bias_dps=(0.02, 0.02, 0.02), noise_density_dps_rthz=0.014,
                                range_dps=125.0),
    # paper 001: constant drift 1 deg/h, random drift 0.5 deg/h (white, per sample); an ideal
    # navigation-class gyro: no band limit, no quantisation.
    "qian2015": GyroErrorParams("qian2015", bias_dps=(1 / 3600,) * 3, white_sigma_dph=0.5, filter_hz=0.0,
                                internal_hz=400.0, range_dps=0.0),
    # BMI088 datasheet class: zero-rate offset +-1 deg/s (max ~ 3 sigma), noise density
    # 0.014 deg/s/rtHz, bias instability ~2 deg/h, sensitivity tolerance +-1 % (~3 sigma),
    # cross-axis sensitivity +-1 % (~3 mrad sigma); RRW not given (assumed 3e-5 deg/s/rts).
    # BMI088 scale-factor and cross-axis errors as above, its zero-rate offset already removed by a
    # static calibration (gyrostar calibrate gyro-static) down to paper 000's drift of 0.02 deg/s:
    # what camera/gyro calibration on a flatsat starts from (scenario miscal)
    "bmi088_offset_removed": GyroErrorParams("bmi088_offset_removed", bias_dps=(0.02, -0.02, 0.02),
                                             bias_instability_dph=2.0, bias_tau_s=100.0, rrw_dps_per_rts=3e-5,
                                             noise_density_dps_rthz=0.014, scale_factor_sigma_ppm=3300.0,
                                             misalignment_sigma_mrad=3.3, range_dps=2000.0),
    "bmi088": GyroErrorParams("bmi088", bias_sigma_dps=0.33, bias_instability_dph=2.0, bias_tau_s=100.0,
                              rrw_dps_per_rts=3e-5, noise_density_dps_rthz=0.014, scale_factor_sigma_ppm=3300.0,
                              misalignment_sigma_mrad=3.3, range_dps=2000.0),
}


def gyro_params(name: str, **overrides) -> GyroErrorParams:
    """A named parameter set, optionally with fields replaced (e.g. ``range_dps=125``)."""
    try:
        p = GYRO_PARAMS[name]
    except KeyError:
        raise ConfigError(f"unknown gyro parameter set '{name}' (known: {', '.join(GYRO_PARAMS)})") from None
    try:
        p = dataclasses.replace(p, **overrides)
    except TypeError as exc:
        raise ConfigError(f"bad gyro parameter override: {exc}") from exc
    p.validate()
    return p


@dataclasses.dataclass(frozen=True)
class GyroSamples:
    """Output samples at ``odr_hz`` (the sample at index i is taken at ``t[i]``)."""

    t: np.ndarray            # (n,) s
    omega_true: np.ndarray   # (n, 3) rad/s body rate at t (unfiltered truth)
    omega_meas: np.ndarray   # (n, 3) rad/s what the gyro reports (raw·LSB, or ideal)
    omega_sensed: np.ndarray  # (n, 3) rad/s filtered sensor output before quantisation
    raw: np.ndarray | None   # (n, 3) int16 register values at params.range_dps, None if ideal
    bias: np.ndarray         # (n, 3) rad/s total additive bias b₀ + b_gm + b_rw at t
    scale: np.ndarray        # (3,) scale-factor errors (fraction)
    misalignment: np.ndarray  # (3, 3) I + [m]
    params: GyroErrorParams

    def raw_at_range(self, range_dps: float) -> np.ndarray:
        """int16 register values (n, 3) had the range register been set to ``range_dps``.

        For a register model that serves whatever range the driver configured
        (BMI088: 2000, 1000, 500, 250, 125 °/s; LSB = range / 32768).
        """
        if not range_dps > 0:
            raise ConfigError(f"range_dps must be > 0, got {range_dps!r}")
        return quantise(self.omega_sensed, range_dps)


def quantise(omega: np.ndarray, range_dps: float) -> np.ndarray:
    """Rates (rad/s) → int16 LSBs at ``range_dps`` full scale: round, then saturate."""
    lsb = range_dps / 32768.0
    return np.clip(np.round(omega / DEG / lsb), -32768, 32767).astype(np.int16)


def butterworth2(fc: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """2nd-order low-pass Butterworth biquad (bilinear, prewarped): (b (3,), a (3,), a[0] = 1)."""
    k = math.tan(math.pi * fc / fs)
    q = 1.0 / math.sqrt(2.0)
    norm = 1.0 / (1.0 + k / q + k * k)
    b = np.array([k * k * norm, 2 * k * k * norm, k * k * norm])
    a = np.array([1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm])
    return b, a


@njit(cache=True, nogil=True)
def _sensor_chain(omega_in, b0, gm_sigma, gm_phi, rrw_step, white_int, white_out, filt_b, filt_a, use_filter,
                  decim, seed, state):
    """Internal-rate chain: add biases and noise, filter, decimate. Returns (meas, bias, signal)
    at ODR; ``signal`` is the filtered body rate alone (the chain without biases and noise: it is
    linear, so ``meas − signal`` is the filtered error), for content between output samples.

    ``state`` (11, 3) carries the chain from one call to the next and is updated in place:
    rows 0–1 the Gauss–Markov and random-walk biases, rows 2–5 the filter's x[n−1], x[n−2],
    y[n−1], y[n−2], row 6 column 0 nonzero once started, rows 7–10 the signal filter's. All
    zeros is a fresh start (the Gauss–Markov bias is drawn from its stationary distribution,
    the filter starts in steady state at the first value). The noise comes from ``seed``.
    """
    np.random.seed(seed)
    n_int = omega_in.shape[0]
    n_out = n_int // decim
    meas = np.empty((n_out, 3))
    bias = np.empty((n_out, 3))
    sig = np.empty((n_out, 3))
    sx1 = state[7]
    sx2 = state[8]
    sy1 = state[9]
    sy2 = state[10]
    gm = state[0]
    rw = state[1]
    x1 = state[2]
    x2 = state[3]
    y1 = state[4]
    y2 = state[5]
    primed = state[6, 0] != 0.0
    if not primed:
        for j in range(3):
            gm[j] = gm_sigma * np.random.standard_normal()
    drive = math.sqrt(max(0.0, 1.0 - gm_phi * gm_phi)) * gm_sigma
    for i in range(n_int):
        for j in range(3):
            gm[j] = gm_phi * gm[j] + drive * np.random.standard_normal()
            rw[j] += rrw_step * np.random.standard_normal()
            x = omega_in[i, j] + b0[j] + gm[j] + rw[j] + white_int * np.random.standard_normal()
            xs = omega_in[i, j]
            if use_filter:
                if not primed:  # start the filter in steady state at the first value
                    x1[j], x2[j], y1[j], y2[j] = x, x, x, x
                    sx1[j], sx2[j], sy1[j], sy2[j] = xs, xs, xs, xs
                y = filt_b[0] * x + filt_b[1] * x1[j] + filt_b[2] * x2[j] - filt_a[1] * y1[j] - filt_a[2] * y2[j]
                x2[j], x1[j] = x1[j], x
                y2[j], y1[j] = y1[j], y
                ys = (filt_b[0] * xs + filt_b[1] * sx1[j] + filt_b[2] * sx2[j] - filt_a[1] * sy1[j]
                      - filt_a[2] * sy2[j])
                sx2[j], sx1[j] = sx1[j], xs
                sy2[j], sy1[j] = sy1[j], ys
            else:
                y = x
                ys = xs
            if (i + 1) % decim == 0:
                k = (i + 1) // decim - 1
                meas[k, j] = y + white_out * np.random.standard_normal()
                bias[k, j] = b0[j] + gm[j] + rw[j]
                sig[k, j] = ys
        primed = True
    if primed:
        state[6, 0] = 1.0
    return meas, bias, sig


class _Chain:
    """The per-run draws (constant bias, scale factors, misalignment) and the chain's
    coefficients for one parameter set and seed, as :func:`simulate_gyro` draws them."""

    def __init__(self, params: GyroErrorParams, seed: int):
        p = params
        p.validate()
        rng = np.random.default_rng(seed)
        self.p = p
        self.decim = int(round(p.internal_hz / p.odr_hz))
        self.b0 = np.asarray(p.bias_dps, dtype=np.float64) * DEG + rng.standard_normal(3) * p.bias_sigma_dps * DEG
        self.scale = rng.standard_normal(3) * p.scale_factor_sigma_ppm * 1e-6
        self.mis = np.eye(3) + _skew(rng.standard_normal(3) * p.misalignment_sigma_mrad * 1e-3)
        self.sens = np.diag(1.0 + self.scale) @ self.mis
        dt = 1.0 / p.internal_hz
        self.gm_phi = math.exp(-dt / p.bias_tau_s)
        self.white_int = p.noise_density_dps_rthz * DEG * math.sqrt(p.internal_hz / 2.0)
        self.rrw_step = p.rrw_dps_per_rts * DEG * math.sqrt(dt)
        if p.filter_hz > 0:
            self.fb, self.fa = butterworth2(p.filter_hz, p.internal_hz)
        else:
            self.fb, self.fa = np.zeros(3), np.zeros(3)
        self.seed = int(rng.integers(0, 2**31 - 1))

    def run(self, profile: RateProfile, i0_out: int, n_out: int, seed: int, state: np.ndarray):
        """(meas, bias) for output samples ``i0_out … i0_out + n_out − 1`` (sample i at
        ``(i + 1) / odr_hz``), continuing ``state``."""
        p = self.p
        t_int = np.arange(i0_out * self.decim + 1, (i0_out + n_out) * self.decim + 1) / p.internal_hz
        omega_int = profile.rate(t_int) @ self.sens.T
        return _sensor_chain(np.ascontiguousarray(omega_int), self.b0, p.bias_instability_dph * DPH, self.gm_phi,
                             self.rrw_step, self.white_int, p.white_sigma_dph * DPH, self.fb, self.fa,
                             p.filter_hz > 0, self.decim, seed, state)


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def simulate_gyro(profile: RateProfile, duration_s: float, params: GyroErrorParams | str = "bmi088",
                  seed: int = 0) -> GyroSamples:
    """Gyro output over ``duration_s`` for body-rate profile ``profile`` (t = 0 at its start).

    Output sample i is at ``t = (i + 1) / odr_hz`` (the sensor's first sample after start).
    """
    p = gyro_params(params) if isinstance(params, str) else params
    p.validate()
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigError(f"gyro duration_s must be > 0, got {duration_s!r}")
    n_out = int(math.floor(duration_s * p.odr_hz + 1e-9))
    if n_out < 1:
        raise ConfigError("gyro duration shorter than one output sample")
    chain = _Chain(p, seed)
    meas, bias, _ = chain.run(profile, 0, n_out, chain.seed, np.zeros((11, 3)))
    t = np.arange(1, n_out + 1) / p.odr_hz
    raw = None
    sensed = meas
    if p.range_dps > 0:
        raw = quantise(sensed, p.range_dps)
        meas = raw.astype(np.float64) * p.lsb_dps * DEG
    return GyroSamples(t, profile.rate(t), meas, sensed, raw, bias, chain.scale, chain.mis, p)


class GyroStream:
    """Gyro output for a run of any length, generated on demand in chunks.

    The error model and sensor chain of :func:`simulate_gyro` (same per-run draws; its first
    ``chunk`` samples are exactly ``simulate_gyro``'s), with the chain's state carried from
    one chunk to the next and chunk ``c ≥ 1`` drawing its noise from a seed derived from
    ``(seed, c)``: the output is a pure function of the seed, whatever the order and size of
    the requests. Output sample ``i`` (0, 1, …) is taken at ``t = (i + 1) / odr_hz`` s from the
    profile's start. Memory stays bounded: the chain state at every chunk start is kept
    (168 bytes per chunk) and the last ``cache_chunks`` chunks; an older chunk asked for again
    is regenerated from its start state. The next chunk is generated ahead in a worker thread.
    Thread-safe.
    """

    def __init__(self, profile: RateProfile, params: GyroErrorParams | str = "bmi088", seed: int = 0,
                 chunk: int = 4096, cache_chunks: int = 8):
        p = gyro_params(params) if isinstance(params, str) else params
        if chunk < 1 or cache_chunks < 1:
            raise ConfigError(f"gyro stream chunk and cache must be >= 1, got {chunk}, {cache_chunks}")
        self.params = p
        self.profile = profile
        self.seed = int(seed)
        self.chunk = int(chunk)
        self.cache_chunks = int(cache_chunks)
        self._chain = _Chain(p, seed)
        self.scale, self.misalignment = self._chain.scale, self._chain.mis
        self._starts = [np.zeros((11, 3))]   # chain state before chunk c
        self._cache: OrderedDict = OrderedDict()   # c -> (meas, bias, signal)
        self.generated = 0                  # chunks generated (regenerations included)
        self._ahead = None                  # (chunk, future, its state) being generated ahead
        self._worker = None
        self._lock = threading.Lock()

    @property
    def odr_hz(self) -> float:
        return self.params.odr_hz

    def _chunk_seed(self, c: int) -> int:
        if c == 0:
            return self._chain.seed
        return int(np.random.SeedSequence([self.seed, c]).generate_state(1)[0] & 0x7FFFFFFF)

    def _chunk(self, c: int):
        """(meas, bias) of chunk ``c`` (lock held). The chunk after the newest one is generated
        ahead in a worker thread (the chain releases the GIL), so a caller moving forward in
        time (the register model, 10 s per chunk at 400 Hz) does not wait for it."""
        hit = self._cache.get(c)
        if hit is not None:
            self._cache.move_to_end(c)
            return hit
        first = min(c, len(self._starts) - 1)   # generate on from the nearest known start state
        for cc in range(first, c + 1):
            if self._ahead is not None and self._ahead[0] == cc:
                _, future, state = self._ahead
                self._ahead = None
                got = future.result()
            else:
                state = self._starts[cc].copy()
                got = self._chain.run(self.profile, cc * self.chunk, self.chunk, self._chunk_seed(cc), state)
            self.generated += 1
            if cc + 1 == len(self._starts):
                self._starts.append(state)
            self._remember(cc, got)
        self._generate_ahead(c + 1)
        return got

    def _remember(self, c: int, got) -> None:
        self._cache[c] = got
        self._cache.move_to_end(c)
        while len(self._cache) > self.cache_chunks:
            self._cache.popitem(last=False)

    def _generate_ahead(self, c: int) -> None:
        """Start generating chunk ``c`` in the worker if it is the next new one (lock held)."""
        if self._ahead is not None or c != len(self._starts) - 1 or c in self._cache:
            return
        if self._worker is None:
            from concurrent.futures import ThreadPoolExecutor

            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gyro-stream")
        state = self._starts[c].copy()
        future = self._worker.submit(self._chain.run, self.profile, c * self.chunk, self.chunk,
                                     self._chunk_seed(c), state)
        self._ahead = (c, future, state)

    def _rows(self, which: int, i) -> np.ndarray:
        i = np.atleast_1d(np.asarray(i, np.int64))
        out = np.empty((len(i), 3))
        if not len(i):
            return out
        if i.min() < 0:
            raise ValueError(f"gyro sample index must be >= 0, got {int(i.min())}")
        c = i // self.chunk
        c0 = int(c[0])
        if c0 == c.min() == c.max():   # the usual request: a few samples of one chunk
            with self._lock:
                return self._chunk(c0)[which][i - c0 * self.chunk]
        order = np.argsort(c, kind="stable")
        cuts = np.flatnonzero(np.diff(c[order])) + 1
        with self._lock:
            for seg in np.split(order, cuts):
                cc = int(c[seg[0]])
                out[seg] = self._chunk(cc)[which][i[seg] - cc * self.chunk]
        return out

    def meas(self, i) -> np.ndarray:
        """What the gyro reports (rad/s, body axes, filtered; quantised at ``params.range_dps``
        unless 0) at output sample index/indices ``i``."""
        out = self._rows(0, i)
        p = self.params
        if p.range_dps > 0:
            out = quantise(out, p.range_dps).astype(np.float64) * p.lsb_dps * DEG
        return out

    def meas_at(self, x) -> np.ndarray:
        """What the gyro reports for a sample taken between output samples: ``x`` the fractional
        output index (sample i at ``(i + 1)/odr_hz``, so time ``t`` is ``x = t·odr_hz − 1``). The
        filtered body rate is interpolated to ``x`` (the filter leaves it smooth: at the scenarios'
        rate ramps the error is below 1e-3 °/s), the filtered errors are the nearest sample's (their
        statistics untouched), then quantised as :meth:`meas`. At integer ``x`` it is :meth:`meas`."""
        x = np.maximum(np.atleast_1d(np.asarray(x, np.float64)), 0.0)
        i0 = np.floor(x).astype(np.int64)
        f = (x - i0)[:, None]
        near = np.where(f[:, 0] >= 0.5, i0 + 1, i0)
        c0 = int(i0[0]) // self.chunk if len(i0) else 0
        if len(i0) and c0 == int(i0.min()) // self.chunk == int(i0.max() + 1) // self.chunk:
            with self._lock:                      # the usual request: one chunk, one look-up
                meas, _, sig = self._chunk(c0)
            j0, jn = i0 - c0 * self.chunk, near - c0 * self.chunk
            s0, s1 = sig[j0], sig[j0 + 1]
            out = meas[jn] - sig[jn] + s0 + f * (s1 - s0)
        else:
            s0, s1 = self._rows(2, i0), self._rows(2, i0 + 1)
            out = self._rows(0, near) - self._rows(2, near) + s0 + f * (s1 - s0)
        p = self.params
        if p.range_dps > 0:
            out = quantise(out, p.range_dps).astype(np.float64) * p.lsb_dps * DEG
        return out

    def bias(self, i) -> np.ndarray:
        """Total additive bias b₀ + b_gm + b_rw (rad/s) at output sample index/indices ``i``."""
        return self._rows(1, i)
