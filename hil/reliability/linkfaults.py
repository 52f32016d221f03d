"""Link faults during a run of the coupled loop at 100 Hz frames (400 Hz gyro).

``python -m gyrostar.hil.reliability.linkfaults [--duration 30] [--seed 1]`` runs the built-in
flatsat with four faults on the head → host reply stream (one after another, each
``FAULT_S`` long, starting at ``FIRST_S``): 1 % random byte corruption, dropped bytes
(0.1 %), garbage bursts (8–64 random bytes before 30 % of replies), and a 2 s disconnect
(the head's pty closes, a new one opens). It prints one JSON object: per fault the
attitude continuity (cross-boresight error vs simulator truth just before, the maximum
during, the maximum over the 2 s after; the largest increase and decrease of that error
between consecutive 400 Hz outputs), the mode time during the fault, the image frames
the loop needed after the fault to get a good one back (resynchronisation), injected vs
counted bad frames, and run-wide: exceptions escaping the loop (must be 0), gyro samples
lost, mode time. Exit status 1 when a criterion fails.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

FIRST_S = 6.0
FAULT_S = 3.0
GAP_S = 3.0


def schedule(first_s: float = FIRST_S, fault_s: float = FAULT_S, gap_s: float = GAP_S):
    """The four link faults, back to back with ``gap_s`` of clean link between them."""
    from ..config import Fault

    kinds = [("corruption 1 %", "link-corruption", {"rate": 0.01}, fault_s),
             ("dropped bytes 0.1 %", "link-corruption", {"rate": 0.0, "drop_rate": 0.001}, fault_s),
             ("garbage bursts", "link-corruption", {"rate": 0.0, "garbage_rate": 0.3}, fault_s),
             ("disconnect 2 s", "head-disconnect", {}, 2.0)]
    out, t = [], first_s
    for name, kind, rates, secs in kinds:
        out.append((name, Fault(kind, t, secs, **rates)))
        t += secs + gap_s
    return out


def cumulative(x: np.ndarray) -> np.ndarray:
    """A counter that restarts (a new head client after reconnect) made cumulative."""
    d = np.diff(x, prepend=x[:1])
    return np.cumsum(np.where(d < 0, x, d))


IN_FLIGHT_S = 0.05   # s: longer than one image cycle (windows, exposure, reply) at 100 Hz


def analyse(res: dict, faults) -> dict:
    """Per-fault continuity, resynchronisation and bad-frame accounting from a campaign result."""
    from .campaign import cross_boresight_error_arcsec, mode_seconds

    tr, truth = res["trace"], res["truth"]
    t = tr["t"] - res["t_origin"]
    err = cross_boresight_error_arcsec(tr, truth)
    good = tr["frames"]
    failed = tr["frames_failed"]
    corrupt = cumulative(tr["link_corrupt"])
    retries = cumulative(tr["link_retries"])
    step = np.diff(err, prepend=np.nan)
    out = []
    for (name, ev), counts in zip(faults, res["byte_faults"]):
        t0, t1 = ev.at_s, ev.at_s + ev.seconds
        before = (t >= t0 - 1.0) & (t < t0)
        during = (t >= t0) & (t < t1)
        # a frame whose reply was already on the wire when the fault began completes inside
        # the window without having crossed the faulty link: not counted as good "during"
        settled = (t >= t0 + IN_FLIGHT_S) & (t < t1)
        after = (t >= t1) & (t < t1 + 2.0)
        around = (t >= t0 - 1.0) & (t < t1 + 2.0)
        i1 = int(np.searchsorted(t, t1))
        ok_rows = np.flatnonzero(good[i1:] > good[i1]) if i1 < len(t) else np.zeros(0, int)
        resync = None
        t_back = None
        if len(ok_rows):
            j = i1 + int(ok_rows[0])
            # image cycles that ended after the fault: failures before the first good one, plus it
            resync = int(failed[j] - failed[i1]) + 1
            t_back = float(t[j] - t1)
        d = {
            "fault": name, "at_s": t0, "seconds": ev.seconds,
            "mode_at_start": int(tr["mode"][max(int(np.searchsorted(t, t0)) - 1, 0)]) if len(t) else None,
            "err_before_arcsec": _nanmax(err[before]),
            "err_max_during_arcsec": _nanmax(err[during]),
            "err_max_after_2s_arcsec": _nanmax(err[after]),
            # continuity: the largest change of the error between consecutive outputs (2.5 ms)
            # that made it worse (a jump), and that made it better (an update correcting the coast)
            "err_largest_increase_step_arcsec": _nanmax(step[around]),
            "err_largest_correction_step_arcsec": _nanmax(-step[around]),
            "modes_during_s": mode_seconds(t, tr["mode"], during),
            "valid_fraction_during": float(np.mean(np.isfinite(err[during]))) if np.any(during) else None,
            "frames_good_during": int(np.ptp(good[settled])) if np.any(settled) else 0,
            "frames_failed_during": int(np.ptp(failed[during | after])) if np.any(during) else 0,
            "resync_frames": resync, "resync_s": t_back,
            "host_corrupt_frames": int(np.ptp(corrupt[during | after])) if np.any(during) else 0,
            "host_retries": int(np.ptp(retries[during | after])) if np.any(during) else 0,
        }
        if counts:
            d["injected"] = counts
            # every mangled reply must show up as a corrupt frame or a missing reply (retry); a lost
            # delimiter joins a mangled reply to the next one, which may be mangled too: one corrupt
            # frame for both
            d["bad_frames_accounted"] = (d["host_corrupt_frames"] + d["host_retries"] + counts.get("delimiters_lost", 0)
                                         >= counts.get("mangled", 0))
        out.append(d)
    return out


def _nanmax(x):
    x = x[np.isfinite(x)]
    return float(x.max()) if x.size else None


def run(duration: float = 30.0, seed: int = 1) -> dict:
    from .campaign import mode_seconds, run_campaign

    faults = schedule()
    res = run_campaign([ev for _, ev in faults], duration, seed=seed, keep_hz=400.0, rss_every_s=5.0)
    per = analyse(res, faults)
    tr = res["trace"]
    modes = mode_seconds(tr["t"], tr["mode"])
    summary = {
        "duration_s": duration, "seed": seed, "wall_s": round(res["wall_s"], 1),
        "exceptions_escaped": res["n_exceptions"], "exceptions": res["exceptions"],
        "faults": per, "counters": res["counters"], "mode_seconds": modes,
        "overruns": res["overruns"], "steps": res["steps"],
    }
    summary["pass"] = bool(
        res["n_exceptions"] == 0
        and all(f["resync_frames"] is not None and f["resync_frames"] <= 2 for f in per)
        and all(f.get("bad_frames_accounted", True) for f in per))
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyrostar.hil.reliability.linkfaults",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    from ...cli.output import json_safe

    s = run(a.duration, a.seed)
    json.dump(json_safe(s), sys.stdout, indent=1)
    print()
    return 0 if s["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
