"""A scenario's acceptance keys applied to a run's summary (``gyrostar run`` exits 1 on a failure).

Keys (:class:`gyrostar.hil.config.Scenario`): ``max_error_arcsec_1sigma`` (cross-boresight
1σ over TRACK samples against truth; 0 = not checked), ``max_error_over_floor`` (that error over
the run's own attitude floor, ``measured_over_floor``; 0 = not checked), ``min_track_fraction`` (share of
outputs in TRACK with a valid attitude; 0 = not checked), ``must_reacquire`` (TRACK lost
and regained at least once). They describe the whole scenario: a run shorter than it, or
one without simulator truth (a real flatsat, for the error and the TRACK share) is not
judged on them, and the result says why.

Two checks hold for every run however long, truth or not: ``max_samples_lost`` (gyro
samples lost to a FIFO overflow, from the loop's counters; 0 unless the scenario injects a
stall; -1 = not checked), and ``reached_track`` (some time in TRACK, from the output modes)
for a scenario that expects tracking (any of the three keys above set): a run that loses
samples, or never tracks, never passes. An interrupted run is not judged.
"""

from __future__ import annotations


def expects_tracking(scen) -> bool:
    """The scenario judges the tracking (any of its tracking keys is set)."""
    return (scen.max_error_arcsec_1sigma > 0 or scen.max_error_over_floor > 0 or scen.min_track_fraction > 0
            or scen.must_reacquire)


def evaluate(scen, summary: dict, duration_s: float) -> dict:
    """``{"applied": bool, "note": str, "checks": {key: {value, limit, unit, pass}}}``."""
    if summary.get("interrupted"):
        return {"applied": False, "note": "run interrupted", "checks": {}}
    checks: dict = {}
    if scen.max_samples_lost >= 0:
        lost = int(summary.get("samples_lost") or 0)
        checks["max_samples_lost"] = {"value": lost, "limit": scen.max_samples_lost, "unit": "gyro samples",
                                      "pass": lost <= scen.max_samples_lost}
    if expects_tracking(scen):
        tracked = float((summary.get("mode_seconds") or {}).get("TRACK", 0.0))
        checks["reached_track"] = {"value": tracked, "limit": 0, "unit": "s in TRACK", "pass": tracked > 0,
                                   "failed": "never reached TRACK"}
    if not checks:
        return {"applied": False, "note": f"scenario {scen.name} sets no acceptance keys", "checks": {}}
    if duration_s + 1e-9 < scen.duration_s:
        note = (f"run of {duration_s:g} s is shorter than the scenario's {scen.duration_s:g} s: "
                "only lost samples and reaching TRACK checked") if expects_tracking(scen) else ""
        return {"applied": True, "checks": checks, "note": note}
    has_truth = "track_fraction" in summary
    if scen.max_error_arcsec_1sigma > 0 and has_truth:
        err = summary.get("attitude_error_arcsec_1sigma")
        checks["max_error_arcsec_1sigma"] = {"value": err, "limit": scen.max_error_arcsec_1sigma, "unit": "arcsec",
                                             "pass": err is not None and err <= scen.max_error_arcsec_1sigma}
    if scen.max_error_over_floor > 0 and has_truth:
        ratio = summary.get("measured_over_floor")
        checks["max_error_over_floor"] = {"value": ratio, "limit": scen.max_error_over_floor, "unit": "x floor",
                                          "pass": ratio is not None and ratio <= scen.max_error_over_floor}
    if scen.min_track_fraction > 0 and has_truth:
        frac = summary["track_fraction"]
        checks["min_track_fraction"] = {"value": frac, "limit": scen.min_track_fraction, "unit": "",
                                        "pass": frac >= scen.min_track_fraction}
    if scen.must_reacquire:
        n = summary.get("track_regained", 0)
        checks["must_reacquire"] = {"value": n, "limit": 1, "unit": "returns to TRACK", "pass": n >= 1}
    judged_on_truth = scen.max_error_arcsec_1sigma > 0 or scen.min_track_fraction > 0
    note = "" if has_truth or not judged_on_truth else "no simulator truth: error and track fraction not checked"
    return {"applied": True, "note": note, "checks": checks}


def track_regained(mode, track_mode: int) -> int:
    """How often the mode sequence returned to TRACK after leaving it."""
    import numpy as np

    tr = np.asarray(mode) == track_mode
    entries = int(np.count_nonzero(tr[1:] & ~tr[:-1])) + int(bool(len(tr) and tr[0]))
    return max(entries - 1, 0)


def failures(result: dict) -> list[str]:
    """One text per failed check, e.g. ``max_error_arcsec_1sigma: 4.58 > 3 arcsec``."""
    out = []
    for key, c in result.get("checks", {}).items():
        if c["pass"]:
            continue
        if c.get("failed"):
            out.append(f"{key}: {c['failed']}")
            continue
        value = "never tracked" if c["value"] is None else f"{c['value']:.4g}"
        rel = "<" if key.startswith("min") or key == "must_reacquire" else ">"
        rel = rel if c["value"] is not None else "vs limit"
        out.append(f"{key}: {value} {rel} {c['limit']:g} {c['unit']}".rstrip())
    return out
