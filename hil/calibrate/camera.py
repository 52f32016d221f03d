"""``gyrostar calibrate camera``: focal length, principal point and Brown–Conrady
distortion from many identified star fields (robust bundle least squares,
:mod:`gyrostar.calibration.intrinsics`).

Input: a table of identified stars, ``.npz`` with ``field`` (N,), ``uv`` (N, 2) px
[column, row] and ``ref`` (N, 3) ICRS unit vectors (what ``gyrostar replay LOG --export calib``
writes from a flatsat run), or a CSV with the header
``field,u,v,ra_deg,dec_deg``. The nominal camera (start point, sensor size) is a
``gyrostar.camera`` preset (``--camera``).

``--images PATH...``: real sky frames (files or folders, any format ``gyrostar solve`` reads).
Each is solved with no field-of-view hint (:mod:`gyrostar.starid.lost_in_space`, the
``--fov-range`` searched); the matched stars' centroids (the real-frame detector's, without
saturated or border-cut spots) and catalog directions form the table. The nominal camera is the
median of the per-image solutions (focal length, k1; principal point at the sensor's centre),
and the fit frees f, cx, cy and k1 (``--fix`` to change).

``--simulate``: random attitudes; the simulator's sky (:class:`gyrostar.mocks.sky.Sky`,
Hipparcos to ``--mag-limit``) seen through the preset camera with an injected principal
point offset and distortion gives the true centroids; Gaussian centroid noise
(``--centroid-noise`` px per axis, the error of a centroid averaged over a few frames)
and a fraction of misidentified stars (``--outliers``) are added.

Principal-point precision: in a narrow field a principal-point shift is almost a pure
attitude change; it is seen only through the second-order perspective term (≈ δc·x²,
x ≤ tan(half field)), so σ(c) ≈ σ_centroid / (⟨x²⟩ √N_stars): 0.5 px needs tens of
thousands of star observations at 0.02 px for the 8.8° xing2012 camera. When the table names
each observation's star (``star_id``, as ``--export calib`` writes), the reported σ treats a
star's observations as one cluster (a tracked star keeps its own centroid error from field to
field: fixed pattern, pixel phase), so it counts the stars, not the observations; the σ as if
every observation were independent is reported beside it (``sigma_iid``). When the table gives
each centroid's σ (``uv_sigma``, the CRLB of the smeared-PSF fit, as ``--export calib``
writes) each observation is weighted by it, with a floor per observation and one per star
position (:func:`gyrostar.calibration.intrinsics.fit`): a V 3 star's centroid is ten times
as precise as a V 6.3 one's, and a star held at one pixel through a rest of a hundred frames
keeps most of its error in all of them. The file's [camera] keeps the principal point's 1σ
(``principal_point_sigma_px``): a run reports the pointing bias it implies (σ/f) beside its
covariance.
"""

from __future__ import annotations

import numpy as np

HELP = "camera intrinsics (focal length, principal point, Brown-Conrady) from identified star fields"

TRUE_OFFSETS = {"dcx_px": 3.2, "dcy_px": -2.1, "f_scale": 1.0008, "k1": 0.3, "k2": 4.0, "k3": 0.0,
                "p1": 2.0e-4, "p2": -1.0e-4}


# the largest displacement (px, at the sensor corner) each distortion term of a narrow-field
# star camera plausibly makes: k1 a few px (the simulated truth: 2.6 px), the higher orders and the
# tangential terms well under one; a fit beyond these by more than PLAUSIBLE_SIGMA of its σ is wrong
PLAUSIBLE_CORNER_PX = {"k1": 50.0, "k2": 5.0, "k3": 5.0, "p1": 5.0, "p2": 5.0}
PLAUSIBLE_SIGMA = 3.0
TRUTH_SIGMA = 5.0         # --simulate: every fitted parameter within this many of its σ of the truth

MAX_FIELDS = 20000        # --fields: 20000 simulate and fit in ≈ 3.5 min, 0.8 GB peak (10× the default)
MAX_OUTLIER_FRACTION = 0.5  # --outliers: the fit's median-based σ and rejection break down at half the stars


def fix_names(text: str) -> str:
    """argparse type of ``--fix``: comma-separated names of :data:`~gyrostar.calibration.intrinsics.NAMES`
    (or '' for none), checked at parse time."""
    import argparse

    from ...calibration.intrinsics import NAMES

    unknown = sorted({n.strip() for n in text.split(",") if n.strip()} - set(NAMES))
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown parameter(s) {unknown} (known: {', '.join(NAMES)})")
    return text


def configure(parser) -> None:
    from ...calibration.report import add_common_args
    from ...cli.argtypes import float_in, int_in

    add_common_args(parser, "identified-star table (.npz: field, uv, ref; or .csv: field,u,v,ra_deg,dec_deg)")
    parser.add_argument("--camera", default="xing2012", help="nominal camera preset (default xing2012)")
    parser.add_argument("--fix", type=fix_names, default=None, metavar="NAMES",
                        help="parameters held at their nominal value; default k3,p1,p2 for an INPUT file (in a "
                             "narrow field the tangential terms trade with the principal point), none with "
                             "--simulate (its camera has tangential terms); '' fits all of "
                             "f_px,cx_px,cy_px,k1,k2,k3,p1,p2")
    parser.add_argument("--images", nargs="+", default=None, metavar="PATH",
                        help="real night-sky frames (files or folders): solved with no field-of-view hint, their "
                             "matched stars are the table (the fit frees f_px,cx_px,cy_px,k1 unless --fix)")
    parser.add_argument("--fov-range", type=_fov_range_arg, default=(5.0, 30.0), metavar="MIN,MAX",
                        help="--images: horizontal fields of view searched (deg, default 5,30)")
    parser.add_argument("--fields", type=int_in(1, MAX_FIELDS), default=2000,
                        help=f"--simulate: star fields, 1 to {MAX_FIELDS} (default 2000)")
    parser.add_argument("--mag-limit", type=float_in(3.0, 12.0), default=7.0,
                        help="--simulate: faintest V used, 3 to 12 (default 7.0)")
    parser.add_argument("--centroid-noise", type=float_in(0.0, 1.0, unit="px"), default=0.02,
                        help="--simulate: centroid noise per axis, px, 0 to 1 (default 0.02)")
    parser.add_argument("--outliers", type=float_in(0.0, MAX_OUTLIER_FRACTION, hi_open=True), default=0.01,
                        help="--simulate: fraction of misidentified stars, in [0, 0.5): the fit's median-based "
                             "rejection needs most stars right (default 0.01)")


def _fov_range_arg(text: str):
    from ...cli.solve import _fov_range

    return _fov_range(text)



def images_table(args):
    """``(StarFields, nominal CameraModel, per-image list)`` from real frames (``--images``)."""
    from ...calibration.intrinsics import StarFields
    from ...camera import CameraModel
    from ...catalog import load_catalog
    from ...cli.output import progress
    from ...errors import ConfigError
    from ...imaging.detect import FLAG_EDGE, FLAG_SATURATED
    from ...imaging.plate import solve_frame
    from ...imaging.read import expand_paths, read_frames
    from ...starid.lost_in_space import LostInSpace

    files = expand_paths(args.images)
    cat = load_catalog("hip2", 10.0)
    index = {int(i): k for k, i in enumerate(cat.ids)}
    solvers: dict = {}
    fl, uvl, refl, starl, per_image = [], [], [], [], []
    size = None
    with progress(args, "solving images", len(files)) as step:
        for f in files:
            for frame in read_frames(f):
                if size is None:
                    size = (frame.width, frame.height)
                elif (frame.width, frame.height) != size:
                    raise ConfigError(f"--images: {frame.name} is {frame.width}x{frame.height} px, the first image "
                                      f"{size[0]}x{size[1]}: one camera's frames only")
                key = size
                if key not in solvers:
                    solvers[key] = LostInSpace.for_sensor(*size, fov_range_deg=args.fov_range,
                                                          mag_limit=None, quiet=True)
                res = solve_frame(frame, solvers[key])
                sol = res.solution
                info = {"file": frame.name, "solved": bool(sol.solved), "status": sol.status}
                if sol.solved:
                    flags = res.detection.flags[res.rows]
                    ok = (sol.match >= 0) & ((flags & (FLAG_SATURATED | FLAG_EDGE)) == 0)
                    rows = [index[int(c)] for c in sol.match[ok]]
                    info.update(focal_length_px=float(sol.focal_length_px), k1=float(sol.k1), stars=int(ok.sum()))
                    if ok.sum() >= 3:
                        fl.append(np.full(ok.sum(), len(fl)))
                        uvl.append(res.xy[ok])
                        refl.append(cat.vectors[rows])
                        starl.append(sol.match[ok])
                per_image.append(info)
            step()
    solved = [p for p in per_image if p["solved"]]
    if not fl:
        raise ConfigError(f"--images: none of the {len(per_image)} images was solved "
                          f"({'; '.join(sorted({p['status'] for p in per_image}))})")
    f0 = float(np.median([p["focal_length_px"] for p in solved]))
    k1 = float(np.median([p["k1"] for p in solved]))
    w, h = size
    pitch = 1e-5
    nominal = CameraModel(f0 * pitch, pitch, w, h, (w - 1) / 2.0, (h - 1) / 2.0, k1)
    stars = StarFields(np.concatenate(fl), np.concatenate(uvl), np.concatenate(refl), star=np.concatenate(starl))
    return stars, nominal, per_image


def load_table(path):
    """StarFields from an .npz or CSV table (see the module docstring)."""
    from pathlib import Path

    from ...attitude import radec_to_vec
    from ...calibration.intrinsics import StarFields
    from ...errors import ConfigError

    path = Path(path)
    if path.suffix == ".npz":
        from ...calibration.report import read_npz

        z = read_npz(path, ("field", "uv", "ref"))
        star = z.get("star_id")            # --export calib names each observation's star
        sigma = z.get("uv_sigma")          # ... and gives each centroid's σ (the fit's weights)
        for name, col in (("star_id", star), ("uv_sigma", sigma)):
            if col is not None and col.shape != z["field"].shape:
                raise ConfigError(f"INPUT {path}: {name} has shape {col.shape}, field {z['field'].shape}: "
                                  "one per observation")
        try:
            return StarFields(z["field"], z["uv"], z["ref"], star=star, sigma=sigma)
        except ConfigError as exc:
            raise ConfigError(f"INPUT {path}: {exc}") from None
    if path.suffix == ".csv":
        from ...files import check_regular

        check_regular(path, "INPUT")        # a FIFO or a device named *.csv: refused, never read
        try:
            tab = np.genfromtxt(path, delimiter=",", names=True)
        except ValueError as exc:
            raise ConfigError(f"{path}: not a readable CSV table: {exc}") from exc
        need = ("field", "u", "v", "ra_deg", "dec_deg")
        if tab.dtype.names is None or any(n not in tab.dtype.names for n in need):
            raise ConfigError(f"INPUT {path}: CSV header must hold {','.join(need)}")
        tab = np.atleast_1d(tab)
        if len(tab) == 0:
            raise ConfigError(f"INPUT {path}: CSV table has no rows")
        for name in need:
            bad = np.flatnonzero(~np.isfinite(tab[name]))
            if len(bad):
                raise ConfigError(f"INPUT {path}: line {bad[0] + 2}, column '{name}' is not a number")
        ref = np.array([radec_to_vec(np.radians(a), np.radians(d)) for a, d in zip(tab["ra_deg"], tab["dec_deg"])])
        return StarFields(tab["field"].astype(np.int64), np.column_stack([tab["u"], tab["v"]]), ref)
    raise ConfigError(f"camera input must be .npz or .csv, got {path}")


def true_camera(nominal):
    """The simulated 'real' camera: the nominal preset with :data:`TRUE_OFFSETS` applied."""
    import dataclasses

    o = TRUE_OFFSETS
    return dataclasses.replace(nominal, focal_length_m=nominal.focal_length_m * o["f_scale"],
                               cx_px=nominal.cx_px + o["dcx_px"], cy_px=nominal.cy_px + o["dcy_px"],
                               k1=o["k1"], k2=o["k2"], k3=o["k3"], p1=o["p1"], p2=o["p2"])


def simulate(args, nominal):
    """Identified-star table from the simulator's sky through the 'real' camera."""
    import dataclasses

    from ...calibration.intrinsics import StarFields
    from ...catalog import load_catalog
    from ...cli.output import progress
    from ...mocks.sim_preset import load_preset
    from ...mocks.sky import Sky
    from ...mocks.trajectory import random_attitudes

    rng = np.random.default_rng(args.seed)
    cam = true_camera(nominal)
    preset = dataclasses.replace(load_preset(args.camera), camera=cam)
    cat = load_catalog("hip2", args.mag_limit)
    sky = Sky(cat, preset, seed=args.seed)
    index = {int(i): k for k, i in enumerate(cat.ids)}
    fl, uvl, refl = [], [], []
    qs = random_attitudes(args.fields, rng)
    with progress(args, "simulating star fields", args.fields) as step:
        for q in qs:
            truth = sky.expose(q).truth
            sel = truth.in_field & (truth.vmag <= args.mag_limit)
            if sel.sum() >= 4:
                fl.append(np.full(sel.sum(), len(fl)))
                uvl.append(truth.uv[sel])
                refl.append(cat.vectors[[index[int(i)] for i in truth.ids[sel]]])
            step()
    if not fl:
        from ...errors import ConfigError

        raise ConfigError(f"--mag-limit {args.mag_limit:g}: none of the {args.fields} --fields holds 4 stars; "
                          "give a fainter limit or more fields")
    field, uv_true, ref = np.concatenate(fl), np.concatenate(uvl), np.concatenate(refl)
    uv = uv_true + args.centroid_noise * rng.standard_normal(uv_true.shape)
    bad = rng.random(len(uv)) < args.outliers  # misidentified: the centroid of another star
    uv[bad] = uv[rng.permutation(np.flatnonzero(bad))] if bad.sum() > 1 else uv[bad]
    bad &= np.linalg.norm(uv - uv_true, axis=1) > 1.0
    return StarFields(field, uv, ref), cam, bad


def corner_px(name: str, value: float, f_px: float, r_corner: float) -> float:
    """Displacement (px) a distortion term ``name`` of size ``value`` makes at the normalised
    radius ``r_corner`` (the sensor corner) of a camera of focal length ``f_px``."""
    power = {"k1": 3, "k2": 5, "k3": 7, "p1": 2, "p2": 2}[name]
    return abs(value) * f_px * r_corner ** power * (3.0 if name in ("p1", "p2") else 1.0)


def implausible(theta, sigma, free, f_px: float, r_corner: float) -> dict:
    """The free distortion terms whose corner displacement lies beyond :data:`PLAUSIBLE_CORNER_PX`
    by more than :data:`PLAUSIBLE_SIGMA` of its σ: ``{name: (px, σ px)}``."""
    from ...calibration.intrinsics import NAMES

    out = {}
    for name, bound in PLAUSIBLE_CORNER_PX.items():
        i = NAMES.index(name)
        if free[i]:
            px, spx = corner_px(name, theta[i], f_px, r_corner), corner_px(name, sigma[i], f_px, r_corner)
            if px - bound > PLAUSIBLE_SIGMA * spx:
                out[name] = (px, spx)
    return out


def run(args) -> int:
    from ...calibration import calfile, report
    from ...calibration.intrinsics import NAMES, fit, model_difference
    from ...camera import camera_preset
    from ...errors import ConfigError

    per_image = None
    if args.images:
        if args.input is not None or args.simulate:
            raise ConfigError("--images replaces INPUT and --simulate: give one of them")
        source = "images"
        stars, nominal, per_image = images_table(args)
    else:
        source = report.check_source(args)
        nominal = camera_preset(args.camera)
    w, h = nominal.width_px, nominal.height_px
    truth_cam, bad = None, None
    if source == "simulate":
        stars, truth_cam, bad = simulate(args, nominal)
    elif source == "file":
        stars = load_table(args.input)
    theta0 = nominal.as_array()[:8]
    r_corner = np.hypot(w, h) / 2.0 / nominal.focal_length_px
    f0 = nominal.focal_length_px
    before = fit(stars, theta0, free=np.zeros(8, bool), reject_k=5.0)
    default_fix = {"simulate": "", "images": "k2,k3,p1,p2"}.get(source, "k3,p1,p2")
    fix = args.fix if args.fix is not None else default_fix
    fixed = {n.strip() for n in fix.split(",") if n.strip()}     # names checked at parse time (fix_names)
    free = np.array([n not in fixed for n in NAMES])
    res = fit(stars, theta0, free=free, prior_k2=1.0 / (f0 * r_corner**5), prior_k3=1.0 / (f0 * r_corner**7))
    params = res.params(w, h)
    folder = report.report_dir(args, "camera")
    table = report.ParamTable()
    tvec = truth_cam.as_array() if truth_cam is not None else None
    units = {"f_px": "px", "cx_px": "px", "cy_px": "px"}
    for i, name in enumerate(NAMES):
        table.add(name, res.theta[i], units.get(name, "1"), None if tvec is None else tvec[i])
        table.rows[name]["sigma"] = float(res.sigma[i])
    extra = {"sigma_basis": (f"per star ({len(np.unique(stars.star))} stars; their observations' errors "
                             "correlated)") if stars.star is not None else "independent observations",
             "sigma_iid": {n: float(res.sigma_iid[i]) for i, n in enumerate(NAMES)},
             "weights": ("each centroid's σ (CRLB) with floors per observation and per star position"
                         if stars.sigma is not None else "uniform (the table gives no centroid σ)"),
             "fixed": sorted(fixed), "n_fields": int(stars.n_fields), "n_stars": int(len(stars.field)),
             "n_rejected": int((~res.inlier).sum()), "residual_rms_before_px": before.rms_px,
             "residual_rms_after_px": res.rms_px,
             "residual_rms_after_arcsec": float(res.rms_px / res.theta[0] * 206264.806),
             "residual_rms_2d_px": float(np.sqrt((res.residuals[res.inlier] ** 2).sum(axis=1).mean()))}
    if per_image is not None:
        extra["images"] = per_image
        extra["images_solved"] = sum(p["solved"] for p in per_image)
    wild = implausible(res.theta, res.sigma, free, f0, r_corner)
    extra["implausible_terms"] = {n: {"corner_px": px, "sigma_px": spx} for n, (px, spx) in wild.items()}
    checks = {"implausible_terms": report.check(len(wild), 0, "terms beyond their plausible corner displacement "
                                                "(" + ", ".join(f"{n} {px:.3g}±{spx:.2g} px" for n, (px, spx)
                                                                in wild.items()) + ")" if wild else "terms")}
    if tvec is not None:
        rms, mx = model_difference(params, tvec)
        table.add("distortion_residual_px", rms, "px (RMS over the sensor vs the true model)", 0.0)
        table.add("distortion_residual_max_px", mx, "px", 0.0)
        table.add("focal_length_rel_error", (res.theta[0] - tvec[0]) / tvec[0], "1", 0.0)
        extra["outliers_injected"] = int(bad.sum())
        extra["outliers_caught"] = int((bad & ~res.inlier).sum())
        z = np.abs(res.theta - tvec[:8])[free] / np.maximum(res.sigma[free], 1e-300)
        worst = np.asarray(NAMES)[free][int(np.argmax(z))] if free.any() else "-"
        checks.update({"focal_length_rel": report.check((res.theta[0] - tvec[0]) / tvec[0], 5e-4, "(0.05 %)"),
                       "principal_point_px": report.check(np.hypot(*(res.theta[1:3] - tvec[1:3])), 0.5, "px"),
                       "distortion_residual_px": report.check(rms, 0.05, "px"),
                       "parameters_from_truth_sigma": report.check(float(z.max(initial=0.0)), TRUTH_SIGMA,
                                                                   f"σ (worst: {worst})")})
    cal = calfile.CameraCal(float(res.theta[0]), (float(res.theta[1]), float(res.theta[2])),
                            *[float(v) for v in res.theta[3:8]], image_size_px=(int(w), int(h)),
                            residual_rms_px=res.rms_px,
                            principal_point_sigma_px=(float(res.sigma[1]), float(res.sigma[2])))
    toml = args.toml or folder / "calibration.toml"
    calfile.write_section(toml, "camera", cal, source=str(args.input) if args.input else
                          (f"{len(per_image)} images: {', '.join(args.images)}" if per_image else source))
    extra["toml"] = str(toml)
    if not args.no_plots:
        _plots(folder, stars, before, res, w, h)
    return report.finish(args, "camera", table, extra, folder, checks)


def _plots(folder, stars, before, after, w, h) -> None:
    from ...calibration.report import new_figure, save_figure

    fig, axes = new_figure(1, 2, figsize=(12, 5.5))
    for ax, fitres, title in ((axes[0], before, "nominal model"), (axes[1], after, "calibrated model")):
        nb = 16
        iu = np.clip((stars.uv[:, 0] / w * nb).astype(int), 0, nb - 1)
        iv = np.clip((stars.uv[:, 1] / h * nb).astype(int), 0, nb - 1)
        cell = iv * nb + iu
        ok = fitres.inlier
        cnt = np.bincount(cell[ok], minlength=nb * nb)
        mu = np.bincount(cell[ok], fitres.residuals[ok, 0], nb * nb) / np.maximum(cnt, 1)
        mv = np.bincount(cell[ok], fitres.residuals[ok, 1], nb * nb) / np.maximum(cnt, 1)
        cu = (np.arange(nb * nb) % nb + 0.5) * w / nb
        cv = (np.arange(nb * nb) // nb + 0.5) * h / nb
        scale = max(np.hypot(mu, mv).max(), 1e-6)
        ax.quiver(cu, cv, mu, mv, angles="xy", scale_units="xy", scale=scale / (w / nb))
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect("equal")
        ax.set_title(f"{title}: RMS {fitres.rms_px:.3f} px/axis (arrow = cell = {scale:.3g} px)")
        ax.set_xlabel("column (px)")
        ax.set_ylabel("row (px)")
    save_figure(fig, folder / "camera_residuals.png")
    fig, ax = new_figure(figsize=(7, 5))
    r = np.hypot(stars.uv[:, 0] - after.theta[1], stars.uv[:, 1] - after.theta[2])
    for fitres, label in ((before, "nominal"), (after, "calibrated")):
        radial = ((stars.uv - after.theta[1:3]) * fitres.residuals).sum(axis=1) / np.maximum(r, 1e-9)
        ax.plot(r[fitres.inlier], radial[fitres.inlier], ".", ms=1, alpha=0.4, label=label)
    ax.set_xlabel("radius from principal point (px)")
    ax.set_ylabel("radial residual (px)")
    ax.legend()
    save_figure(fig, folder / "camera_radial_residuals.png")
