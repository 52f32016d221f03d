"""``gyrostar sim frame``: render one simulated exposure to FITS (+ PNG).

The FITS primary HDU holds the uint16 ADU image; its header carries the truth attitude
(``QS_X..QS_W`` at exposure start, ``QM_*`` at mid-exposure; ICRS→body, scalar last),
the body rates, the preset, seeds and a TAN WCS built from the mid-exposure attitude
(``CRPIX`` = principal point, 1-based; ``CD`` from the camera's focal length; lens
distortion is not in the WCS). A ``TRUTH`` table lists every star near the field:
catalog id, V, exposure-averaged centroid (0-based column/row) and the in-field flag.
The PNG is the image with a square-root stretch.
"""

from __future__ import annotations

import math
from pathlib import Path

from gyrostar.cli.argtypes import seed
from gyrostar.cli.main import add_json
from gyrostar.errors import ConfigError

HELP = "render one simulated star-camera frame (FITS with truth header, plus PNG)"
MAX_RATE_DPS = 2000.0   # deg/s: the BMI088's widest range


def _triple(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"--rate-dps takes three comma-separated numbers X,Y,Z (deg/s), got '{text}'")
    if math.hypot(*vals) > MAX_RATE_DPS:
        raise ConfigError(f"--rate-dps {text}: above {MAX_RATE_DPS:g} deg/s (a gyro's widest range)")
    return vals


def configure(parser) -> None:
    parser.add_argument("--preset", default="xing2012", help="simulator preset name or TOML file")
    parser.add_argument("--rate-dps", default="0,0,0", help="body rate X,Y,Z over the exposure (deg/s)")
    parser.add_argument("--out", required=True, help="output FITS path (the PNG goes beside it)")
    parser.add_argument("--ra-deg", type=float, default=None, help="boresight RA at exposure start (deg)")
    parser.add_argument("--dec-deg", type=float, default=None, help="boresight Dec at exposure start (deg)")
    parser.add_argument("--roll-deg", type=float, default=0.0, help="roll about the boresight (deg)")
    parser.add_argument("--seed", type=seed, default=0, help="sensor seed (noise, and the attitude if no RA/Dec)")
    parser.add_argument("--frame", type=int, default=0, help="frame counter (noise realisation)")
    parser.add_argument("--catalog", default="hip2", help="catalog: hip2 or gaia")
    parser.add_argument("--mag-limit", type=float, default=8.5, help="faintest V rendered")
    parser.add_argument("--no-noise", action="store_true", help="expected signal only, no noise")
    parser.add_argument("--force", action="store_true", help="replace an existing FITS file and its PNG")
    add_json(parser)


def wcs_cd(q, camera):
    """TAN CD matrix (deg/px) and boresight (ra, dec) in deg for attitude ``q`` (ICRS→body)."""
    from gyrostar.imaging.wcs import tan_cd

    return tan_cd(q, camera.focal_length_px)


def run(args) -> int:
    import numpy as np
    from astropy.io import fits
    from gyrostar.attitude import quat_from_boresight
    from gyrostar.catalog import load_catalog
    from gyrostar.cli.output import emit

    from .sim_preset import load_preset
    from .sky import Sky
    from .trajectory import random_attitudes

    out = Path(args.out)
    if out.suffix.lower() not in (".fits", ".fit", ".fts"):
        raise ConfigError(f"--out must name a .fits file, got {out}")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist")
    for path in (out, out.with_suffix(".png")):
        if path.exists() and not (args.force and path.is_file()):
            raise ConfigError(f"--out {out}: {path} exists" + ("" if path.is_file() else " and is not a file")
                              + (" (--force replaces it)" if path.is_file() else ""))
    rate = np.radians(_triple(args.rate_dps))
    preset = load_preset(args.preset)
    if (args.ra_deg is None) != (args.dec_deg is None):
        raise ConfigError("give both --ra-deg and --dec-deg, or neither (random attitude from --seed)")
    for flag, value, lo, hi in (("--ra-deg", args.ra_deg, 0.0, 360.0), ("--dec-deg", args.dec_deg, -90.0, 90.0),
                                ("--roll-deg", args.roll_deg, -360.0, 360.0)):
        if value is not None and not lo <= value <= hi:
            raise ConfigError(f"{flag} must be in [{lo:g}, {hi:g}], got {value:g}")
    if args.ra_deg is None:
        q0 = random_attitudes(1, np.random.default_rng(args.seed))[0]
    else:
        q0 = quat_from_boresight(math.radians(args.ra_deg), math.radians(args.dec_deg), math.radians(args.roll_deg))
    sky = Sky(load_catalog(args.catalog, args.mag_limit), preset, seed=args.seed)
    img, truth = sky.render_frame(q0, rate, frame=args.frame, noise=not args.no_noise)

    cam = preset.camera
    cd, ra_c, dec_c = wcs_cd(truth.q_mid, cam)
    hdu = fits.PrimaryHDU(img)
    h = hdu.header
    h["BUNIT"] = ("adu", "10-bit ADC counts")
    h["PRESET"] = (preset.name, "simulator preset")
    h["CATALOG"] = (args.catalog, "star catalog")
    h["MAGLIM"] = (args.mag_limit, "faintest V rendered")
    h["EXPTIME"] = (preset.detector.exposure_s, "exposure (s)")
    h["SEED"] = (args.seed, "sensor seed")
    h["FRAME"] = (args.frame, "frame counter")
    h["NOISE"] = (not args.no_noise, "noise rendered")
    for ax, v in zip("XYZ", np.degrees(rate)):
        h[f"RATE_{ax}"] = (float(v), f"body rate {ax} (deg/s)")
    for pre, q, what in (("QS", truth.q_start, "start"), ("QM", truth.q_mid, "mid"), ("QE", truth.q_end, "end")):
        for comp, v in zip("XYZW", q):
            h[f"{pre}_{comp}"] = (float(v), f"ICRS->body quaternion at {what}")
    h["FOCALPX"] = (cam.focal_length_px, "focal length (px)")
    h["PIXPITCH"] = (cam.pixel_pitch_m, "pixel pitch (m)")
    h["WCSAXES"] = 2
    h["CTYPE1"], h["CTYPE2"] = "RA---TAN", "DEC--TAN"
    h["CUNIT1"], h["CUNIT2"] = "deg", "deg"
    h["CRPIX1"] = (cam.cx_px + 1.0, "principal point column (1-based)")
    h["CRPIX2"] = (cam.cy_px + 1.0, "principal point row (1-based)")
    h["CRVAL1"] = (ra_c, "boresight RA at mid-exposure (deg)")
    h["CRVAL2"] = (dec_c, "boresight Dec at mid-exposure (deg)")
    h["CD1_1"], h["CD1_2"], h["CD2_1"], h["CD2_2"] = (float(cd[0, 0]), float(cd[0, 1]), float(cd[1, 0]),
                                                      float(cd[1, 1]))
    h["RADESYS"] = "ICRS"
    h["COMMENT"] = "WCS from the mid-exposure truth attitude; lens distortion not included"
    cols = fits.ColDefs([
        fits.Column(name="ID", format="K", array=truth.ids),
        fits.Column(name="VMAG", format="D", array=truth.vmag),
        fits.Column(name="COL", format="D", array=truth.uv[:, 0]),
        fits.Column(name="ROW", format="D", array=truth.uv[:, 1]),
        fits.Column(name="ELECTRONS", format="D", array=truth.electrons),
        fits.Column(name="IN_FIELD", format="L", array=truth.in_field),
    ])
    tab = fits.BinTableHDU.from_columns(cols, name="TRUTH")
    fits.HDUList([hdu, tab]).writeto(out, overwrite=True)

    png = out.with_suffix(".png")
    _write_png(png, img, preset.detector.bias_adu)
    result = {"fits": str(out), "png": str(png), "preset": preset.name, "stars_in_field": int(truth.in_field.sum()),
              "boresight_ra_deg": ra_c, "boresight_dec_deg": dec_c, "rate_dps": list(np.degrees(rate)),
              "max_adu": int(img.max()), "mean_adu": float(img.mean())}
    emit(args, result, f"wrote {out} and {png}: {result['stars_in_field']} stars in field, "
                       f"boresight RA {ra_c:.3f} Dec {dec_c:.3f} deg")
    return 0


def _write_png(path: Path, img, bias: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    x = np.sqrt(np.clip(img.astype(np.float64) - bias, 0.0, None))
    top = max(1.0, float(np.percentile(x, 99.9)))
    plt.imsave(path, np.clip(x / top, 0.0, 1.0), cmap="gray", origin="upper")
