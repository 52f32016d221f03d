"""Star tracks: a star dropped as a wrong identification stays out for a doubling time.

Truth: the simulator's own hot pixel — seed 1 of the demo puts a 500 e⁻/s pixel 2 px from
HIP 11840 (V 5.84), whose pulled centroid fails the gate; without the back-off the loop took
it back 88 times in 30 s (818 rejected star updates)."""

import math

import numpy as np
from gyrostar.attitude import quat_from_boresight
from gyrostar.camera import camera_preset
from gyrostar.loop.coupled import LoopParams
from gyrostar.loop.tracks import BAN_FIRST_S, BAN_MAX_S, StarTracks
from gyrostar.starid.index import load_index


def _tracks():
    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    return StarTracks(LoopParams(), cam, idx)


def test_wrong_identification_is_kept_out_for_a_doubling_time():
    tr = _tracks()
    q = quat_from_boresight(math.radians(83.8), math.radians(-5.4), 0.0)      # Orion: a full field
    tr.fill_from_catalog(q, 0.0)
    s = int(tr.tracked()[0])
    nav = int(tr.nav[s])
    t = 10.0
    for k in range(8):
        tr.drop_wrong(s, t)
        wait = min(BAN_FIRST_S * 2.0 ** k, BAN_MAX_S)
        tr.fill_from_catalog(q, t + wait - 1e-3)            # still kept out
        assert nav not in tr.nav[tr.active].tolist()
        tr.clear()                                          # (its slot went to the next star)
        tr.fill_from_catalog(q, t + wait + 1e-3)            # back
        assert nav in tr.nav[tr.active].tolist()
        s = int(np.flatnonzero(tr.active & (tr.nav == nav))[0])
        t += wait + 1.0
    assert tr.strikes[nav] == 8


def test_seed_1_demo_hot_pixel_star_is_not_retried_every_frame(tmp_path):
    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat

    res = run_flatsat(hc.load_flatsat(), hc.load_scenario("demo"), duration=30.0, seed=1, folder=tmp_path,
                      plots=False, status=False, fast=True)
    c = res["counters"]
    assert c["wrong_ids_dropped"] <= 6 and c["rejected_updates"] < 150, c
    assert res["mid_exposure_error_arcsec_1sigma"] < 1.2 * res["floor_mid_exposure_arcsec"]
