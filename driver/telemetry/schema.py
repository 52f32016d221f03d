"""The columns of every tabular export of the loop outputs (CSV, HDF5, XTCE parameters):
one list, each column with its unit and meaning, computed from the 400 Hz output records.

Frames: ``q`` maps ICRS → body (= camera frame), scalar last; rates and bias in body axes.
``sigma_theta_*`` and ``sigma_bias_*`` are the square roots of the covariance diagonal.
Times: host monotonic, TAI (since 1958-01-01 TAI) and UTC (:mod:`gyrostar.telemetry.timescale`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..loop.record import sigma


@dataclass(frozen=True)
class Column:
    name: str
    dtype: str          # numpy dtype of the column
    unit: str           # SI or named unit; "1" for dimensionless, "" for none (enumerations, counters)
    description: str


def _vec(prefix, axes, dtype, unit, what):
    return [Column(f"{prefix}_{a}", dtype, unit, f"{what}, {a} component") for a in axes]


COLUMNS: tuple[Column, ...] = tuple([
    Column("t_monotonic_s", "f8", "s", "host CLOCK_MONOTONIC time of the gyro sample the output belongs to"),
    Column("tai_s", "f8", "s", "TAI seconds since 1958-01-01T00:00:00 TAI of the same instant"),
    Column("seq", "u4", "", "output counter (a gap means lost outputs)"),
    Column("mode", "u1", "", "0 ACQUIRE, 1 TRACK, 2 COAST"),
    Column("flags", "u2", "", "quality flags (gyrostar.loop.record FLAG_*); bits 12–15: the reason code "
           "(FLATSAT §output records: 0 tracking, 1 acquiring, 2 few stars, 3 blinded, 4 rate, 5 head lost)"),
    Column("n_stars", "u1", "", "stars tracked; in COAST those the newest image still measured (0: none)"),
    *_vec("q", "xyzw", "f8", "1", "attitude quaternion ICRS → body, scalar last"),
    *_vec("omega", "xyz", "f8", "rad/s", "body rate, bias-corrected, body axes"),
    *_vec("bias", "xyz", "f8", "rad/s", "gyro bias estimate, body axes"),
    *_vec("sigma_theta", "xyz", "f8", "rad", "1-sigma attitude error about the body axis"),
    *_vec("sigma_bias", "xyz", "f8", "rad/s", "1-sigma gyro bias error"),
    Column("latency_us", "f4", "us", "host time from the gyro FIFO read to this output"),
    Column("t_mid_monotonic_s", "f8", "s", "mid-exposure host time of the newest frame applied (nan: none)"),
    Column("tai_mid_s", "f8", "s", "the same instant in TAI seconds since 1958-01-01"),
    *_vec("q_mid", "xyzw", "f8", "1", "attitude at t_mid filtered with that frame, ICRS → body"),
    *_vec("sigma_theta_mid", "xyz", "f8", "rad", "1-sigma error of q_mid about the body axis"),
    Column("t_mid_s_monotonic_s", "f8", "s", "mid-exposure host time of the frame before (nan: none)"),
    *_vec("q_mid_s", "xyzw", "f8", "1", "attitude at t_mid_s smoothed with the newest frame, ICRS → body"),
    *_vec("sigma_theta_mid_s", "xyz", "f8", "rad", "1-sigma error of q_mid_s about the body axis"),
])
NAMES = tuple(c.name for c in COLUMNS)


def table(records: np.ndarray, timemap=None) -> dict[str, np.ndarray]:
    """Column name → array for output records (``tai_s`` NaN without a time map)."""
    t = records["t"].astype(np.float64)
    d = sigma(records["cov"])
    out = {"t_monotonic_s": t, "tai_s": timemap.tai(t) if timemap is not None else np.full(len(t), np.nan),
           "seq": records["seq"], "mode": records["mode"], "flags": records["flags"], "n_stars": records["n_stars"]}
    for i, a in enumerate("xyzw"):
        out[f"q_{a}"] = records["q"][:, i]
    for i, a in enumerate("xyz"):
        out[f"omega_{a}"] = records["omega"][:, i]
        out[f"bias_{a}"] = records["bias"][:, i]
        out[f"sigma_theta_{a}"] = d[:, i]
        out[f"sigma_bias_{a}"] = d[:, 3 + i]
    out["latency_us"] = records["latency_us"]
    if "t_mid" in (records.dtype.names or ()):
        out["t_mid_monotonic_s"] = records["t_mid"]
        out["tai_mid_s"] = timemap.tai(records["t_mid"]) if timemap is not None else np.full(len(t), np.nan)
        out["t_mid_s_monotonic_s"] = records["t_mid_s"]
        for key, q, cov in (("", "q_mid", "cov_mid"), ("_s", "q_mid_s", "cov_mid_s")):
            dm = sigma(records[cov])
            for i, a in enumerate("xyzw"):
                out[f"q_mid{key}_{a}"] = records[q][:, i]
            for i, a in enumerate("xyz"):
                out[f"sigma_theta_mid{key}_{a}"] = dm[:, i]
    else:                                   # logs recorded before the mid-exposure products
        for c in COLUMNS:
            out.setdefault(c.name, np.full(len(t), np.nan))
    return {c.name: np.asarray(out[c.name]).astype(c.dtype) for c in COLUMNS}
