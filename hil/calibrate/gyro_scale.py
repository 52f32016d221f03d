"""``gyrostar calibrate gyro-scale``: gyro scale factors and 3×3 misalignment
(:mod:`gyrostar.calibration.scale_fit`), from rate-table runs or from star-tracker attitude
during slews.

Inputs:

* ``--method rate-table``: an ``.npz`` gyro log with ``t``, ``rate`` (N×3 rad/s), ``run``
  (N,) run id (−1 while the table changes rate) and ``table_rate`` (K×3 rad/s, the known
  rate vector of each run in the gyro reference frame). ``--trim`` s are dropped at both
  ends of each run.
* ``--method slew`` (the default for a file without ``run``): an ``.npz`` with the gyro log
  (``t``, ``rate``) and the tracker's attitudes ``t_cam`` (K,) s and ``q_cam`` (K×4, [x, y, z, w]
  ICRS → camera) on the same clock, e.g. ``gyrostar replay LOG --export calib``. The result
  maps gyro readings to camera axes (mounting included) unless
  ``--alignment`` names a calibration TOML whose [alignment] rotation is removed first (by
  default the ``--out`` file's, when it has one).

``--simulate``: the simulator's gyro model (:mod:`gyrostar.hil.calibrate.gyro_sim`, parameter
set ``--gyro-params``) turned at ±``--rates`` about each axis for ``--run-seconds`` per run
(rate table), or a simulated slew seen by the tracker (slew).
"""

from __future__ import annotations

import numpy as np

HELP = "gyro scale factors and misalignment from rate-table runs or star-tracker slews"
DEG = np.pi / 180.0
OFF_DIAGONAL = tuple((i, j) for i in range(3) for j in range(3) if i != j)


MAX_RATE_DPS = 2000.0     # --rates: the BMI088's largest range
MAX_RUN_S = 600.0         # --run-seconds: 10 min per table run (the default schedule is then 3.3 h)
MAX_SLEW_S = 7200.0       # --duration: 2 h of slew at 20 attitudes/s


def configure(parser) -> None:
    from ...calibration.report import add_common_args
    from ...cli.argtypes import existing_file, float_in, float_list_in
    from .gyro_sim import gyro_param_sets, override

    add_common_args(parser, "gyro log .npz: t, rate (N×3 rad/s), run and table_rate for rate-table runs; or t, "
                            "rate, t_cam and q_cam (gyrostar replay LOG --export calib) for slews")
    parser.add_argument("--method", choices=("rate-table", "slew"), default=None,
                        help="default: slew when INPUT has no 'run' array (a flatsat run's export), else rate-table")
    parser.add_argument("--trim", type=float_in(0.0, 60.0, unit="s"), default=0.5,
                        help="rate table: seconds dropped at each run end, 0 to 60 (default 0.5)")
    parser.add_argument("--alignment", type=existing_file, default=None,
                        help="slew: calibration TOML whose [alignment] is applied (default: the --out file's, if any)")
    parser.add_argument("--gyro-params", default="bmi088", choices=gyro_param_sets(),
                        help="--simulate: gyro error-model parameter set (default bmi088)")
    parser.add_argument("--set", action="append", type=override, default=None, metavar="KEY=VALUE",
                        help="--simulate: override a gyro parameter (repeatable)")
    parser.add_argument("--rates", type=float_list_in(0.0, MAX_RATE_DPS, lo_open=True, max_count=10, unit="deg/s"),
                        default=[10.0, 30.0, 60.0],
                        help=f"--simulate: table rates, deg/s (both signs, each axis), at most 10, each in "
                             f"(0, {MAX_RATE_DPS:g}] (default 10,30,60)")
    parser.add_argument("--run-seconds", type=float_in(1.0, MAX_RUN_S, unit="s"), default=20.0,
                        help=f"--simulate: seconds per table run, 1 to {MAX_RUN_S:g}, more than twice --trim "
                             "(default 20)")
    parser.add_argument("--duration", type=float_in(10.0, MAX_SLEW_S, unit="s"), default=300.0,
                        help=f"--simulate slew: seconds, 10 to {MAX_SLEW_S:g} (default 300)")


def rate_table_schedule(rates_dps, run_s: float, gap_s: float = 2.0):
    """Table rate vectors (K×3 rad/s: ± each rate about each axis, then two tilted runs),
    the session as a piecewise-constant body-rate profile (table at rest between runs) and
    the session length (s)."""
    from ...mocks.trajectory import Piecewise

    vecs = []
    for r in rates_dps:
        for axis in range(3):
            for sign in (1.0, -1.0):
                v = np.zeros(3)
                v[axis] = sign * r * DEG
                vecs.append(v)
    top = max(rates_dps) * DEG / np.sqrt(3.0)
    vecs += [np.array([top, top, top]), np.array([-top, top, -top])]
    table = np.array(vecs)
    times, omegas = [], []
    for k, v in enumerate(table):
        times += [k * (run_s + gap_s), k * (run_s + gap_s) + run_s]
        omegas += [tuple(v), (0.0, 0.0, 0.0)]
    return table, Piecewise(tuple(times), tuple(omegas)), len(table) * (run_s + gap_s)


def run_ids(t: np.ndarray, n_runs: int, run_s: float, gap_s: float = 2.0) -> np.ndarray:
    """Run id of each sample time of a :func:`rate_table_schedule` session (−1 in the gaps)."""
    k = np.floor(t / (run_s + gap_s)).astype(np.int64)
    inside = (t - k * (run_s + gap_s) < run_s) & (k < n_runs)
    return np.where(inside, k, -1)


def _from_rate_table(rec_t, rate, run, table, trim_s):
    from ...calibration.scale_fit import fit_rate_table, run_means

    fs = 1.0 / np.median(np.diff(rec_t))
    means, _ = run_means(rate, run, len(table), trim=int(trim_s * fs))
    return fit_rate_table(table, means)


def from_slews(t_g, w_g, t_cam, q_cam, lag: int = 5):
    """Windows of ``lag`` camera frames, those whose gyro integral is not their rotation
    vector left out (:meth:`~gyrostar.calibration.gyro_integral.GyroIntegral.rotation_windows`:
    more than 170°, or not about one fixed axis)."""
    from ...calibration.gyro_integral import GyroIntegral
    from ...calibration.scale_fit import attitude_increments, fit_slews

    sel = (t_cam >= t_g[0]) & (t_cam <= t_g[-1])
    t_cam, q_cam = t_cam[sel], q_cam[sel]
    idx = np.arange(0, len(t_cam), lag)
    phi = attitude_increments(q_cam[idx])
    gi = GyroIntegral(t_g, w_g)
    g = np.diff(gi.at(t_cam[idx]), axis=0)
    keep = gi.rotation_windows(t_cam[idx][:-1], t_cam[idx][1:])
    return fit_slews(phi[keep], g[keep], np.diff(t_cam[idx])[keep])


def run(args) -> int:
    from pathlib import Path

    from ...calibration import calfile, report
    from ...errors import ConfigError
    from . import gyro_sim

    source = report.check_source(args)
    folder = report.report_dir(args, "gyro-scale")
    truth = None
    if args.method is None:
        args.method = "rate-table"
        if source == "file":
            z = report.read_npz(args.input, ("t", "rate"))
            args.method = "rate-table" if "run" in z else "slew"
    target = None
    if source == "file" and args.toml and Path(args.toml).exists():
        target = calfile.load(args.toml)
        if args.method == "slew" and not args.alignment and target.alignment is not None:
            args.alignment = str(args.toml)
    note = None
    if args.method == "rate-table":
        if source == "simulate":
            if 2.0 * args.trim >= args.run_seconds:
                raise ConfigError(f"--trim {args.trim:g} s at both ends leaves nothing of --run-seconds "
                                  f"{args.run_seconds:g}: give --run-seconds > 2 × --trim")
            table, profile, length = rate_table_schedule(args.rates, args.run_seconds)
            p = gyro_sim.params(args.gyro_params, args.set)
            gyro_sim.check_length(p, length, "--rates × --run-seconds")
            t, rate, truth = gyro_sim.measure_profile(profile, length, p, args.seed)
            run_id = run_ids(t - truth["delay_s"], len(table), args.run_seconds)
        else:
            z = report.read_npz(args.input, ("t", "rate", "run", "table_rate"))
            t, rate, run_id, table = z["t"], z["rate"], z["run"], z["table_rate"]
        fit = _from_rate_table(t, rate, run_id, table, args.trim)
    else:
        if source == "simulate":
            from .slew_sim import simulate_attitudes

            p = gyro_sim.params(args.gyro_params, args.set)
            gyro_sim.check_length(p, args.duration, "--duration")
            sl = simulate_attitudes(args.duration, 20.0, args.seed)
            t, rate, truth = gyro_sim.measure_profile(sl.profile, args.duration, p, args.seed)
            t_g = t - truth["delay_s"]  # the alignment calibration's time offset, applied
            t_cam, q_cam = sl.t_cam, sl.q_cam
        else:
            from ...calibration.star_fields import load_slew_input

            t_g, rate, t_cam, q_cam, note = load_slew_input(args.input, target)
            if args.alignment:
                al = calfile.load(args.alignment).alignment
                if al is None:
                    raise ConfigError(f"{args.alignment} has no [alignment] table")
                from ...attitude import quat_to_dcm

                r_align = quat_to_dcm(np.asarray(al.q_gyro_to_camera, float))
                rate = rate @ r_align.T
                t_g = t_g + al.time_offset_s
        fit = from_slews(t_g, rate, t_cam, q_cam)
        if args.alignment and source != "simulate":  # back to gyro axes: S_g = Rᵀ S_cam R
            from ...calibration.scale_fit import ScaleFit

            s_g = r_align.T @ fit.sensitivity @ r_align
            fit = ScaleFit(s_g, np.linalg.inv(s_g), r_align.T @ fit.bias, fit.sensitivity_sigma, fit.residual_rms)
    table_out = report.ParamTable()
    ts = None if truth is None else truth["sensitivity"]
    table_out.add("scale_factor_ppm", fit.scale_factor_ppm, "ppm",
                  None if ts is None else (np.diag(ts) - 1.0) * 1e6)
    for i, j in OFF_DIAGONAL:         # the cross-axis terms only: the diagonal is the scale-factor row above
        table_out.add(f"misalignment_{'xyz'[i]}{'xyz'[j]}_urad", fit.misalignment_rad[i, j] * 1e6,
                      f"µrad (S_{'xyz'[i]}{'xyz'[j]}: axis {'xyz'[i]} senses rate about {'xyz'[j]})",
                      None if ts is None else ts[i, j] * 1e6)
    table_out.add("bias_dps", fit.bias / DEG, "deg/s", None if truth is None else truth["bias"] / DEG)
    table_out.rows["scale_factor_ppm"]["sigma"] = (np.diag(fit.sensitivity_sigma) * 1e6).tolist()
    extra = {"method": args.method, "residual_rms": fit.residual_rms, "sensitivity": fit.sensitivity,
             "alignment_removed": None if args.alignment is None else str(args.alignment), "attitudes": note}
    checks = None
    if ts is not None:
        sf_err = (np.diag(fit.sensitivity) - np.diag(ts)) * 1e6
        mis_err = (fit.sensitivity - ts - np.diag(np.diag(fit.sensitivity - ts))) * 1e6
        checks = {"scale_factor_ppm": report.check(float(np.abs(sf_err).max()), 200.0, "ppm (worst axis)")}
        extra["misalignment_max_error_urad"] = float(np.abs(mis_err).max())
    cal = calfile.GyroScaleCal(_mat(fit.correction), _mat(fit.sensitivity), tuple(float(v) for v in fit.bias),
                               tuple(float(v) for v in fit.scale_factor_ppm), args.method)
    toml = args.toml or folder / "calibration.toml"
    calfile.write_section(toml, "gyro_scale", cal, source=str(args.input) if args.input else source)
    extra["toml"] = str(toml)
    if not args.no_plots:
        _plot(folder, fit, ts, args.method)
    return report.finish(args, "gyro-scale", table_out, extra, folder, checks)


def _mat(m):
    return tuple(tuple(float(v) for v in row) for row in m)


def residual_text(residual_rms: float, method: str) -> str:
    """The fit's residual RMS with its unit: a rate (rad/s) for a rate table, an angle (rad)
    over each camera interval for slews."""
    if method == "rate-table":
        return f"{residual_rms / DEG:.3g} °/s"
    return f"{residual_rms / DEG * 3600.0:.3g}″"


def _plot(folder, fit, truth, method: str) -> None:
    from ...calibration.report import new_figure, save_figure

    fig, ax = new_figure(figsize=(7, 4.5))
    est = (fit.sensitivity - np.eye(3)).ravel() * 1e6
    x = np.arange(9)
    ax.bar(x - 0.2, est, 0.4, yerr=fit.sensitivity_sigma.ravel() * 1e6, label="estimated")
    if truth is not None:
        ax.bar(x + 0.2, (truth - np.eye(3)).ravel() * 1e6, 0.4, label="simulated truth")
    ax.set_xticks(x, [f"S{i}{j}" for i in "xyz" for j in "xyz"])
    ax.set_ylabel("S − I (ppm / µrad)")
    ax.legend()
    what = "rate per rest" if method == "rate-table" else "angle per camera interval"
    ax.set_title(f"gyro sensitivity matrix, residual RMS {residual_text(fit.residual_rms, method)} ({what})",
                 fontsize=10)
    save_figure(fig, folder / "gyro_scale.png")
