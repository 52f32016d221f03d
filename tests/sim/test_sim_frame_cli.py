"""``gyrostar sim frame``: FITS with truth header and WCS that maps truth back to the catalog."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

astropy = pytest.importorskip("astropy")


def test_sim_frame_writes_fits_png_and_consistent_wcs(tmp_path):
    from astropy.io import fits
    from astropy.wcs import WCS

    out = tmp_path / "f.fits"
    proc = subprocess.run([sys.executable, "-m", "gyrostar", "sim", "frame", "--preset", "xing2012", "--rate-dps",
                           "0.5,-1,0.2", "--ra-deg", "83.8", "--dec-deg", "-5.4", "--roll-deg", "20", "--out",
                           str(out), "--json", "--mag-limit", "7.0"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert out.exists() and (tmp_path / "f.png").exists() and res["stars_in_field"] > 10
    with fits.open(out) as h:
        img, hdr, tab = h[0].data, h[0].header, h["TRUTH"].data
        assert img.shape == (1024, 1024) and img.dtype == np.uint16
        q = np.array([hdr["QS_X"], hdr["QS_Y"], hdr["QS_Z"], hdr["QS_W"]])
        assert np.linalg.norm(q) == pytest.approx(1.0)
        assert hdr["RATE_Y"] == pytest.approx(-1.0)
        w = WCS(hdr)
        from gyrostar.catalog import load_catalog

        cat = load_catalog("hip2", 7.0)
        ins = np.flatnonzero(tab["IN_FIELD"])
        for k in ins[:5]:
            ra, dec = w.all_pix2world(tab["COL"][k], tab["ROW"][k], 0)
            v = cat.vectors[np.flatnonzero(cat.ids == tab["ID"][k])[0]]
            sep = math.degrees(math.acos(min(1.0, v @ np.array([
                math.cos(math.radians(dec)) * math.cos(math.radians(ra)),
                math.cos(math.radians(dec)) * math.sin(math.radians(ra)), math.sin(math.radians(dec))]))))
            assert sep * 3600 < 1.0  # the smear is averaged around the mid-exposure WCS
        # the brightest in-field star is bright in the image at its truth position
        k = ins[0]
        r, c = int(round(tab["ROW"][k])), int(round(tab["COL"][k]))
        assert img[r - 2:r + 3, c - 2:c + 3].max() > 300


def test_sim_frame_bad_rate():
    proc = subprocess.run([sys.executable, "-m", "gyrostar", "sim", "frame", "--rate-dps", "1,2", "--out",
                           "/tmp/x.fits"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "rate-dps" in proc.stderr


def test_sim_frame_keeps_an_existing_frame_without_force(tmp_path):
    """A second frame to the same path is refused (exit 2) and the first kept; ``--force`` replaces it."""
    out = tmp_path / "f.fits"
    base = [sys.executable, "-m", "gyrostar", "sim", "frame", "--ra-deg", "10", "--dec-deg", "20", "--out", str(out),
            "--mag-limit", "6.0"]
    assert subprocess.run(base, capture_output=True, text=True, timeout=300).returncode == 0
    first = out.read_bytes()
    proc = subprocess.run(base + ["--seed", "5"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "--force" in proc.stderr and out.read_bytes() == first
    proc = subprocess.run(base + ["--seed", "5", "--force"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and out.read_bytes() != first
    proc = subprocess.run(base[:-4] + ["--out", str(tmp_path / "g.fits"), "--rate-dps", "1e9,0,0"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "rate-dps" in proc.stderr and not (tmp_path / "g.fits").exists()
