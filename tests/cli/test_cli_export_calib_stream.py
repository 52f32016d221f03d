"""`gyrostar replay LOG --export calib` on a run of the streaming head (the default): every
pushed frame's pixels are paired with the window set that frame used (by the frame it names),
so each exported star sits where its field's attitude puts its catalog star."""

import json

import numpy as np
from cli_helpers import gyrostar
from gyrostar.attitude import quat_to_dcm
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
    ok, q = field_attitudes(z["field"], z["uv"], z["ref"], cam, k)
    assert ok.mean() > 0.9
    res = []
    for f in np.flatnonzero(ok):
        sel = z["field"] == f
        uv, valid = cam.project(z["ref"][sel] @ quat_to_dcm(q[f]).T)
        res.append(np.hypot(*(uv[valid] - z["uv"][sel][valid]).T))
    res = np.concatenate(res)
    # a window set paired with another frame's pixels would put stars pixels off
    assert np.percentile(res, 99) < 0.5, np.percentile(res, [50, 99, 100])
