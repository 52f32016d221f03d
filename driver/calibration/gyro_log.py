"""Gyro records for calibration: load from ``.npz``, or record from a live BMI088.

A record is ``t`` (N,) s (strictly increasing), ``rate`` (N, 3) rad/s in gyro axes, and
optionally ``temperature`` (N,) °C and ``run`` (N,) int (rate-table run id, −1 between
runs). ``fs`` is the median sample rate (Hz).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError


@dataclass
class GyroRecord:
    t: np.ndarray
    rate: np.ndarray
    temperature: np.ndarray | None = None
    run: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, float)
        self.rate = np.asarray(self.rate, float)
        n = len(self.t)
        if self.t.ndim != 1 or self.rate.shape != (n, 3) or n < 16:
            raise ConfigError(f"gyro record needs t (N,) and rate (N, 3) with N ≥ 16; got {self.t.shape}, "
                              f"{self.rate.shape}")
        if np.any(np.diff(self.t) <= 0):
            raise ConfigError("gyro timestamps must increase strictly")
        if not (np.all(np.isfinite(self.rate)) and np.all(np.isfinite(self.t))):
            raise ConfigError("gyro record holds NaN or infinite values")
        for name in ("temperature", "run"):
            v = getattr(self, name)
            if v is not None and np.shape(v) != (n,):
                raise ConfigError(f"gyro record: {name} must have one value per sample")

    @property
    def fs(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))

    def save(self, path: Path) -> Path:
        extra = {k: v for k, v in (("temperature", self.temperature), ("run", self.run)) if v is not None}
        np.savez_compressed(path, t=self.t, rate=self.rate, **extra)
        return Path(path)


def load(path: Path) -> GyroRecord:
    """Read a record from ``.npz`` (arrays ``t``, ``rate``, optional ``temperature``, ``run``)."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ConfigError(f"gyro log must be an .npz (t, rate[, temperature, run]); got {path}")
    from .report import read_npz

    z = read_npz(path, ("t", "rate"))
    if z["t"].ndim != 1 or z["rate"].shape != (len(z["t"]), 3) or len(z["t"]) < 3:
        raise ConfigError(f"INPUT {path}: 't' must be (N,) s and 'rate' (N, 3) rad/s with N ≥ 3, got "
                          f"{z['t'].shape} and {z['rate'].shape}")
    if not (np.all(np.isfinite(z["t"])) and np.all(np.diff(z["t"]) > 0)):
        raise ConfigError(f"INPUT {path}: 't' must be finite and increasing")
    return GyroRecord(z["t"], z["rate"], z.get("temperature"), z.get("run"))


LIVE_MAX_S = 12 * 3600.0     # s: a --live record at 400 Hz stays under ~1 GB


def add_live_args(parser) -> None:
    from ..cli.argtypes import float_in, int_in
    from ..gyro.bmi088 import RANGES_DPS

    parser.add_argument("--i2c-bus", type=int_in(0, 255), default=1, help="--live: Linux I2C bus number (default 1)")
    parser.add_argument("--address", type=_i2c_address, default=0x68,
                        help="--live: I2C address, 0x08 … 0x77 (default 0x68)")
    parser.add_argument("--range-dps", type=int, choices=sorted(RANGES_DPS), default=125,
                        help="--live: gyro range, deg/s (default 125)")
    parser.add_argument("--duration", type=float_in(10.0, LIVE_MAX_S, unit="s"), default=600.0,
                        help=f"--live: record length, s (10 … {LIVE_MAX_S:g}; default 600)")


def _i2c_address(text: str) -> int:
    """A 7-bit I2C device address (0x08 … 0x77, the range not reserved), decimal or 0x hex."""
    import argparse

    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects an address such as 0x68, got {text!r}") from None
    if not 0x08 <= value <= 0x77:
        raise argparse.ArgumentTypeError(f"must be 0x08 … 0x77, got {text!r}")
    return value


def record(gyro, clock, duration_s: float, range_dps: float = 125.0, step=None) -> GyroRecord:
    """Record ``duration_s`` from a :class:`gyrostar.gyro.GyroDevice` at 400 Hz, polling its
    FIFO every 50 ms on ``clock`` (the host clock, or a simulated one with the mocks)."""
    from ..gyro import GyroSamples

    gyro.probe()
    gyro.configure(400.0, range_dps, 50)
    out = GyroSamples(int(duration_s * 400.0 * 1.02) + 200)
    gyro.start()
    t0 = clock.now()
    last = t0
    while clock.now() - t0 < duration_s and out.room > 100:
        clock.sleep(0.05)
        gyro.read(out)
        if step is not None and clock.now() - last >= 1.0:
            step()
            last = clock.now()
    t, _, rate, _ = out.view()
    return GyroRecord(t.copy(), rate.copy())


def record_live(args, folder: Path) -> GyroRecord:
    """Record ``--duration`` s from a BMI088 gyro on ``--i2c-bus``/``--address``; the raw
    record is saved in the report folder (``gyro_live.npz``) before calibration."""
    from ..cli.output import progress
    from ..clock import MONOTONIC
    from ..gyro import Bmi088Gyro
    from ..transport.i2c import I2CBus, I2CRegisters

    gyro = Bmi088Gyro(I2CRegisters(I2CBus.open(args.i2c_bus), args.address), clock=MONOTONIC)
    with progress(args, "recording gyro", int(args.duration)) as step:
        rec = record(gyro, MONOTONIC, args.duration, args.range_dps, step)
    rec.save(folder / "gyro_live.npz")
    return rec
