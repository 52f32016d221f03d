"""``gyrostar solve PATH...``: night-sky images → attitude, field of view and lens, with no
field-of-view hint (:mod:`gyrostar.starid.lost_in_space`), one record per image.

Inputs: image files or folders of them (:mod:`gyrostar.imaging.read`: FITS, TIFF 8/16 bit,
PNG, JPEG, BMP, ``sim frame`` FITS, the head's full-frame dumps). Each frame: stars detected
(:mod:`gyrostar.imaging.detect`), the brightest usable spots solved. ``--out DIR`` writes per
image ``STEM.png`` (annotated), ``STEM.wcs.fits`` (TAN-SIP header, astropy) and
``STEM.stars.csv`` (matched stars and residuals). ``--site``/``--time`` add the boresight's
altitude and azimuth (astropy AltAz, no network: IERS auto-download is off; a time outside
the bundled IERS table is said to degrade the precision).

Exit 0 when every image is solved, 1 when any is not (one stderr line per such image), 2 for
a bad argument or an unreadable image (one line each; the other images are still solved).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from ..errors import ConfigError

DEFAULT_FOV_RANGE = (5.0, 30.0)
MAX_WORKERS = 64
CREDIT_NOTE = "annotated by gyrostar solve"


def _fov_range(text: str) -> tuple[float, float]:
    import argparse

    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"takes MIN,MAX in degrees, got '{text}'") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 1.0 <= lo <= hi <= 45.0):
        raise argparse.ArgumentTypeError(f"needs 1 <= MIN <= MAX <= 45 (degrees), got '{text}'")
    return lo, hi


def _site(text: str) -> tuple[float, float, float]:
    import argparse

    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3) or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"takes LAT,LON[,H_M] (degrees, degrees east, metres), got '{text}'")
    lat, lon, hgt = vals[0], vals[1], vals[2] if len(vals) == 3 else 0.0
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0 and -500.0 <= hgt <= 1e5):
        raise argparse.ArgumentTypeError(f"latitude in [-90, 90], longitude in [-180, 360], height in [-500, 1e5] m; "
                                         f"got '{text}'")
    return lat, lon, hgt


def configure(parser) -> None:
    from .argtypes import float_in, int_in
    from .main import add_json

    parser.add_argument("paths", nargs="+", metavar="PATH", help="image files or folders of images")
    parser.add_argument("--fov-deg", type=float_in(1.0, 45.0, unit="deg"), default=None,
                        help="horizontal field of view hint (deg); the search then covers ±5 %% of it")
    parser.add_argument("--fov-range", type=_fov_range, default=DEFAULT_FOV_RANGE, metavar="MIN,MAX",
                        help="horizontal fields of view searched with no hint (deg, default 5,30)")
    parser.add_argument("--camera", default=None, metavar="PRESET|calibration.toml",
                        help="a known camera (preset name, or a calibration TOML with a [camera] table): its "
                             "intrinsics are used and no field is searched")
    parser.add_argument("--mag-limit", type=float_in(2.0, 10.0), default=None,
                        help="faintest catalog V used (default: from the field of view)")
    parser.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=1,
                        help=f"images solved in parallel processes, 1 to {MAX_WORKERS} (default 1)")
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="write per image an annotated PNG, a FITS WCS (TAN-SIP) header and a CSV of the "
                             "matched stars into DIR (created)")
    parser.add_argument("--site", type=_site, default=None, metavar="LAT,LON[,H_M]",
                        help="observing site (deg, deg east, m): report the boresight's altitude and azimuth")
    parser.add_argument("--time", default=None, metavar="UTC",
                        help="with --site: the exposure time, ISO UTC (e.g. 2019-07-29T20:47:26)")
    add_json(parser)


@dataclasses.dataclass(frozen=True)
class Setup:
    """What every worker needs to solve and write an image (picklable)."""

    fov_range: tuple[float, float]
    fov_hint: float | None
    camera: object | None           # gyrostar.camera.CameraModel
    mag_limit: float | None
    out: str | None


_SOLVERS: dict = {}


def _solver(setup: Setup, width: int, height: int):
    from ..starid.lost_in_space import LostInSpace

    key = (width, height)
    if key not in _SOLVERS:
        if setup.camera is not None:
            _SOLVERS[key] = LostInSpace.for_camera(setup.camera, mag_limit=setup.mag_limit)
        else:
            _SOLVERS[key] = LostInSpace.for_sensor(width, height, fov_range_deg=setup.fov_range,
                                                   mag_limit=setup.mag_limit, quiet=True)
    return _SOLVERS[key]


def solve_path(path: str, setup: Setup) -> list[dict]:
    """Solve every frame of one file: per frame ``{"record": ..., "error": None}``, or one
    ``{"record": None, "error": "..."}`` when the file cannot be read or does not fit."""
    from ..imaging.plate import solve_frame
    from ..imaging.read import read_frames

    try:
        frames = read_frames(path)
    except ConfigError as exc:
        return [{"record": None, "error": str(exc), "file": str(path)}]
    out = []
    used: set = set()
    for frame in frames:
        if setup.camera is not None and (frame.width, frame.height) != (setup.camera.width_px,
                                                                        setup.camera.height_px):
            out.append({"record": None, "file": frame.name,
                        "error": f"{frame.name}: image is {frame.width}x{frame.height} px, --camera is "
                                 f"{setup.camera.width_px}x{setup.camera.height_px}"})
            continue
        res = solve_frame(frame, _solver(setup, frame.width, frame.height), fov_hint_deg=setup.fov_hint)
        rec = res.record()
        if setup.out:
            rec_files = _write_products(Path(setup.out), frame, res, used)
            out.append({"record": rec, "error": None, "files": rec_files})
        else:
            out.append({"record": rec, "error": None})
    return out


def _write_products(out_dir: Path, frame, res, used: set) -> list[str]:
    from ..catalog import load_catalog
    from ..imaging.annotate import write_png
    from ..imaging.plate import matched_stars, out_stem, write_csv, write_wcs
    from ..imaging.star_names import star_names

    stem = out_stem(out_dir, frame.name, used)
    png = stem.with_name(stem.name + ".png")
    write_png(png, frame.pixels, res, star_names(), credit=CREDIT_NOTE)
    files = [str(png)]
    if res.solution.solved:
        wcs = stem.with_name(stem.name + ".wcs.fits")
        write_wcs(wcs, res)
        csv = stem.with_name(stem.name + ".stars.csv")
        write_csv(csv, matched_stars(res, load_catalog("hip2", 10.0)))
        files += [str(wcs), str(csv)]
    return files


def _camera_from(arg: str):
    from ..camera import CameraModel, camera_preset

    if not arg.endswith(".toml"):
        return camera_preset(arg)
    from ..calibration import calfile

    cal = calfile.load(arg)
    c = cal.camera
    if c is None:
        raise ConfigError(f"--camera {arg}: the file has no [camera] table")
    pitch = c.pixel_pitch_um * 1e-6
    w, h = c.image_size_px
    return CameraModel(c.focal_length_px * pitch, pitch, int(w), int(h), c.principal_point_px[0],
                       c.principal_point_px[1], c.k1, c.k2, c.k3, c.p1, c.p2)


def alt_az(records: list[dict], site, when: str) -> str | None:
    """Add ``alt_deg``/``az_deg`` (az from north through east) of each solved boresight; returns
    a note when the IERS table does not cover ``when`` (precision degraded), else None."""
    import warnings

    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    try:
        t = Time(when, scale="utc")
    except ValueError as exc:
        raise ConfigError(f"--time {when!r}: not an ISO UTC time ({exc})") from None
    loc = EarthLocation.from_geodetic(site[1] * u.deg, site[0] * u.deg, site[2] * u.m)
    note = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame = AltAz(obstime=t, location=loc)
        for rec in records:
            if rec["solved"]:
                c = SkyCoord(rec["ra_deg"] * u.deg, rec["dec_deg"] * u.deg, frame="icrs").transform_to(frame)
                rec["alt_deg"], rec["az_deg"] = float(c.alt.deg), float(c.az.deg)
    for w in caught:
        if "IERS" in str(w.message) or "ERFA" in type(w.message).__name__:
            note = (f"--time {when}: outside the bundled IERS table (no download): altitude/azimuth precision "
                    "degraded (polar motion and UT1-UTC taken as 0, below 1\" and 1 s)")
            break
    return note


def run(args) -> int:
    import sys

    from ..imaging.read import expand_paths
    from .output import emit, progress

    if (args.site is None) != (args.time is None):
        raise ConfigError("--site and --time go together (altitude/azimuth need both)")
    camera = _camera_from(args.camera) if args.camera else None
    if args.fov_deg is not None and not args.fov_range[0] <= args.fov_deg <= args.fov_range[1]:
        raise ConfigError(f"--fov-deg {args.fov_deg:g} lies outside --fov-range "
                          f"{args.fov_range[0]:g},{args.fov_range[1]:g}")
    files = expand_paths(args.paths)
    if args.out:
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out {out}: exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
    setup = Setup(tuple(args.fov_range), args.fov_deg, camera, args.mag_limit, args.out)
    results: list[dict] = []
    with progress(args, "solving images", len(files)) as step:
        if args.workers == 1 or len(files) == 1:
            for f in files:
                results += solve_path(str(f), setup)
                step()
        else:
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(max_workers=min(args.workers, len(files))) as pool:
                for got in pool.map(solve_path, [str(f) for f in files], [setup] * len(files)):
                    results += got
                    step()
    records = [r["record"] for r in results if r["record"] is not None]
    errors = [r["error"] for r in results if r["error"] is not None]
    note = alt_az(records, args.site, args.time) if args.site else None
    for r in records:
        if not r["solved"]:
            sys.stderr.write(f"gyrostar solve: {r['file']}: not solved: {r['status']}\n")
    for e in errors:
        sys.stderr.write(f"gyrostar solve: error: {e}\n")
    if note:
        sys.stderr.write(f"gyrostar solve: note: {note}\n")
    n_ok = sum(r["solved"] for r in records)
    code = 2 if errors else (0 if n_ok == len(records) else 1)
    result = {"images": records, "solved": n_ok}
    if errors:
        result.update(error=errors[0], exit_code=code)
    if note:
        result["note"] = note
    emit(args, result, _text(records, n_ok, results))
    return code


def _text(records: list[dict], n_ok: int, results: list[dict]) -> str:
    lines = []
    for r in records:
        if not r["solved"]:
            continue
        line = (f"{r['file']}: RA {r['ra_deg']:.5f}° Dec {r['dec_deg']:+.5f}° roll {r['roll_deg']:.3f}° "
                f"FOV {r['fov_deg']:.4f}° f {r['focal_length_px']:.1f} px k1 {r['k1']:+.4f}; "
                f"{r['stars_matched']} stars, {r['residual_arcsec_rms']:.2f}\" RMS, p_false {r['p_false']:.1e}, "
                f"{r['solve_ms']:.1f} ms")
        if "alt_deg" in r:
            line += f"; alt {r['alt_deg']:.3f}° az {r['az_deg']:.3f}°"
        lines.append(line)
    lines.append(f"solved {n_ok} of {len(records)} images" + ("" if len(records) == len(results) else
                                                              f" ({len(results) - len(records)} unreadable)"))
    return "\n".join(lines)
