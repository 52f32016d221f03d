"""``gyrostar calibrate alignment``: the rotation between gyro and camera frames and the
time offset between gyro samples and exposure mid-times, from slews
(:mod:`gyrostar.calibration.align_fit`).

Input: an ``.npz`` with the gyro log ``t`` (s, gyro time stamps), ``rate`` (N×3 rad/s, gyro
axes) and the tracker's attitudes ``t_cam`` (K,) s (exposure mid-times) and ``q_cam``
(K×4 [x, y, z, w] ICRS → camera), both on the host clock — e.g. from ``gyrostar replay LOG
--export calib``; when that file also holds the identified stars and the target ``--out``
file already has a [camera] table, the attitudes are recomputed through that camera. ``--gyro-cal TOML`` applies a
[gyro_scale] correction first (scale and non-orthogonality are not a rotation).

``--simulate``: the body slews back and forth (one sinusoid per axis, ``--amplitudes``),
the tracker's attitudes come from the simulator's sky (:mod:`.slew_sim`, ``--camera-hz``),
and the simulator's gyro (``--gyro-params``, default ``bmi088`` with its scale and
misalignment errors set to zero, as after ``gyro-scale``) is mounted with a known rotation
and stamped ``--clock-offset-ms`` late. The true time offset is that clock offset minus
the gyro filter's group delay (its reading lags the body rate).

Precision: the gyro's angle random walk N limits the rotation, σ ≈ N / (ω⊥ √T) per axis
(ω⊥ the RMS rate about the other two axes, T the slew length); the time offset needs
angular acceleration, σ ≈ N / (α √T). For the BMI088 (N ≈ 1.7e-4 rad/√s) 20″ needs
ω⊥·√T ≳ 5 rad/√s with margin: the default slews at 20/16/12 °/s for 20 minutes.
"""

from __future__ import annotations

import numpy as np

HELP = "gyro-to-camera rotation and gyro/exposure time offset from slews"
ARCSEC = np.pi / 180.0 / 3600.0
DEFAULT_SET = ["scale_factor_sigma_ppm=0", "misalignment_sigma_mrad=0"]
TRUE_MOUNT_DEG = (0.3, -0.5, 90.2)  # rotation vector of the simulated gyro → camera mounting, degrees


MAX_DURATION_S = 7200.0   # --duration: 2 h of slew (12× the default)
MAX_CAMERA_HZ = 100.0     # --camera-hz: one 10 ms exposure after another (the xing2012 preset)
MAX_RATE_DPS = 2000.0     # --amplitudes: the BMI088's largest range


def configure(parser) -> None:
    from ...calibration.report import add_common_args
    from ...cli.argtypes import existing_file, float_in, float_list_in, int_in
    from .gyro_sim import gyro_param_sets, override

    add_common_args(parser, "slew log .npz: t, rate (gyro) and t_cam, q_cam (tracker)")
    parser.add_argument("--gyro-cal", type=existing_file, default=None,
                        help="calibration TOML whose [gyro_scale] is applied first")
    parser.add_argument("--lag", type=int_in(1, 1000), default=2,
                        help="camera frames per comparison window, 1 to 1000 (default 2)")
    parser.add_argument("--max-offset-ms", type=float_in(0.0, 1000.0, lo_open=True, unit="ms"), default=50.0,
                        help="time-offset search range ±, ms, in (0, 1000] (default 50)")
    parser.add_argument("--gyro-params", default="bmi088", choices=gyro_param_sets(),
                        help="--simulate: gyro error-model parameter set (default bmi088)")
    parser.add_argument("--set", action="append", type=override, default=None, metavar="KEY=VALUE",
                        help="--simulate: gyro parameter override (repeatable; default: "
                             + " ".join(DEFAULT_SET) + ")")
    parser.add_argument("--duration", type=float_in(1.0, MAX_DURATION_S, unit="s"), default=1200.0,
                        help=f"--simulate: slew length, s, 1 to {MAX_DURATION_S:g} (default 1200)")
    parser.add_argument("--camera-hz", type=float_in(0.0, MAX_CAMERA_HZ, lo_open=True, unit="Hz"), default=10.0,
                        help=f"--simulate: attitude rate, Hz, at most {MAX_CAMERA_HZ:g} (one 10 ms exposure after "
                             "another; default 10)")
    parser.add_argument("--amplitudes", type=float_list_in(0.0, MAX_RATE_DPS, lo_open=True, counts=(1, 3),
                                                           unit="deg/s"),
                        default=[20.0, 16.0, 12.0],
                        help=f"--simulate: slew rate amplitudes, deg/s, one for all axes or x,y,z, each in "
                             f"(0, {MAX_RATE_DPS:g}] (default 20,16,12)")
    parser.add_argument("--clock-offset-ms", type=float_in(-1000.0, 1000.0, unit="ms"), default=2.5,
                        help="--simulate: gyro stamp lateness, ms, within ±1000 (default 2.5)")


def mount_rotation() -> np.ndarray:
    """The simulated gyro → camera rotation (from :data:`TRUE_MOUNT_DEG`)."""
    from ...calibration.intrinsics import rotvec_dcm

    return rotvec_dcm(np.radians(np.array([TRUE_MOUNT_DEG])))[0]


def gyro_arw(cal) -> tuple[float, str]:
    """The gyro's angle random walk N (rad/√s) for the precision limit: the calibration
    file's [gyro_static] (mean of the axes) when it has one, else the BMI088 datasheet value
    the loop uses."""
    if cal is not None and cal.gyro_static is not None:
        return float(np.mean(cal.gyro_static.arw_rad_per_sqrt_s)), "[gyro_static]"
    from ...loop.coupled import LoopParams

    return float(LoopParams.gyro_arw), "BMI088 datasheet (0.014 °/s/√Hz)"


def simulate(args):
    """(t_g, rate, t_cam, q_cam, truth) of a simulated slew."""
    from ...cli.output import progress
    from . import gyro_sim
    from .slew_sim import simulate_attitudes, slew_profile

    p = gyro_sim.params(args.gyro_params, DEFAULT_SET if args.set is None else args.set)
    gyro_sim.check_length(p, args.duration, "--duration")
    n_frames = int(args.duration * args.camera_hz)
    need = 13 * args.lag + 3                # fit_alignment: at least 12 windows of --lag frames
    if n_frames < need:
        from ...errors import ConfigError

        raise ConfigError(f"--duration {args.duration:g} s at --camera-hz {args.camera_hz:g} gives {n_frames} "
                          f"attitudes; --lag {args.lag} needs at least {need}")
    profile = slew_profile(args.amplitudes)
    with progress(args, "simulating tracker attitudes", n_frames) as step:
        sl = simulate_attitudes(args.duration, args.camera_hz, args.seed, profile=profile, progress_step=step)
    r_true = mount_rotation()
    t, rate, gt = gyro_sim.measure_profile(profile, args.duration, p, args.seed, body_to_sensor=r_true.T)
    clock = args.clock_offset_ms * 1e-3
    t_g = t - clock
    truth = {"rotation": r_true, "time_offset_s": clock - gt["delay_s"], "bias": gt["bias"],
             "filter_delay_s": gt["delay_s"], "arw": gt["arw"]}
    return t_g, rate, sl.t_cam, sl.q_cam, truth


def run(args) -> int:
    from pathlib import Path

    from ...calibration import calfile, report
    from ...calibration.align_fit import fit_alignment, rotation_angle
    from ...errors import ConfigError

    source = report.check_source(args)
    gs = None
    if args.gyro_cal:                      # checked before anything is simulated or loaded
        gs = calfile.load(args.gyro_cal).gyro_scale
        if gs is None:
            raise ConfigError(f"--gyro-cal {args.gyro_cal} has no [gyro_scale] table")
    folder = report.report_dir(args, "alignment")
    truth = None
    extra_in = {}
    target = None
    if source == "simulate":
        t_g, rate, t_cam, q_cam, truth = simulate(args)
    else:
        from ...calibration.star_fields import load_slew_input

        target = calfile.load(args.toml) if args.toml and Path(args.toml).exists() else None
        t_g, rate, t_cam, q_cam, extra_in["attitudes"] = load_slew_input(args.input, target)
    if gs is not None:
        rate = (np.asarray(rate) - np.asarray(gs.bias_rps)) @ np.asarray(gs.correction).T
    arw, arw_from = gyro_arw(target)
    fit = fit_alignment(t_g, rate, t_cam, q_cam, lag=args.lag, max_offset=args.max_offset_ms * 1e-3, arw=arw)
    table = report.ParamTable()
    q = fit.quaternion
    extra = {"n_windows": fit.n_windows, "coarse_offset_ms": fit.coarse_offset * 1e3,
             "residual_rms_arcsec": fit.residual_rms / ARCSEC, "rotation_matrix": fit.rotation, **extra_in}
    checks = None
    if truth is None:
        table.add("q_gyro_to_camera", q, "[x, y, z, w]")
        table.add("time_offset_ms", fit.time_offset * 1e3, "ms")
    else:
        from ...attitude import dcm_to_quat

        qt = dcm_to_quat(np.ascontiguousarray(truth["rotation"]))
        if np.dot(q, qt) < 0:
            qt = -qt
        ang = rotation_angle(fit.rotation, truth["rotation"]) / ARCSEC
        table.add("q_gyro_to_camera", q, "[x, y, z, w]", qt)
        table.add("alignment_error_arcsec", ang, "arcsec (angle of R_est R_trueᵀ)", 0.0)
        table.add("time_offset_ms", fit.time_offset * 1e3, "ms", truth["time_offset_s"] * 1e3)
        table.add("gyro_bias_dps", np.degrees(fit.bias), "deg/s", np.degrees(truth["bias"]))
        extra["filter_delay_ms"] = truth["filter_delay_s"] * 1e3
        checks = {"alignment_arcsec": report.check(ang, 20.0, "arcsec"),
                  "time_offset_ms": report.check((fit.time_offset - truth["time_offset_s"]) * 1e3, 0.5, "ms")}
    table.rows["q_gyro_to_camera"]["sigma_arcsec"] = (fit.rotation_sigma / ARCSEC).tolist()
    # what this slew allows at all: the same fit with a noiseless camera (the gyro's ARW alone)
    table.rows["q_gyro_to_camera"]["sigma_gyro_limit_arcsec"] = (fit.rotation_sigma_gyro / ARCSEC).tolist()
    extra["gyro_arw_rad_per_sqrt_s"] = arw
    extra["gyro_arw_from"] = arw_from
    table.rows["time_offset_ms"]["sigma"] = fit.time_offset_sigma * 1e3
    cal = calfile.AlignmentCal(tuple(float(v) for v in q), float(fit.time_offset),
                               float(np.sqrt(np.mean(fit.residual_rms**2)) / ARCSEC))
    toml = args.toml or folder / "calibration.toml"
    calfile.write_section(toml, "alignment", cal, source=str(args.input) if args.input else source)
    extra["toml"] = str(toml)
    if not args.no_plots:
        _plot(folder, t_g, rate, t_cam, q_cam, fit)
    return report.finish(args, "alignment", table, extra, folder, checks)


def _plot(folder, t_g, rate, t_cam, q_cam, fit) -> None:
    from ...calibration.gyro_integral import GyroIntegral
    from ...calibration.report import new_figure, save_figure
    from ...calibration.scale_fit import attitude_increments

    gi = GyroIntegral(t_g, rate)
    sel = (t_cam - 0.1 > gi.t[0]) & (t_cam + 0.1 < gi.t[-1])
    tc, qc = t_cam[sel], q_cam[sel]
    n = min(len(tc) - 1, 600)
    phi = attitude_increments(qc[: n + 1])
    dt = np.diff(tc[: n + 1])
    cam = phi / dt[:, None]
    mid = 0.5 * (tc[1: n + 1] + tc[:n])
    g = (gi.at(tc[1: n + 1] - fit.time_offset) - gi.at(tc[:n] - fit.time_offset)) / dt[:, None] - fit.bias
    gyro_cam = g @ fit.rotation.T
    fig, axes = new_figure(2, 1, figsize=(11, 7), sharex=True)
    for k in range(3):
        axes[0].plot(mid, np.degrees(cam[:, k]), ".", ms=2, label=f"camera ω{'xyz'[k]}")
        axes[0].plot(mid, np.degrees(gyro_cam[:, k]), "-", lw=0.8, label=f"gyro → camera ω{'xyz'[k]}")
        axes[1].plot(mid, np.degrees(cam[:, k] - gyro_cam[:, k]) * 3600, ".", ms=2, label="xyz"[k])
    axes[0].set_ylabel("rate (°/s)")
    axes[0].legend(fontsize=7, ncol=3)
    axes[1].set_ylabel("camera − aligned gyro (″/s)")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(fontsize=7)
    axes[0].set_title(f"alignment: δt = {fit.time_offset * 1e3:.3f} ms")
    save_figure(fig, folder / "alignment_rates.png")
