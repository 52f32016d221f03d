"""Adapters from the calibration commands to the simulator's gyro (``gyrostar.mocks.gyro_truth``).

Nothing here models a gyro: rates go through :func:`gyrostar.mocks.gyro_truth.simulate_gyro`
with a named parameter set (plus ``KEY=VALUE`` overrides); this module only turns its
output into the truth each calibration compares with (SI units):

* ``arw``: the IEEE 952 coefficient N (σ² = N²/τ) of the set's one-sided noise density n,
  ``N = n/√2`` (white noise of σ = n·√(f/2) per sample has Allan variance n²/(2τ));
* ``bias_instability``: the Gauss–Markov σ the set draws its bias wander from, with its
  correlation time ``bias_tau_s``;
* ``sensitivity``: ``diag(1 + s)(I + [m])`` of the run; ``bias``: mean additive bias;
* ``delay_s``: the group delay at low frequency of the sensor's 2nd-order Butterworth,
  i.e. how late the reported rate is against the body rate (part of any time offset).
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import ConfigError

DEG = math.pi / 180.0


def params(name: str, overrides: list[str] | None = None):
    """Parameter set ``name`` with ``KEY=VALUE`` overrides (floats) applied."""
    from ...mocks.gyro_truth import gyro_params

    kw = {}
    for item in overrides or []:
        key, sep, val = item.partition("=")
        if not sep:
            raise ConfigError(f"gyro parameter override must be KEY=VALUE, got {item!r}")
        try:
            kw[key.strip()] = float(val)
        except ValueError:
            raise ConfigError(f"gyro parameter override {item!r}: value must be a number") from None
    return gyro_params(name, **kw)


MAX_RATE_HZ = 6400.0                       # odr_hz / internal_hz overrides: a MEMS gyro's fastest clock
MAX_INTERNAL_SAMPLES = int(12 * 3600 * 1600)  # 12 h at the BMI088's 1600 Hz: ≈ 3.5 GB peak while simulating


def override(text: str) -> str:
    """argparse type of ``--set``: ``KEY=VALUE`` with KEY a numeric gyro parameter and VALUE a
    finite number (≥ 0 except ``bias_dps``; rates ≤ :data:`MAX_RATE_HZ`), checked at parse time."""
    import argparse
    import dataclasses

    from ...mocks.gyro_truth import GyroErrorParams

    key, sep, val = text.partition("=")
    key = key.strip()
    known = [f.name for f in dataclasses.fields(GyroErrorParams) if f.name != "name"]
    if not sep or key not in known:
        raise argparse.ArgumentTypeError(f"expects KEY=VALUE with KEY one of {', '.join(known)}, got {text!r}")
    try:
        value = float(val)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{key}: value must be a number, got {val.strip()!r}") from None
    if not math.isfinite(value) or (key != "bias_dps" and value < 0):
        raise argparse.ArgumentTypeError(f"{key}: value must be a finite number"
                                         f"{'' if key == 'bias_dps' else ' >= 0'}, got {val.strip()!r}")
    if key in ("odr_hz", "internal_hz") and not 0 < value <= MAX_RATE_HZ:
        raise argparse.ArgumentTypeError(f"{key} must be in (0, {MAX_RATE_HZ:g}] Hz, got {val.strip()!r}")
    return text


def check_length(p, seconds: float, flags: str) -> None:
    """Refuse (before anything is simulated) a record of ``seconds`` whose internal-rate samples
    exceed :data:`MAX_INTERNAL_SAMPLES`; ``flags`` names the arguments that set its length."""
    n = seconds * p.internal_hz
    if n > MAX_INTERNAL_SAMPLES:
        raise ConfigError(f"{flags}: {seconds / 3600:.3g} h of gyro record at internal_hz {p.internal_hz:g} Hz is "
                          f"{n:.3g} samples, more than the {MAX_INTERNAL_SAMPLES:.3g} the simulation holds in memory")


def filter_delay_s(p) -> float:
    """Low-frequency group delay (s) of the set's Butterworth at its internal rate (0 if none)."""
    if p.filter_hz <= 0:
        return 0.0
    from ...mocks.gyro_truth import butterworth2

    b, a = butterworth2(p.filter_hz, p.internal_hz)
    k = np.arange(3)
    return float(((k * b).sum() / b.sum() - (k * a).sum() / a.sum()) / p.internal_hz)


class _Rotated:
    """Body-rate profile seen in another frame: ``rate(t) @ m.T`` (``m`` maps body → sensor)."""

    def __init__(self, base, m: np.ndarray):
        self.base = base
        self.m = np.asarray(m, float)
        self.duration_s = getattr(base, "duration_s", math.inf)

    def rate(self, t):
        return self.base.rate(t) @ self.m.T


def measure_profile(profile, duration_s: float, p, seed: int, body_to_sensor: np.ndarray | None = None):
    """Gyro output for a body-rate profile (optionally mounted with ``body_to_sensor``):
    ``(t, rate_meas (N, 3) rad/s, truth dict)``; sample i is stamped with the true time
    of the sensor's sample, ``t = (i + 1)/odr``."""
    from ...mocks.gyro_truth import simulate_gyro

    prof = profile if body_to_sensor is None else _Rotated(profile, body_to_sensor)
    g = simulate_gyro(prof, duration_s, p, seed=seed)
    sens = np.diag(1.0 + g.scale) @ g.misalignment
    truth = {"sensitivity": sens, "bias": g.bias.mean(axis=0), "arw": np.full(3, p.noise_density_dps_rthz * DEG
                                                                              / math.sqrt(2.0)),
             "bias_instability": np.full(3, p.bias_instability_dph * DEG / 3600.0), "bias_tau_s": p.bias_tau_s,
             "rrw": np.full(3, p.rrw_dps_per_rts * DEG), "delay_s": filter_delay_s(p)}
    return g.t, g.omega_meas, truth


def static_record(p, hours: float, seed: int):
    """A static (zero-rate) record as a :class:`~gyrostar.calibration.gyro_log.GyroRecord` and its truth."""
    from ...calibration.gyro_log import GyroRecord
    from ...mocks.trajectory import Constant

    t, w, truth = measure_profile(Constant((0.0, 0.0, 0.0)), hours * 3600.0, p, seed)
    return GyroRecord(t, w), truth


def sound_static_hours(p) -> float:
    """Record length (h) for which the Gauss–Markov σ is estimated to ≈ 5 % (1-σ), so a 10 %
    check is a 2-σ one: the bias wander gives about T/(2 T_c) independent looks, so
    σ²'s relative error is ≈ √(4 T_c/T); white noise on top inflates it by (1 + r), r the
    ARW-to-Markov variance ratio at the Markov peak (τ ≈ 1.89 T_c)."""
    tc = p.bias_tau_s
    gm = (0.617 * p.bias_instability_dph * DEG / 3600.0) ** 2
    if gm <= 0:
        return 1.0
    arw2 = (p.noise_density_dps_rthz * DEG) ** 2 / 2.0 / (1.89 * tc)
    r = arw2 / gm
    return float(400.0 * tc * (1.0 + r) ** 2 / 3600.0)


def gyro_param_sets() -> tuple[str, ...]:
    """Names of the simulator's gyro error-model parameter sets (``--gyro-params`` choices)."""
    from ...mocks.gyro_truth import GYRO_PARAMS

    return tuple(GYRO_PARAMS)
