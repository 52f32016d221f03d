"""``gyrostar solve`` end to end on tetra3's 8 real night-sky images, with no field-of-view hint:
each solution against tetra3rs's solution of the same image (the peer's own centroids and
database), the WCS header read back by astropy against the catalog positions of the matched
stars, and the JSON schema of the issue."""

from __future__ import annotations

import csv
import json
import math
from datetime import UTC
from pathlib import Path

import numpy as np
import pytest
from gyrostar.cli.main import main
from gyrostar.imaging.plate import JSON_KEYS

pytestmark = pytest.mark.timeout(1800)   # solves real frames: minutes on a loaded machine

TETRA3 = Path(__file__).resolve().parents[1] / "data" / "tetra3"


def _sep_arcsec(ra1, dec1, ra2, dec2) -> float:
    r1, d1, r2, d2 = map(math.radians, (ra1, dec1, ra2, dec2))
    c = math.sin(d1) * math.sin(d2) + math.cos(d1) * math.cos(d2) * math.cos(r1 - r2)
    return math.degrees(math.acos(min(1.0, c))) * 3600.0


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("solve_out")
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["solve", str(TETRA3), "--json", "--out", str(out), "-q"])
    return code, json.loads(buf.getvalue()), out


@pytest.fixture(scope="module")
def peer_solutions():
    """tetra3rs's (RA, Dec, FOV) of each image: its extract_centroids + solve_from_centroids."""
    pytest.importorskip("tetra3rs")
    from tetra3_peer import peer_solves

    got = {}
    for name, s, _ in peer_solves()[1]:
        assert s, f"tetra3rs did not solve {name}"
        got[name] = (s.ra_deg, s.dec_deg, s.fov_deg)
    return got


def test_all_eight_solved_with_no_hint_like_tetra3rs(solved, peer_solutions):
    code, out, _ = solved
    assert code == 0
    assert out["solved"] == 8 and len(out["images"]) == 8
    for rec in out["images"]:
        assert tuple(rec) == JSON_KEYS
        ra, dec, fov = peer_solutions[Path(rec["file"]).name]
        assert _sep_arcsec(rec["ra_deg"], rec["dec_deg"], ra, dec) < 10.0, rec["file"]
        assert abs(rec["fov_deg"] / fov - 1.0) < 1e-3, (rec["file"], rec["fov_deg"], fov)
        assert len(rec["q_icrs_to_camera"]) == 4
        assert rec["stars_matched"] >= 10 and rec["p_false"] < 1e-6


def test_wcs_header_maps_matched_stars_to_their_catalog_positions(solved):
    from astropy.io import fits
    from astropy.wcs import WCS

    _, out, folder = solved
    for rec in out["images"][:3]:
        stem = folder / Path(rec["file"]).stem
        with fits.open(stem.with_name(stem.name + ".wcs.fits")) as hdul:
            w = WCS(hdul[0].header)
        assert w.sip is not None
        with open(stem.with_name(stem.name + ".stars.csv")) as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == rec["stars_matched"]
        u = np.array([float(r["u_px"]) for r in rows])
        v = np.array([float(r["v_px"]) for r in rows])
        ra, dec = w.all_pix2world(u, v, 0)
        for r, a, d in zip(rows, ra, dec):
            sep = _sep_arcsec(a, d, float(r["ra_deg"]), float(r["dec_deg"]))
            assert sep <= float(r["residual_arcsec"]) + 0.5, (r["catalog_id"], sep, r["residual_arcsec"])
        # and back: the catalog position lands on the predicted pixel
        pu, pv = w.all_world2pix(np.array([float(r["ra_deg"]) for r in rows]),
                                 np.array([float(r["dec_deg"]) for r in rows]), 0)
        assert np.max(np.hypot(pu - [float(r["u_pred_px"]) for r in rows],
                               pv - [float(r["v_pred_px"]) for r in rows])) < 0.1
        assert stem.with_name(stem.name + ".png").stat().st_size > 10_000


def test_workers_give_the_serial_solutions(solved):
    import contextlib
    import io

    _, out, _ = solved
    files = [out["images"][0]["file"], out["images"][5]["file"]]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["solve", *files, "--workers", "2", "--json", "-q"])
    assert code == 0
    par = json.loads(buf.getvalue())["images"]
    for a, b in zip(par, [out["images"][0], out["images"][5]]):
        assert a["file"] == b["file"]
        assert _sep_arcsec(a["ra_deg"], a["dec_deg"], b["ra_deg"], b["dec_deg"]) < 1e-3


def _gmst_deg(jd_ut1: float) -> float:
    """Greenwich mean sidereal time (IAU 1982, to ~0.1 s): an independent hand formula."""
    t = (jd_ut1 - 2451545.0) / 36525.0
    return (280.46061837 + 360.98564736629 * (jd_ut1 - 2451545.0) + 0.000387933 * t * t) % 360.0


def test_alt_az_of_the_pole_and_of_a_meridian_transit():
    """Independent truth: the celestial pole stands at the site's latitude; a star on the
    meridian (local sidereal time = its RA) at δ < φ stands due south at 90° − (φ − δ).
    The RA given is the meridian's, precessed back to J2000 by hand (m + n sin α tan δ per
    year); tolerance 0.2°: the hand formulas ignore nutation, aberration and polar motion."""
    from datetime import datetime

    from gyrostar.cli.solve import alt_az

    lat, lon = 52.0, 4.4
    when = "2026-11-29T21:30:00"
    jd = datetime(2026, 11, 29, 21, 30, tzinfo=UTC).timestamp() / 86400.0 + 2440587.5
    lst = (_gmst_deg(jd) + lon) % 360.0
    years = (jd - 2451545.0) / 365.25
    m_deg, n_deg = 46.1 / 3600.0, 20.04 / 3600.0            # general precession in RA and Dec per year
    ra2000 = lst - years * (m_deg + n_deg * math.sin(math.radians(lst)) * math.tan(math.radians(20.0)))
    dec2000 = 20.0 - years * n_deg * math.cos(math.radians(lst))
    recs = [{"solved": True, "ra_deg": 10.0, "dec_deg": 89.99}, {"solved": True, "ra_deg": ra2000, "dec_deg": dec2000},
            {"solved": False, "ra_deg": None, "dec_deg": None}]
    note = alt_az(recs, (lat, lon, 10.0), when)
    assert abs(recs[0]["alt_deg"] - lat) < 0.2
    assert abs(recs[1]["alt_deg"] - (90.0 - (lat - 20.0))) < 0.2
    assert abs(recs[1]["az_deg"] - 180.0) < 0.2
    assert "alt_deg" not in recs[2]
    assert note is None or "degraded" in note


def test_fov_hint_and_known_camera_give_the_no_hint_solution(solved, tmp_path):
    """The same image solved with --fov-deg (the pattern search narrowed to ±5 %) and with
    --camera calibration.toml (LostInSpace.for_camera: no search over the focal length) lands on
    the no-hint boresight."""
    import contextlib
    import io

    from gyrostar.calibration import calfile

    _, out, _ = solved
    ref = out["images"][2]
    toml = tmp_path / "calibration.toml"
    calfile.write_section(toml, "camera", calfile.CameraCal(ref["focal_length_px"], (511.5, 383.5), ref["k1"],
                                                            image_size_px=(1024, 768)), source="test")
    for extra in (["--fov-deg", f"{ref['fov_deg'] * 1.02:.3f}"], ["--camera", str(toml)]):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            code = main(["solve", ref["file"], "--json", "-q", *extra])
        assert code == 0, extra
        (rec,) = json.loads(buf.getvalue())["images"]
        assert _sep_arcsec(rec["ra_deg"], rec["dec_deg"], ref["ra_deg"], ref["dec_deg"]) < 10.0, extra
