"""Frames that hold no star field are "not solved", one stderr line each, exit 1 — never an
attitude: a blank frame, pure noise, a daylight sky, a frame of only trees (sky seen through
leaves: many star-like blobs), each as a user's camera would write it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_helpers import gyrostar
from PIL import Image

pytestmark = pytest.mark.timeout(1800)   # solves real frames: minutes on a loaded machine


def _frames(d, rng):
    h, w = 768, 1024
    Image.fromarray(np.zeros((h, w), np.uint8)).save(d / "blank.png")
    Image.fromarray(np.clip(rng.normal(40, 12, (h, w)), 0, 255).astype(np.uint8)).save(d / "noise.png")
    yy, xx = np.mgrid[0:h, 0:w]
    day = np.stack([150 + 40 * yy / h, 190 + 30 * yy / h, np.full((h, w), 245.0)], axis=-1)
    day += rng.normal(0, 2.0, day.shape)
    day[:, 800:] = 255.0                                       # the sun's glare, saturated
    Image.fromarray(np.clip(day, 0, 255).astype(np.uint8)).save(d / "daylight.jpg", quality=85)
    from scipy.ndimage import gaussian_filter

    canopy = gaussian_filter(rng.normal(0, 1, (h, w)), 4.0)
    holes = canopy > np.quantile(canopy, 0.985)                # sky through the leaves
    trees = np.where(holes, 900.0, 60.0) + rng.normal(0, 6, (h, w))
    tifffile_write(d / "trees.tiff", np.clip(trees, 0, 65535).astype(np.uint16))


def tifffile_write(path, arr):
    import tifffile

    tifffile.imwrite(path, arr)


def test_no_star_field_is_never_solved(tmp_path):
    _frames(tmp_path, np.random.default_rng(11))
    names = ["blank.png", "noise.png", "daylight.jpg", "trees.tiff"]
    res = gyrostar(["solve", *[tmp_path / n for n in names], "--json"], timeout=1500)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 5 and lines[-1] == "solved 0 of 4 images", res.stderr   # --json: the summary on stderr
    for n, ln in zip(names, lines):
        assert n in ln and "not solved" in ln, ln
    out = json.loads(res.stdout)
    assert out["solved"] == 0
    assert all(not r["solved"] and r["ra_deg"] is None and r["q_icrs_to_camera"] is None for r in out["images"])
