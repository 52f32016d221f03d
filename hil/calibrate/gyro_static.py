"""``gyrostar calibrate gyro-static``: per-axis bias (and its temperature coefficient when the
log has temperatures) and the IEEE 952 noise terms from the overlapping Allan deviation
(:mod:`gyrostar.calibration.allan`), with a log-log plot of the curve and the fitted lines.

Input: a static gyro log ``.npz`` (``t`` s, ``rate`` N×3 rad/s, optional ``temperature``
°C), ``--live`` (records ``--duration`` s from a BMI088), or ``--simulate``: the
simulator's gyro truth and error model (:mod:`gyrostar.mocks.gyro_truth`, parameter set
``--gyro-params`` with ``--set KEY=VALUE`` overrides) at rest for ``--hours``.

How long a log must be. The simulator's bias instability is first-order Gauss–Markov
(σ, T_c); a record of length T holds about T/(2 T_c) independent looks at it, so σ² has a
relative error ≈ √(4 T_c / T) even with no other noise: σ to 5 % (1-σ, so that a 10 %
check is a 2-σ one) needs T ≈ 400 T_c, times (1 + r)² where r is the ARW variance over
the Markov variance at the Markov peak (τ ≈ 1.89 T_c). For the datasheet-class ``bmi088``
set (0.014 °/s/√Hz, 2 °/h, T_c = 100 s) r ≈ 4.4 (ARW variance over Markov variance at
the peak, with the IEEE N = n/√2) and T ≈ 330 h (``gyro_sim.sound_static_hours``): its
bias instability is buried under the ARW for any practical record. The default simulation
therefore uses the ``bmi088`` set with a consumer-MEMS bias wander (20 °/h, T_c = 10 s;
r ≈ 0.44, T ≈ 2.3 h for a 2-σ check); the default 3 h gives ≈ 4.4 % 1-σ on σ, so the 10 %
check is a 2.3-σ one per axis. The estimate of that 1-σ for the record at hand is printed
as ``bias_instability_rel_sigma``. ``--hours`` overrides the length.
"""

from __future__ import annotations

import numpy as np

HELP = "gyro bias and Allan-deviation noise terms (ARW, bias instability, RRW) from a static log"

RAD2DEG = 180.0 / np.pi
MAX_HOURS = 12.0   # --hours: a night on the bench; ≈ 3.5 GB peak (gyro_sim.MAX_INTERNAL_SAMPLES)


def configure(parser) -> None:
    from ...calibration.gyro_log import add_live_args
    from ...calibration.report import add_common_args
    from ...cli.argtypes import float_in, positive_float
    from .gyro_sim import gyro_param_sets, override

    add_common_args(parser, "static gyro log (.npz with t [s], rate [rad/s, N×3], optional temperature [C])", live=True)
    add_live_args(parser)
    parser.add_argument("--gyro-params", default="bmi088", choices=gyro_param_sets(),
                        help="--simulate: gyro error-model parameter set (default bmi088)")
    parser.add_argument("--set", action="append", type=override, default=None, metavar="KEY=VALUE",
                        help="--simulate: override a gyro parameter (repeatable; default "
                             "bias_instability_dph=20 bias_tau_s=10, see the module docstring)")
    parser.add_argument("--hours", type=float_in(0.001, MAX_HOURS, unit="h"), default=3.0,
                        help=f"--simulate: record length, h, 0.001 to {MAX_HOURS:g} (default 3; the simulation holds "
                             "the whole record, ≈ 0.3 GB per hour at the BMI088's 1600 Hz internal rate)")
    parser.add_argument("--bias-model", choices=("auto", "flicker", "markov"), default="auto",
                        help="bias-instability term: flicker floor, Gauss-Markov, or the better fit")
    parser.add_argument("--tau-min", type=positive_float, default=0.1,
                        help="shortest cluster time used in the fit, s (default 0.1: above the 47 Hz filter)")


def analyse(rec, tau_min: float = 0.1, bias_model: str = "auto", step=None):
    """Bias, temperature coefficient, Allan curves and noise terms of a static record
    (``step()`` is called after each axis)."""
    from ...calibration.allan import allan_deviation, fit_noise_terms, slope_readings

    fs = rec.fs
    bias = rec.rate.mean(axis=0)
    tc = None
    if rec.temperature is not None and np.ptp(rec.temperature) > 1.0:
        blk = max(int(fs), 1)
        from ...calibration.allan import block_average

        tb = block_average(rec.temperature, blk)
        rb = block_average(rec.rate, blk)
        a = np.column_stack([np.ones_like(tb), tb - tb.mean()])
        coef, *_ = np.linalg.lstsq(a, rb, rcond=None)
        tc = coef[1]
    curves, terms, slopes = [], [], []
    for axis in range(3):
        c = allan_deviation(rec.rate[:, axis], fs)
        curves.append(c)
        terms.append(fit_noise_terms(c, tau_min=tau_min, model=bias_model))
        slopes.append(slope_readings(c))
        if step is not None:
            step()
    return {"bias": bias, "temp_coeff": tc, "curves": curves, "terms": terms, "slopes": slopes, "fs": fs,
            "duration": float(rec.t[-1] - rec.t[0])}


def bias_rel_sigma(terms, duration_s: float) -> float:
    """Approximate 1-σ relative error of the fitted bias-instability coefficient from the
    record length: ½·√(4 T_c/T)·(1 + r) for a Markov term (T_c its correlation time, r the
    ARW-to-Markov variance ratio at the Markov peak); for a flicker floor the same with
    T_c → the τ where the ARW line meets the floor."""
    b = terms.bias_instability
    if b <= 0:
        return float("inf")
    if terms.model == "markov":
        tc = terms.markov_tau
        peak = (0.617 * b) ** 2
        r = terms.arw**2 / (1.89 * tc) / peak
    else:
        tc = (terms.arw / (0.6643 * b)) ** 2
        r = 1.0
    return float(0.5 * np.sqrt(4.0 * tc / duration_s) * (1.0 + r))


DEFAULT_SET = ["bias_instability_dph=20", "bias_tau_s=10"]


def simulate(args):
    """A static record from the simulator's gyro model, and its truth (SI units)."""
    from . import gyro_sim

    p = gyro_sim.params(args.gyro_params, DEFAULT_SET if args.set is None else args.set)
    gyro_sim.check_length(p, args.hours * 3600.0, "--hours")
    rec, truth = gyro_sim.static_record(p, args.hours, args.seed)
    truth["sound_hours"] = gyro_sim.sound_static_hours(p)
    return rec, truth


def run(args) -> int:
    from ...calibration import calfile, report
    from ...calibration.gyro_log import load, record_live
    from ...cli.output import progress

    source = report.check_source(args)
    rec = load(args.input) if source == "file" else None
    folder = report.report_dir(args, "gyro-static")
    truth = None
    # stages: the record (simulated or live), then the Allan deviation and fit of each axis
    with progress(args, "gyro-static: record, Allan deviation per axis", 4) as step:
        if source == "simulate":
            rec, truth = simulate(args)
        elif source == "live":
            rec = record_live(args, folder)
        step()
        a = analyse(rec, args.tau_min, args.bias_model, step)
    table = report.ParamTable()
    t = truth or {}
    table.add("bias_dps", a["bias"] * RAD2DEG, "deg/s", None if "bias" not in t else np.asarray(t["bias"]) * RAD2DEG)
    arw = np.array([x.arw for x in a["terms"]])
    bi = np.array([x.bias_instability for x in a["terms"]])
    rrw = np.array([x.rrw for x in a["terms"]])
    q = np.array([x.quantization for x in a["terms"]])
    conv = {"arw": RAD2DEG * 60.0, "bias_instability": RAD2DEG * 3600.0, "rrw": RAD2DEG * 3600.0 * 60.0}
    units = {"arw": "deg/sqrt(h)", "bias_instability": "deg/h", "rrw": "deg/h/sqrt(h)"}
    for name, val in (("arw", arw), ("bias_instability", bi), ("rrw", rrw)):
        tv = t.get(name)
        table.add(name, val * conv[name], units[name], None if tv is None else np.asarray(tv) * conv[name])
        if tv is not None:
            table.rows[name]["rel_error"] = (val / np.asarray(tv) - 1.0).tolist()
    if np.any(q > 0):
        table.add("quantization_rad", q, "rad")
    if a["temp_coeff"] is not None:
        table.add("bias_temp_coeff_dps_per_c", a["temp_coeff"] * RAD2DEG, "deg/s/C")
    extra = {"duration_s": a["duration"], "fs_hz": a["fs"],
             "bias_model": [x.model for x in a["terms"]], "markov_tau_s": [x.markov_tau for x in a["terms"]],
             "bias_instability_rel_sigma": [bias_rel_sigma(x, a["duration"]) for x in a["terms"]],
             "slope_readings": {k: [s[k] for s in a["slopes"]] for k in a["slopes"][0]}}
    checks = None
    if truth is not None:
        extra["hours_for_2sigma_bias_check"] = truth["sound_hours"]
        checks = {}
        for name, val in (("arw", arw), ("bias_instability", bi)):
            rel = np.abs(val / np.asarray(truth[name]) - 1.0)
            checks[f"{name}_rel"] = report.check(float(rel.max()), 0.10, "(10 %, worst axis)")
    cal = calfile.GyroStaticCal(
        tuple(float(v) for v in a["bias"]), tuple(float(v) for v in arw), tuple(float(v) for v in bi),
        tuple(float(v) for v in rrw), tuple(float(v) for v in q), a["duration"],
        float(np.mean(rec.temperature)) if rec.temperature is not None else None,
        tuple(float(v) for v in a["temp_coeff"]) if a["temp_coeff"] is not None else None)
    toml = args.toml or folder / "calibration.toml"
    calfile.write_section(toml, "gyro_static", cal, source=str(args.input) if args.input else source)
    extra["toml"] = str(toml)
    if not args.no_plots:
        _plot(folder, a)
    return report.finish(args, "gyro-static", table, extra, folder, checks)


def _plot(folder, a) -> None:
    from ...calibration.report import new_figure, save_figure

    fig, axes = new_figure(1, 3, figsize=(16, 5), sharey=True)
    to_dph = RAD2DEG * 3600.0
    for axis, (ax, c, x) in enumerate(zip(axes, a["curves"], a["terms"])):
        tau = np.logspace(np.log10(c.tau[0]), np.log10(c.tau[-1]), 200)
        ax.errorbar(c.tau, c.adev * to_dph, yerr=c.err * to_dph, fmt=".", ms=3, label="overlapping ADEV")
        ax.loglog(tau, x.adev(tau) * to_dph, "k-", lw=1.5, label="IEEE 952 model")
        ax.loglog(tau, x.arw / np.sqrt(tau) * to_dph, "--", label=f"ARW {x.arw * RAD2DEG * 60:.3g} °/√h (−½)")
        if x.model == "markov":
            label = f"Markov σ {x.bias_instability * to_dph:.3g} °/h, T_c {x.markov_tau:.3g} s"
        else:
            label = f"BI {x.bias_instability * to_dph:.3g} °/h (0)"
        ax.loglog(tau, x.bias_term_adev(tau) * to_dph, "--", label=label)
        if x.rrw > 0:
            ax.loglog(tau, x.rrw * np.sqrt(tau / 3.0) * to_dph, "--",
                      label=f"RRW {x.rrw * to_dph * 60:.3g} °/h/√h (+½)")
        if x.quantization > 0:
            ax.loglog(tau, np.sqrt(3.0) * x.quantization / tau * to_dph, ":", label="quantisation (−1)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(max(c.adev.min() * to_dph / 5, 1e-3), c.adev.max() * to_dph * 3)
        ax.set_title(f"axis {'xyz'[axis]}")
        ax.set_xlabel("τ (s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("Allan deviation (°/h)")
    save_figure(fig, folder / "allan_deviation.png")
