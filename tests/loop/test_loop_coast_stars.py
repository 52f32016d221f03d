"""``n_stars`` through a star-less COAST: the stars the newest image measured (0), not the
tracked stars the loop still predicts (it stayed at 12 through an eclipse)."""

import numpy as np
from gyrostar.loop import record as R


def test_n_stars_is_zero_while_an_eclipse_hides_every_star(tmp_path):
    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat

    outs = []
    res = run_flatsat(hc.load_flatsat(), hc.load_scenario("eclipse"), duration=4.5, seed=2, folder=tmp_path,
                      plots=False, status=False, fast=True, on_output=lambda r: outs.append(r.copy()))
    out = np.concatenate(outs)
    t = out["t"] - out["t"][0]
    track = (out["mode"] == R.MODE_TRACK) & (t < 3.0)
    assert track.sum() > 400 and np.median(out["n_stars"][track]) >= 8
    dark = (out["mode"] == R.MODE_COAST) & (t > 3.2)          # a frame period into the eclipse
    assert dark.sum() > 200, res["mode_seconds"]
    assert np.all(out["n_stars"][dark] == 0)
    tracked_rows = (out["star_id"][dark] >= 0).sum(axis=1)
    assert np.all(tracked_rows >= 8)                             # still predicted: the windows of the regain
