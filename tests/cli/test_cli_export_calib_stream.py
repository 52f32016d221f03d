"""`gyrostar replay LOG --export calib` on a run of the streaming head (the default): every
pushed frame's pixels are paired with the window set that frame used (by the frame it names),
so each exported star sits where its field's attitude puts its catalog star."""

import json

import numpy as np
from cli_helpers import gyrostar
from gyrostar.attitude import quat_to_dcm
from gyrostar.calibration.intrinsics import OBS_FLOOR_PX
from gyrostar.calibration.star_fields import field_attitudes
from gyrostar.camera import camera_preset


def test_export_calib_of_a_streamed_run(tmp_path):
    out = tmp_path / "run"
    run = gyrostar(["run", "--duration", "6", "--out", out, "--no-plots", "--json"])
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["head_mode"] == "stream"
    npz = tmp_path / "calib.npz"
    exp = gyrostar(["replay", out / "flatsat.gslog", "--export", "calib", "--out", npz])
    assert exp.returncode == 0, exp.stderr
    z = np.load(npz)
    k = len(z["t_cam"])
    assert k >= 0.3 * summary["frames"] and len(z["field"]) >= 3 * k
    cam = camera_preset("xing2012")                 # the default flatsat's nominal camera
    assert np.allclose(cam.as_array(), z["camera"])
    sig = z["uv_sigma"]                              # each centroid's CRLB, px per axis
    assert sig.shape == z["field"].shape and np.isfinite(sig).mean() > 0.95
    ok, q = field_attitudes(z["field"], z["uv"], z["ref"], cam, k, uv_sigma=sig)
    assert ok.mean() > 0.9
    res, norm = [], []
    for f in np.flatnonzero(ok):
        sel = z["field"] == f
        uv, valid = cam.project(z["ref"][sel] @ quat_to_dcm(q[f]).T)
        d = uv[valid] - z["uv"][sel][valid]
        res.append(np.hypot(*d.T))
        norm.append(d / np.sqrt(sig[sel][valid] ** 2 + OBS_FLOOR_PX ** 2)[:, None])
    res = np.concatenate(res)
    # a window set paired with another frame's pixels would put stars pixels off
    assert np.percentile(res, 99) < 0.5, np.percentile(res, [50, 99, 100])
    # the σ it states is the scatter it has (the default flatsat's camera is the nominal one)
    z_rms = np.sqrt(np.mean(np.concatenate(norm) ** 2))
    assert 0.6 < z_rms < 1.5, z_rms
