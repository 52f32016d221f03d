"""The orbit environment of a simulated run, for its summary: the hazard parameters switched on
and what the simulator's truth says happened (sampled once a second along the true attitude)."""

from __future__ import annotations

import numpy as np

SAMPLE_S = 1.0


def environment_summary(env, truth, preset, params, duration_s: float, t_origin: float) -> dict:
    """``{"parameters": …, "truth": …}`` of ``env`` (:class:`gyrostar.mocks.environment.Environment`)
    over a run of ``duration_s`` (s) whose attitude truth is ``truth`` (host times from ``t_origin``);
    ``preset``, ``params``: the head's simulator preset and true camera array."""
    ts = np.arange(0.0, max(duration_s, SAMPLE_S), SAMPLE_S)
    rows = truth.rows(t_origin + ts)
    samples = [env.truth(float(t), q, preset, params) for t, q in zip(ts, rows["q"])]
    out: dict = {"sampled_every_s": SAMPLE_S}

    def span(key):
        v = [s[key] for s in samples if s.get(key) is not None]
        return [float(min(v)), float(max(v))] if v else None

    if env.thermal.enabled:
        out["temperature_c"] = span("temperature_c")
    if env.rad.enabled:
        out["saa_seconds"] = SAMPLE_S * sum(bool(s["in_saa"]) for s in samples)
        out["hits_per_frame"] = span("hits_per_frame")
    if env.orbit is not None:
        out["sun_angle_deg"] = span("sun_angle_deg")
        out["earth_limb_angle_deg"] = span("earth_limb_angle_deg")
        out["moon_angle_deg"] = span("moon_angle_deg")
        out["eclipse_seconds"] = SAMPLE_S * sum(bool(s["eclipse"]) for s in samples)
        out["stray_e_px_at_centre"] = span("stray_e_px")
        out["moon_in_field_seconds"] = SAMPLE_S * sum(s.get("moon_uv") is not None for s in samples)
        out["subpoint_start_deg"] = [samples[0]["lat_deg"], samples[0]["lon_deg"]]
    return {"parameters": env.describe(), "truth": out}


def summary_line(r: dict) -> str | None:
    """The human summary's line for a run's ``environment`` entry (None without one)."""
    env = r.get("environment")
    if not env:
        return None
    parts = []
    for key, cfg in env["parameters"].items():
        vals = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in cfg.items())
        parts.append(f"{key} ({vals})")
    tr = env["truth"]
    seen = []
    if tr.get("sun_angle_deg"):
        seen.append("Sun {:.1f}–{:.1f}°".format(*tr["sun_angle_deg"]))
        seen.append("Earth limb {:.1f}–{:.1f}°".format(*tr["earth_limb_angle_deg"]))
        seen.append("Moon {:.1f}–{:.1f}°".format(*tr["moon_angle_deg"]))
        seen.append(f"eclipse {tr['eclipse_seconds']:.0f} s")
        seen.append("stray light {:.3g}–{:.3g} e⁻/px".format(*tr["stray_e_px_at_centre"]))
    if "saa_seconds" in tr:
        lo, hi = tr["hits_per_frame"]
        seen.append(f"SAA {tr['saa_seconds']:.0f} s, hits/frame {lo:.2g}–{hi:.2g}")
    if tr.get("temperature_c"):
        seen.append("sensor {:.1f}–{:.1f} °C".format(*tr["temperature_c"]))
    return "  orbit environment: " + "; ".join(parts) + "\n  environment truth (from the boresight): " + ", ".join(seen)
