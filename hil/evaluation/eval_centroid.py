"""``gyrostar eval centroid``: paper 000's simulations — fixed window vs gyro window vs EKF.

Runs :func:`gyrostar.hil.evaluation.paper000_sim.run_paper000` (one Mv 5 star on the ``xing2012``
preset, rendered by the simulator) and reports, per method, the per-axis RMS centroid
error (px), the fraction of frames in which the fixed and the gyro window lose the star,
the highest rate each still tracks, the final drift-estimate error and the CRLB.
``--plot PATH`` writes the paper-style figure (rates, per-axis errors A/B/C, drift).
"""

from __future__ import annotations

HELP = "paper 000 centroid simulations sim1..sim4: fixed window, gyro window, EKF"


def configure(parser) -> None:
    from ...cli.argtypes import seed as seed_type
    from ...cli.main import add_json
    from .plot_target import png_file

    parser.add_argument("--scenario", choices=("sim1", "sim2", "sim3", "sim4"), default="sim2",
                        help="paper 000 simulation (default sim2)")
    parser.add_argument("--max-rate-dps", type=float, default=None,
                        help="sim1: rate at the end of the 8 s ramp (°/s, paper: 8)")
    parser.add_argument("--seed", type=seed_type, default=0, help="noise seed")
    parser.add_argument("--plot", metavar="FILE.png", type=png_file, default=None, help="write a PNG figure")
    parser.add_argument("--centroid", choices=("fit", "iwcog", "cog"), default="fit",
                        help="centroid estimator feeding the EKF: smeared-PSF fit (default), weighted CoG, CoG")
    parser.add_argument("--model", choices=("pinhole", "first_order"), default="pinhole",
                        help="EKF spot-motion model (default pinhole)")
    parser.add_argument("--gyro-noise-dps-rthz", type=float, default=None,
                        help="override the gyro white-noise density (°/s/√Hz; xing2012 set: 0.014)")
    parser.add_argument("--window-k", type=int, default=6, help="side of the trajectory squares (px)")
    add_json(parser)


def run(args) -> int:
    from ...cli.output import emit, progress
    from .paper000_sim import Paper000Config, run_paper000

    kw = {}
    if args.gyro_noise_dps_rthz is not None:
        kw["gyro_noise_dps_rthz"] = args.gyro_noise_dps_rthz
    cfg = Paper000Config(scenario=args.scenario, max_rate_dps=args.max_rate_dps, seed=args.seed,
                         centroid=args.centroid, model=args.model, window_k=args.window_k, **kw)
    cfg.validate()
    from ...mocks.trajectory import paper000

    _, n = paper000(cfg.scenario)
    with progress(args, f"eval centroid {cfg.scenario}", n) as advance:
        result = run_paper000(cfg, progress=advance)
    series = result.pop("_series")
    if args.plot:
        plot(result, series, args.plot)
        result["plot"] = args.plot
    emit(args, result, _human(result))
    return 0


def _fmt(v) -> str:
    return "lost" if v != v else f"{v:.3f}"


def after_text(seconds) -> str:
    """'after N s', or 'never' for a convergence that did not happen (nan/None)."""
    return "never" if seconds is None or seconds != seconds else f"after {seconds:g} s"


def _human(r: dict) -> str:
    ax = r["rms_px_axes"]
    lines = [f"paper 000 {r['scenario']}: {r['frames']} frames, peak rate {r['max_rate_dps_profile']:.2f} °/s"]
    for m, label in (("fixed_window", "A fixed window"), ("gyro_window", "B gyro window"), ("ekf", "C EKF")):
        lost = r["lost_fraction"].get(m, r["lost_fraction_ekf"])
        lines.append(f"  {label:15s} RMS x {_fmt(ax[m][0])} y {_fmt(ax[m][1])} px   lost {lost:.1%}   "
                     f"tracks to {r['max_rate_tracked_dps'][m]:.2f} °/s")
    g = r["ekf_gyro_rate_output_rms_px"]
    lines.append(f"  C EKF 400 Hz output just before each image RMS x {_fmt(g[0])} y {_fmt(g[1])} px")
    b = r["bias_error_dps"]
    lines.append(f"  drift error (final) [{b[0]:+.4f}, {b[1]:+.4f}, {b[2]:+.4f}] °/s "
                 f"(true {r['bias_true_dps']}); x,y within 10 % " + after_text(r["bias_xy_within_10pct_after_s"]))
    lines.append(f"  CRLB {r['crlb_px']:.3f} px; EKF / CRLB = {r['ekf_to_crlb']:.2f}")
    return "\n".join(lines)


def plot(result: dict, s: dict, path: str) -> None:
    """Paper-style figure: input rates, x/y error of A, B, C per frame, drift estimate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    n = len(s["acq"])
    k = np.arange(n)
    fig, axs = plt.subplots(5, 1, figsize=(8, 13), sharex=True)
    spf = s["spf"]
    tk = np.arange(s["meas_dps"].shape[0]) / spf
    for i, c in enumerate("xyz"):
        axs[0].plot(tk, s["meas_dps"][:, i], lw=0.4, color=f"C{i}", label=f"ω{c} measured (400 Hz)")
        axs[0].plot(k, s["rate_dps"][:, i], lw=1.0, ls="--", color=f"C{i}")
    axs[0].set_ylabel("rate (°/s), dashed: true")
    axs[0].ticklabel_format(axis="y", useOffset=False)
    axs[0].legend(loc="upper left", fontsize=8)
    axs[0].set_title(f"paper 000 {result['scenario']}: A fixed window, B gyro window, C EKF")
    names = (("fixed_window", "A", "tab:red"), ("gyro_window", "B", "tab:blue"), ("ekf", "C", "k"))
    for ax_i, lab in ((1, "x"), (2, "y")):
        ax = axs[ax_i]
        for m, letter, col in names:
            e = s["err"][m][:, ax_i - 1].copy()
            e[s["lost"][m]] = np.nan
            ax.plot(k, e, ".-" if m == "ekf" else ".", ms=2, lw=0.6, color=col,
                    label=f"{letter} (RMS {result['rms_px_axes'][m][ax_i - 1]:.3f})")
        sig = s["ekf_sigma"][:, ax_i - 1]
        ax.fill_between(k, -sig, sig, color="0.85", label="EKF ±1σ")
        ax.set_ylabel(f"{lab} error (px)")
        ax.set_ylim(-1.0, 1.0)
        ax.legend(loc="upper right", fontsize=7, ncol=4)
    for m, letter, col in names[:2]:
        axs[3].plot(k, s["lost"][m].astype(float) * (1.0 if letter == "A" else 0.5), color=col,
                    label=f"{letter} lost")
    axs[3].set_ylabel("lost")
    axs[3].legend(loc="upper left", fontsize=8)
    for i, c in enumerate("xyz"):
        axs[4].plot(k, s["bias_est"][:, i] * 180 / np.pi, label=f"b{c} est")
        axs[4].axhline(s["drift"][i] * 180 / np.pi, ls="--", lw=0.8, color=f"C{i}")
    axs[4].set_ylabel("drift (°/s)")
    axs[4].set_xlabel("frame (100 Hz)")
    axs[4].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
