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
"""

from __future__ import annotations

import dataclasses
import math

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


@njit(cache=True)
def _sensor_chain(omega_in, b0, gm_sigma, gm_phi, rrw_step, white_int, white_out, filt_b, filt_a, use_filter,
                  decim, seed):
    """Internal-rate chain: add biases and noise, filter, decimate. Returns (meas, bias) at ODR."""
    np.random.seed(seed)
    n_int = omega_in.shape[0]
    n_out = n_int // decim
    meas = np.empty((n_out, 3))
    bias = np.empty((n_out, 3))
    gm = np.zeros(3)
    rw = np.zeros(3)
    for j in range(3):
        gm[j] = gm_sigma * np.random.standard_normal()
    x1 = np.zeros(3)
    x2 = np.zeros(3)
    y1 = np.zeros(3)
    y2 = np.zeros(3)
    drive = math.sqrt(max(0.0, 1.0 - gm_phi * gm_phi)) * gm_sigma
    primed = False
    for i in range(n_int):
        for j in range(3):
            gm[j] = gm_phi * gm[j] + drive * np.random.standard_normal()
            rw[j] += rrw_step * np.random.standard_normal()
            x = omega_in[i, j] + b0[j] + gm[j] + rw[j] + white_int * np.random.standard_normal()
            if use_filter:
                if not primed:  # start the filter in steady state at the first value
                    x1[j], x2[j], y1[j], y2[j] = x, x, x, x
                y = filt_b[0] * x + filt_b[1] * x1[j] + filt_b[2] * x2[j] - filt_a[1] * y1[j] - filt_a[2] * y2[j]
                x2[j], x1[j] = x1[j], x
                y2[j], y1[j] = y1[j], y
            else:
                y = x
            if (i + 1) % decim == 0:
                k = (i + 1) // decim - 1
                meas[k, j] = y + white_out * np.random.standard_normal()
                bias[k, j] = b0[j] + gm[j] + rw[j]
        primed = True
    return meas, bias


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
    rng = np.random.default_rng(seed)
    decim = int(round(p.internal_hz / p.odr_hz))
    n_out = int(math.floor(duration_s * p.odr_hz + 1e-9))
    if n_out < 1:
        raise ConfigError("gyro duration shorter than one output sample")
    n_int = n_out * decim
    t_int = np.arange(1, n_int + 1) / p.internal_hz
    b0 = np.asarray(p.bias_dps, dtype=np.float64) * DEG + rng.standard_normal(3) * p.bias_sigma_dps * DEG
    scale = rng.standard_normal(3) * p.scale_factor_sigma_ppm * 1e-6
    mis = np.eye(3) + _skew(rng.standard_normal(3) * p.misalignment_sigma_mrad * 1e-3)
    sens = np.diag(1.0 + scale) @ mis
    omega_int = profile.rate(t_int) @ sens.T
    dt = 1.0 / p.internal_hz
    gm_phi = math.exp(-dt / p.bias_tau_s)
    white_int = p.noise_density_dps_rthz * DEG * math.sqrt(p.internal_hz / 2.0)
    if p.filter_hz > 0:
        fb, fa = butterworth2(p.filter_hz, p.internal_hz)
    else:
        fb, fa = np.zeros(3), np.zeros(3)
    meas, bias = _sensor_chain(np.ascontiguousarray(omega_int), b0, p.bias_instability_dph * DPH, gm_phi,
                               p.rrw_dps_per_rts * DEG * math.sqrt(dt), white_int, p.white_sigma_dph * DPH,
                               fb, fa, p.filter_hz > 0, decim, int(rng.integers(0, 2**31 - 1)))
    t = np.arange(1, n_out + 1) / p.odr_hz
    raw = None
    sensed = meas
    if p.range_dps > 0:
        raw = quantise(sensed, p.range_dps)
        meas = raw.astype(np.float64) * p.lsb_dps * DEG
    return GyroSamples(t, profile.rate(t), meas, sensed, raw, bias, scale, mis, p)
