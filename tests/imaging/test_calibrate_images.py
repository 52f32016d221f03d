"""``gyrostar calibrate camera --images`` on tetra3's 8 real frames against tetra3rs's
``calibrate_camera`` (radial model) on the same images: the focal length within 0.1 %, the
residual RMS within 0.13 px, and the [camera] table the loop reads."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest
from gyrostar.cli.main import main

pytestmark = pytest.mark.timeout(1800)   # solves real frames: minutes on a loaded machine

TETRA3 = Path(__file__).resolve().parents[1] / "data" / "tetra3"


@pytest.fixture(scope="module")
def peer_focal_length():
    """tetra3rs's calibrate_camera (radial) over its own solutions of the 8 images."""
    pytest.importorskip("tetra3rs")
    from tetra3_peer import peer_solves

    db, solves = peer_solves()
    r = db.calibrate_camera([s for _, s, _ in solves], [c for _, _, c in solves], image_shape=(768, 1024),
                            model="radial")
    return r.camera_model.focal_length_px, r.rmse_after_px


def test_focal_length_and_residuals_against_tetra3rs(tmp_path, peer_focal_length):
    from gyrostar.calibration import calfile

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["calibrate", "camera", "--images", str(TETRA3), "--report", str(tmp_path / "rep"), "--json",
                     "-q"])
    assert code == 0
    out = json.loads(buf.getvalue())
    f_peer, rms_peer = peer_focal_length
    f = out["parameters"]["f_px"]["value"]
    assert abs(f / f_peer - 1.0) < 1e-3, (f, f_peer)
    assert out["parameters"]["f_px"]["sigma"] < 1.0
    assert out["residual_rms_2d_px"] <= 0.13
    assert out["images_solved"] == 8 and out["n_stars"] >= 150
    assert out["fixed"] == ["k2", "k3", "p1", "p2"]
    cal = calfile.load(out["toml"])
    assert cal.camera.focal_length_px == pytest.approx(f)
    assert tuple(cal.camera.image_size_px) == (1024, 768)
    assert (tmp_path / "rep" / "camera_residuals.png").exists()
