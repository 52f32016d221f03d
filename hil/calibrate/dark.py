"""``gyrostar calibrate dark``: dark-current map, hot pixels and read noise from dark frames
at several exposures (:mod:`gyrostar.calibration.dark_frames`), saved as FITS.

Input: a folder of FITS dark frames (``EXPTIME`` header, s) or an ``.npz`` with
``frames`` (M, H, W) DN and ``exposure`` (M,) s. The calibration TOML gets the FITS path,
the read noise and the hot-pixel list (the driver masks them in centroiding; the
firmware can be told to skip them).

``--live``: the camera head on ``--port`` (lens capped) is set to each exposure, and for
every frame a CAPTURE is followed by a FULL_FRAME read of the light plane
(:class:`gyrostar.head.HeadClient`); the frames are saved in the report folder
(``dark_frames.npz``) before they are reduced.

``--simulate``: the simulator's detector (:class:`gyrostar.mocks.sky.Sky` with an empty
sky, lens capped) of the ``--preset`` renders ``--frames`` dark frames at each of the
``--exposures``; truth is its fixed pattern (dark rate, hot pixels) and read noise. The
default exposures keep hot pixels below ADC saturation (10-bit, 5 e⁻/DN).
"""

from __future__ import annotations

import numpy as np

HELP = "dark frames at several exposures -> dark-current map, hot pixels, read noise (FITS)"


MAX_EXPOSURE_S = 100.0    # --exposures: the simulator's detector limit
MAX_FRAMES = 64           # --frames: per exposure (8 exposures × 64 frames of 1024² px: ≈ 1.5 min, 2.2 GB peak)


def configure(parser) -> None:
    from ...calibration.report import add_common_args
    from ...cli.argtypes import float_in, float_list_in, int_in

    add_common_args(parser, "folder of FITS dark frames (EXPTIME header) or .npz (frames, exposure)", live=True)
    parser.add_argument("--preset", default="xing2012", help="--simulate: simulator preset (default xing2012)")
    parser.add_argument("--exposures", type=float_list_in(0.0, MAX_EXPOSURE_S, lo_open=True, max_count=8, unit="s"),
                        default=[0.005, 0.03, 0.055, 0.08],
                        help=f"--simulate: exposure times, s, comma separated, at most 8, each in "
                             f"(0, {MAX_EXPOSURE_S:g}]")
    parser.add_argument("--frames", type=int_in(2, MAX_FRAMES), default=8,
                        help=f"--simulate: frames per exposure, 2 to {MAX_FRAMES} (default 8)")
    parser.add_argument("--k-sigma", type=float_in(1.0, 1e6), default=8.0,
                        help="hot pixel: dark current above median + K robust sigma, K ≥ 1 (default 8)")
    parser.add_argument("--hot-factor", type=float_in(0.0, 1e6), default=5.0,
                        help="hot pixel: and above this multiple of the median dark current, ≥ 0 (default 5)")
    parser.add_argument("--temperature", type=float_in(-100.0, 150.0, unit="C"), default=None,
                        help="sensor temperature, C, -100 to 150 (recorded)")
    parser.add_argument("--port", default=None, help="--live: camera-head serial port or pyserial URL")
    parser.add_argument("--head-timeout", type=float_in(0.0, 60.0, lo_open=True, unit="s"), default=2.0,
                        help="--live: seconds to wait for each head reply before a retry, at most 60 (default 2)")


def capture_stacks(client, exposures: list[float], n_frames: int, step=None, keep: dict | None = None):
    """Dark stacks from a live head: per exposure (s) ``n_frames`` CAPTURE + FULL_FRAME reads
    (a one-pixel window is set, since the head exposes only with windows defined).
    The raw frames go into ``keep`` (``frames``, ``exposure``) when given."""
    from ...calibration.dark_frames import stack
    from ...errors import DeviceError

    stacks = []
    client.set_windows(np.array([[0, 0, 0, 1]], np.int32))  # a CAPTURE needs a window; the frame is read whole
    for t_exp in exposures:
        got = client.set_exposure(int(round(t_exp * 1e6)))
        t_real = got * 1e-6 if got else t_exp
        frames, seen = [], set()
        for _ in range(n_frames):
            client.capture(fetch=False)
            img, sensor_frame = client.full_frame()
            if sensor_frame in seen:
                raise DeviceError(f"dark capture: sensor frame {sensor_frame} read twice")
            seen.add(sensor_frame)
            frames.append(img)
            if step is not None:
                step()
        if keep is not None:
            keep.setdefault("frames", []).extend(frames)
            keep.setdefault("exposure", []).extend([t_real] * len(frames))
        stacks.append(stack(np.stack(frames), t_real))
    return stacks


def simulate(args):
    """Dark stacks rendered by the simulator, and the truth (rate DN/s map, hot mask, read noise DN)."""
    import dataclasses

    from ...calibration.dark_frames import stack
    from ...catalog import StarCatalog
    from ...cli.output import progress
    from ...mocks.sim_preset import load_preset
    from ...mocks.sky import Sky

    exposures = list(args.exposures)
    base = load_preset(args.preset)
    empty = StarCatalog("none", np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), 2025.0)
    stacks = []
    q = np.array([0.0, 0.0, 0.0, 1.0])
    with progress(args, "rendering dark frames", len(exposures) * args.frames) as step:
        for e, t_exp in enumerate(exposures):
            preset = dataclasses.replace(
                base, detector=dataclasses.replace(base.detector, exposure_s=t_exp),
                photometry=dataclasses.replace(base.photometry, sky_mag_arcsec2=60.0))
            sky = Sky(empty, preset, seed=args.seed)
            frames = []
            for k in range(args.frames):
                img, _ = sky.render_frame(q, frame=1000 * e + k)
                frames.append(img)
                step()
            stacks.append(stack(np.stack(frames), t_exp))
    det = base.detector
    _, dark_e = sky.fixed_pattern
    rate_true = dark_e.astype(np.float64) / preset.detector.exposure_s / det.gain_e_per_adu
    hot_true = np.isclose(dark_e / preset.detector.exposure_s, det.hot_pixel_dark_e_s, rtol=1e-4)
    return stacks, {"rate": rate_true, "hot": hot_true, "read_noise": det.read_noise_e / det.gain_e_per_adu,
                    "offset": det.bias_adu}


def run(args) -> int:
    from ...calibration import calfile, report
    from ...calibration.dark_frames import load_frames, solve, write_fits

    source = report.check_source(args)
    folder = report.report_dir(args, "dark")
    truth = None
    if source == "simulate":
        stacks, truth = simulate(args)
    elif source == "live":
        stacks = _live(args, folder)
    else:
        stacks = load_frames(args.input)
    res = solve(stacks, k_sigma=args.k_sigma, hot_factor=args.hot_factor)
    # ADC quantisation (1/12 DN²) is part of the measured temporal noise, not of the read noise
    read_noise = float(np.sqrt(max(res.read_noise**2 - 1.0 / 12.0, 0.0)))
    fits_path = write_fits(folder / "dark.fits", res, args.temperature)
    table = report.ParamTable()
    extra = {"exposures_s": res.exposures, "frames": res.frames, "fits": str(fits_path),
             "n_hot": int(len(res.hot))}
    checks = None
    if truth is None:
        table.add("read_noise_dn", read_noise, "DN")
        table.add("dark_current_median_dn_per_s", res.rate_median, "DN/s")
        table.add("hot_pixels", len(res.hot), "count")
    else:
        normal = ~truth["hot"]
        table.add("read_noise_dn", read_noise, "DN", truth["read_noise"])
        table.add("dark_current_median_dn_per_s", res.rate_median, "DN/s", float(np.median(truth["rate"])))
        map_err = float(np.sqrt(np.mean((res.rate - truth["rate"])[normal] ** 2)))
        table.add("dark_current_map_rms_error_dn_per_s", map_err, "DN/s (normal pixels)", 0.0)
        table.add("offset_median_dn", float(np.median(res.offset)), "DN", truth["offset"])
        found = np.zeros_like(truth["hot"])
        found[res.hot[:, 1], res.hot[:, 0]] = True
        table.add("hot_pixels", int(found.sum()), "count", int(truth["hot"].sum()))
        hot = truth["hot"]
        rel = (res.rate[hot] - truth["rate"][hot]) / truth["rate"][hot]
        table.add("hot_pixel_rate_rel_error_rms", float(np.sqrt(np.mean(rel**2))) if hot.any() else 0.0, "1", 0.0)
        extra["hot_missed"] = int((truth["hot"] & ~found).sum())
        extra["hot_false"] = int((found & ~truth["hot"]).sum())
        checks = {"read_noise_rel": report.check(read_noise / truth["read_noise"] - 1.0, 0.05, "(5 %)"),
                  "hot_missed": report.check(extra["hot_missed"], 0, "pixels"),
                  "hot_false": report.check(extra["hot_false"], 0, "pixels")}
    cal = calfile.DarkCal(str(fits_path), read_noise, res.rate_median, float(np.median(res.offset)),
                          [(int(c), int(r)) for c, r in res.hot], args.temperature)
    toml = args.toml or folder / "calibration.toml"
    calfile.write_section(toml, "dark", cal, source=str(args.input) if args.input else source)
    extra["toml"] = str(toml)
    if not args.no_plots:
        _plots(folder, res)
    return report.finish(args, "dark", table, extra, folder, checks)


def _live(args, folder):
    from ...cli.output import progress
    from ...errors import ConfigError
    from ...head import HeadClient
    from ...transport.serial_link import SerialLink

    if not args.port:
        raise ConfigError("--live needs --port (the camera head's serial port or URL)")
    exposures = list(args.exposures)
    keep: dict = {}
    with SerialLink(args.port) as link, progress(args, "capturing dark frames", len(exposures) * args.frames) as step:
        stacks = capture_stacks(HeadClient(link, timeout=args.head_timeout), exposures, args.frames, step, keep)
    np.savez_compressed(folder / "dark_frames.npz", frames=np.stack(keep["frames"]),
                        exposure=np.asarray(keep["exposure"]))
    return stacks


def _plots(folder, res) -> None:
    from ...calibration.report import new_figure, save_figure

    fig, axes = new_figure(1, 2, figsize=(12, 5))
    lo, hi = np.percentile(res.rate, [1, 99])
    im = axes[0].imshow(res.rate, vmin=lo, vmax=hi, cmap="magma", origin="upper")
    axes[0].plot(res.hot[:, 0], res.hot[:, 1], "o", mfc="none", mec="cyan", ms=6, label="hot")
    axes[0].set_title(f"dark current, {len(res.hot)} hot pixels circled", fontsize=10)
    axes[0].set_xlabel("column (px)")
    axes[0].set_ylabel("row (px)")
    axes[0].legend(loc="upper right")
    fig.colorbar(im, ax=axes[0], label="dark current (DN/s)")
    axes[1].set_title("dark current of every pixel", fontsize=10)
    axes[1].hist(res.rate.ravel(), bins=200, log=True)
    axes[1].axvline(res.hot_threshold, color="r", label=f"hot threshold {res.hot_threshold:.0f} DN/s")
    axes[1].set_xlabel("dark current (DN/s)")
    axes[1].set_ylabel("pixels")
    axes[1].legend()
    save_figure(fig, folder / "dark_current.png")
