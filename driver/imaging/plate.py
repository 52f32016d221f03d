"""One image → detection → plate solution, and its products: the JSON record of ``gyrostar
solve``, the matched-star CSV, the FITS WCS header and the annotated PNG.

:class:`ImageSolution` holds the frame's size, its :class:`~gyrostar.imaging.detect.Detection`,
the rows of the spots handed to the solver (brightest usable first) and the
:class:`~gyrostar.starid.lost_in_space.PlateSolution` (``match``/``residual_px`` index those
spots).
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from .detect import Detection, detect_stars

MAX_SPOTS = 40            # brightest usable spots handed to the solver
JSON_KEYS = ("file", "solved", "status", "ra_deg", "dec_deg", "roll_deg", "q_icrs_to_camera", "fov_deg",
             "focal_length_px", "k1", "stars_matched", "residual_arcsec_rms", "p_false", "solve_ms")


@dataclasses.dataclass
class ImageSolution:
    name: str
    width: int
    height: int
    detection: Detection
    rows: np.ndarray          # (k,) rows of detection.spots handed to the solver
    solution: object          # PlateSolution
    detect_ms: float

    @property
    def xy(self) -> np.ndarray:
        return self.detection.spots[self.rows, :2]

    def record(self) -> dict:
        """The per-image object of ``gyrostar solve --json`` (keys :data:`JSON_KEYS`)."""
        s = self.solution
        q = [float(v) for v in s.q_icrs_to_camera] if s.solved else None

        def num(v):
            return float(v) if s.solved and math.isfinite(v) else None

        return {"file": self.name, "solved": bool(s.solved), "status": s.status, "ra_deg": num(s.ra_deg),
                "dec_deg": num(s.dec_deg), "roll_deg": num(s.roll_deg), "q_icrs_to_camera": q,
                "fov_deg": num(s.fov_deg), "focal_length_px": num(s.focal_length_px), "k1": num(s.k1),
                "stars_matched": int(s.stars_matched), "residual_arcsec_rms": num(s.residual_arcsec_rms),
                "p_false": float(s.p_false) if math.isfinite(s.p_false) else None, "solve_ms": float(s.solve_ms)}


def solve_frame(frame, solver, max_spots: int = MAX_SPOTS, fov_hint_deg=None) -> ImageSolution:
    """Detect the stars of ``frame`` (:class:`~gyrostar.imaging.read.Frame`) and solve them with
    ``solver`` (:class:`~gyrostar.starid.lost_in_space.LostInSpace`)."""
    t0 = time.perf_counter()
    det = detect_stars(frame.pixels, frame.saturation)
    xy, rows = det.for_solving(max_spots)
    t1 = time.perf_counter()
    sol = solver.solve(xy, fov_hint_deg=fov_hint_deg)
    return ImageSolution(frame.name, frame.width, frame.height, det, rows, sol, (t1 - t0) * 1e3)


def matched_stars(res: ImageSolution, catalog) -> list[dict]:
    """One row per matched spot: catalog id, V, RA/Dec (°), measured and predicted [u, v] (px)
    and the residual (px, arcsec)."""
    s = res.solution
    index = {int(i): k for k, i in enumerate(catalog.ids)}
    rows = []
    for k in np.flatnonzero(s.match >= 0):
        cid = int(s.match[k])
        u, v = res.xy[k]
        du, dv = s.residual_px[k]
        j = index.get(cid)
        ra = dec = vmag = float("nan")
        if j is not None:
            x, y, z = catalog.vectors[j]
            ra, dec, vmag = math.degrees(math.atan2(y, x)) % 360.0, math.degrees(math.asin(z)), float(catalog.vmag[j])
        rows.append({"catalog_id": cid, "vmag": vmag, "ra_deg": ra, "dec_deg": dec, "u_px": float(u), "v_px": float(v),
                     "u_pred_px": float(u - du), "v_pred_px": float(v - dv), "du_px": float(du), "dv_px": float(dv),
                     "residual_arcsec": float(math.hypot(du, dv) / s.focal_length_px * 206264.806)})
    return rows


def write_csv(path: Path, rows: list[dict]) -> None:
    import csv

    cols = ("catalog_id", "vmag", "ra_deg", "dec_deg", "u_px", "v_px", "u_pred_px", "v_pred_px", "du_px", "dv_px",
            "residual_arcsec")
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow([r["catalog_id"]] + [f"{r[c]:.6f}" if c not in ("u_px", "v_px", "u_pred_px", "v_pred_px",
                                                                        "du_px", "dv_px") else f"{r[c]:.4f}"
                                            for c in cols[1:]])


def write_wcs(path: Path, res: ImageSolution) -> float:
    """FITS file (header only, no data) with the solution's TAN-SIP WCS; returns the SIP fit's
    worst error (px)."""
    from astropy.io import fits

    from .wcs import wcs_header

    s = res.solution
    hdr, err = wcs_header(s.q_icrs_to_camera, s.focal_length_px, s.k1, s.cx_px, s.cy_px, res.width, res.height)
    hdr["SOLVER"] = ("gyrostar", "plate solution")
    hdr["NMATCH"] = (int(s.stars_matched), "stars matched")
    hdr["RESRMS"] = (float(s.residual_arcsec_rms), "matched-star residual RMS (arcsec)")
    hdr["PFALSE"] = (float(s.p_false), "expected false matches of the search")
    hdr["SIPERR"] = (float(err), "worst SIP fit error over the sensor (px)")
    hdr["SRCFILE"] = (Path(res.name.split("#")[0]).name[:68], "image solved")
    fits.PrimaryHDU(header=hdr).writeto(path, overwrite=True)
    return err


def out_stem(out_dir: Path, name: str, used: set) -> Path:
    """A unique output stem in ``out_dir`` for image ``name`` (``file#i`` stacks get ``_i``)."""
    base, _, idx = name.partition("#")
    stem = Path(base).name
    for suf in (".gz",):
        stem = stem[: -len(suf)] if stem.endswith(suf) else stem
    stem = Path(stem).stem + (f"_{idx}" if idx else "")
    cand, n = stem, 1
    while cand in used:
        n += 1
        cand = f"{stem}_{n}"
    used.add(cand)
    return out_dir / cand
