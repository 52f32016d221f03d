"""Rate sources for the gyro register models: ``source(k, t) -> (n, 3)`` rad/s, sensor axes.

A source must give the same value for the same global sample index ``k`` however the
samples are batched (the models produce them lazily), so noise is counter-based: a
splitmix64 hash of (seed, k, axis) → Box–Muller normal deviates.

* :class:`ProfileRates` — body rate ``ω(t) = ω0 + A·sin(2πft + φ)`` per axis plus bias and
  white noise of a given density (°/s/√Hz at the sampling rate), a datasheet-class
  MEMS error model; used where a test needs to know the value behind every index.
* :class:`TruthRates` — the simulator's gyro output over a fixed span (``simulate_gyro``).
* :class:`StreamRates` — the simulator's gyro output for a run of any length
  (:class:`~gyrostar.mocks.gyro_truth.GyroStream`): the simulated flatsat's source.
"""

from __future__ import annotations

import math

import numpy as np

_M64 = np.uint64(0xFFFFFFFFFFFFFFFF)


def _splitmix64(x: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        z = x + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def counter_normal(seed: int, k: np.ndarray, ncols: int = 3) -> np.ndarray:
    """Standard normal deviates, shape (len(k), ncols), a pure function of (seed, k, column)."""
    k = np.asarray(k, np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        base = k[:, None] * np.uint64(2 * ncols) + np.arange(2 * ncols, dtype=np.uint64)[None, :]
        h = _splitmix64(base ^ _splitmix64(np.uint64(seed) + np.zeros(1, np.uint64)))
    u = (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))
    u1 = np.maximum(u[:, :ncols], 1e-300)
    u2 = u[:, ncols:]
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2 * math.pi * u2)


class ProfileRates:
    """Sinusoidal body rates + constant bias + white noise (all per axis, °/s inputs)."""

    def __init__(self, mean_dps=(0.0, 0.0, 0.0), amp_dps=(5.0, -3.0, 2.0), freq_hz=(0.5, 0.3, 0.7),
                 bias_dps=(0.02, -0.01, 0.015), noise_dps_rt_hz: float = 0.014, odr_hz: float = 400.0,
                 seed: int = 1):
        d = math.pi / 180.0
        self.mean = np.asarray(mean_dps, float) * d
        self.amp = np.asarray(amp_dps, float) * d
        self.freq = np.asarray(freq_hz, float)
        self.bias = np.asarray(bias_dps, float) * d
        self.sigma = noise_dps_rt_hz * math.sqrt(odr_hz / 2.0) * d
        self.seed = seed

    def true_rates(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)[:, None]
        return self.mean + self.amp * np.sin(2 * math.pi * self.freq * t)

    def __call__(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.true_rates(t) + self.bias + self.sigma * counter_normal(self.seed, k)


class TruthRates:
    """Measured rates from the simulator's gyro truth + error model (:mod:`gyrostar.mocks.gyro_truth`).

    ``simulate_gyro`` is run once for ``duration_s`` (ideal output: the register model does
    the quantisation at its own range); model time ``t`` maps to output sample
    ``floor((t − t0)·odr)``. Times outside the simulated span are an error, not a wrap.
    """

    def __init__(self, profile, duration_s: float, params: str = "bmi088", t0: float = 0.0, seed: int = 0):
        from .gyro_truth import gyro_params, simulate_gyro

        p = gyro_params(params, range_dps=0.0) if isinstance(params, str) else params
        self.samples = simulate_gyro(profile, duration_s, p, seed=seed)
        self.t0 = t0
        self.odr_hz = p.odr_hz

    def __call__(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        i = np.floor((np.asarray(t, float) - self.t0) * self.odr_hz + 1e-9).astype(np.int64)
        if i.size and (i.min() < 0 or i.max() >= len(self.samples.t)):
            raise ValueError(f"gyro truth covers {len(self.samples.t) / self.odr_hz:.1f} s from t0={self.t0}; "
                             f"asked t in [{np.min(t):.3f}, {np.max(t):.3f}] s")
        return self.samples.omega_meas[i]


class StreamRates:
    """Measured rates from a :class:`~gyrostar.mocks.gyro_truth.GyroStream` at model (host) time.

    ``origin()`` is the host time (s) of the stream's time 0 (the scenario start; it may move
    when the run restarts). A sample the model takes at time ``t`` reports the stream's output
    at exactly ``t − origin`` (:meth:`GyroStream.meas_at`, fractional index
    ``(t − origin)·odr − 1``, clamped at 0), whatever the phase of the model's sample clock
    against the stream's grid: fresh samples for as long as the run lasts.
    """

    def __init__(self, stream, origin):
        self.stream = stream
        self.origin = origin

    def state(self) -> float:
        """What the rates depend on besides (k, t): the origin (a register model may compute
        samples ahead while it holds)."""
        return self.origin()

    def __call__(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        ts = np.maximum(np.asarray(t, float) - self.origin(), 0.0)
        return self.stream.meas_at(ts * self.stream.odr_hz - 1.0)
