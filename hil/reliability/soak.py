"""Soak: the coupled loop on the simulated flatsat for an hour with random faults.

``python -m gyrostar.hil.reliability.soak [--duration 3600] [--seed 1] [--out soak.json]``
(``make soak``). The body rate changes every 2 min (uniform ±0.4 °/s per axis); faults
arrive as a Poisson process (mean every ``--fault-every`` s): reply-stream corruption
(1 %), dropped bytes (0.1 %), garbage bursts, a head disconnect (1–3 s), gyro NACK bursts
(20–200 ms), loop stalls that overrun the gyro FIFO (0.1–0.5 s) and head clock steps (the MCU
clock jumps 5 ms–5 s ahead or back, log-uniform, the link open). Prints one JSON
object: RSS of the loop process and of the head-emulator process at the start (after the
first minute) and at the end, plus the series; overruns per 10-minute window (first vs
last); exceptions escaping the loop; attitude error (cross-boresight, TRACK) per window;
the loop's counters. Exit status 1 when RSS grows by more than ``--max-rss-growth-mb``, the
last window's overrun rate exceeds twice the first's plus 0.5 %, or anything escaped the loop.
"""

from __future__ import annotations

import argparse
import json
import random
import sys

import numpy as np

WINDOW_S = 600.0


def random_schedule(duration: float, seed: int, every_s: float = 45.0, quiet_start_s: float = 60.0):
    """Faults at Poisson times (mean spacing ``every_s``), none in the first ``quiet_start_s``."""
    from ..config import Fault

    rng = random.Random(seed)
    out = []
    t = quiet_start_s
    while True:
        t += rng.expovariate(1.0 / every_s)
        kind = rng.choice(["corrupt", "drop", "garbage", "disconnect", "gyro-nack", "gyro-stall", "clock-step"])
        if kind in ("corrupt", "drop", "garbage"):
            secs = rng.uniform(1.0, 3.0)
            rates = {"corrupt": {"rate": 0.01}, "drop": {"rate": 0.0, "drop_rate": 0.001},
                     "garbage": {"rate": 0.0, "garbage_rate": 0.3}}[kind]
            ev = Fault("link-corruption", t, secs, **rates)
        elif kind == "disconnect":
            ev = Fault("head-disconnect", t, rng.uniform(1.0, 3.0))
        elif kind == "gyro-nack":
            ev = Fault("gyro-nack", t, rng.uniform(0.02, 0.2))
        elif kind == "clock-step":
            # log-uniform 5 ms .. 5 s: a few ms (a timer reload) up to a host suspend
            ev = Fault("head-clock-step", t, 0.0, step_s=rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-2.3, 0.7))
        else:
            ev = Fault("gyro-fifo-overrun", t, rng.uniform(0.1, 0.5))
        if t + ev.seconds >= duration - 5.0:
            return out
        out.append((kind, ev))
        t += ev.seconds


def rate_segments(duration: float, seed: int, every_s: float = 120.0, max_dps: float = 0.4):
    from .. import config as hc

    rng = np.random.default_rng(seed)
    n = int(np.ceil((duration + 60.0) / every_s))
    return [hc.Segment(seconds=every_s, rate_dps=tuple(float(v) for v in rng.uniform(-max_dps, max_dps, 3)))
            for _ in range(n)]


def run(duration: float = 3600.0, seed: int = 1, fault_every_s: float = 45.0, max_rss_growth_mb: float = 20.0,
        progress: bool = True) -> dict:
    from ...loop.record import MODE_NAMES, MODE_TRACK
    from .campaign import cross_boresight_error_arcsec, mode_seconds, run_campaign
    from .linkfaults import cumulative

    faults = random_schedule(duration, seed, fault_every_s)

    def show(t, loop):
        if progress:
            from .campaign import rss_bytes

            print(f"soak {t:7.0f}/{duration:.0f} s  mode {MODE_NAMES[loop.mode]:7s} frames {loop.c.frames} "
                  f"rss {rss_bytes() / 2**20:.1f} MB", file=sys.stderr, flush=True)

    res = run_campaign([ev for _, ev in faults], duration, seed=seed, keep_hz=10.0,
                       segments=rate_segments(duration, seed), rss_every_s=60.0, progress=show)
    tr, rss = res["trace"], res["rss"]
    t = tr["t"] - res["t_origin"]
    err = cross_boresight_error_arcsec(tr, res["truth"])
    windows = []
    for w0 in np.arange(0.0, duration, WINDOW_S):
        m = (t >= w0) & (t < w0 + WINDOW_S)
        if not np.any(m):
            continue
        idx = np.flatnonzero(m)
        ov = int(tr["overruns"][idx[-1]] - (tr["overruns"][idx[0] - 1] if idx[0] > 0 else 0))
        trk = m & (tr["mode"] == MODE_TRACK) & np.isfinite(err)
        windows.append({
            "from_s": float(w0), "overruns": ov, "overrun_percent": 100.0 * ov / (WINDOW_S * 400.0),
            "track_fraction": float(np.mean(tr["mode"][m] == MODE_TRACK)),
            "err_track_median_arcsec": float(np.median(err[trk])) if np.any(trk) else None,
            "err_track_p99_arcsec": float(np.percentile(err[trk], 99)) if np.any(trk) else None,
        })
    i0 = int(np.searchsorted(rss[:, 0], 60.0)) if len(rss) > 1 else 0
    i0 = min(i0, len(rss) - 1)
    rss_start, rss_end = rss[i0], rss[-1]
    growth = (rss_end[1] - rss_start[1]) / 2**20
    kinds: dict = {}
    for k, _ in faults:
        kinds[k] = kinds.get(k, 0) + 1
    first, last = windows[0], windows[-1]
    summary = {
        "duration_s": duration, "seed": seed, "wall_s": round(res["wall_s"], 1), "steps": res["steps"],
        "faults_injected": len(faults), "fault_kinds": kinds,
        "rss_start_mb": round(rss_start[1] / 2**20, 2), "rss_end_mb": round(rss_end[1] / 2**20, 2),
        "rss_start_t_s": float(rss_start[0]), "rss_end_t_s": float(rss_end[0]),
        "rss_growth_mb": round(growth, 2),
        "emulator_rss_start_mb": round(rss_start[2] / 2**20, 2), "emulator_rss_end_mb": round(rss_end[2] / 2**20, 2),
        "rss_series_mb": [[round(float(a), 0), round(b / 2**20, 2), round(c / 2**20, 2)] for a, b, c in rss],
        "overruns_total": res["overruns"], "windows": windows,
        "exceptions_escaped": res["n_exceptions"], "exceptions": res["exceptions"],
        "mode_seconds": mode_seconds(tr["t"], tr["mode"]),
        "counters": {k: v for k, v in res["counters"].items() if k != "mode_changes"},
        "mode_changes": len(res["counters"]["mode_changes"]),
        # found by the clock model; a step while the head is away meets a new client's model
        "head_clock_steps_detected": int(cumulative(tr["link_clock_steps"])[-1]) if len(tr) else 0,
        "gyro_bus_injected": res["gyro_bus"],
    }
    summary["pass"] = bool(
        res["n_exceptions"] == 0 and growth <= max_rss_growth_mb
        and last["overrun_percent"] <= 2.0 * first["overrun_percent"] + 0.5)
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyrostar.hil.reliability.soak", description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="flatsat seconds (real time)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--fault-every", type=float, default=45.0, help="mean seconds between faults")
    ap.add_argument("--max-rss-growth-mb", type=float, default=20.0)
    ap.add_argument("--out", default="", help="also write the JSON here")
    a = ap.parse_args(argv)
    from ...cli.output import json_safe

    s = json_safe(run(a.duration, a.seed, a.fault_every, a.max_rss_growth_mb))
    text = json.dumps(s, indent=1)
    print(text)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text + "\n")
    return 0 if s["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
