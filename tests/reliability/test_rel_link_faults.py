"""Link faults during a short run of the coupled loop on the simulated flatsat (the 30 s
campaign is ``python -m gyrostar.hil.reliability.linkfaults``): the loop never raises, coasts on
the gyro with a valid attitude, gets a good frame back within 2 frames, counts bad frames."""

import numpy as np
import pytest
from gyrostar.hil.reliability.campaign import FaultEvent, run_campaign
from gyrostar.hil.reliability.linkfaults import analyse, cumulative
from gyrostar.loop.record import MODE_ACQUIRE


def test_cum_counter_survives_client_restart():
    assert list(cumulative(np.array([0, 2, 5, 0, 1, 4]))) == [0, 2, 5, 5, 6, 9]


def test_fault_events_are_checked():
    with pytest.raises(ValueError):
        FaultEvent("meteor", 1.0, 1.0)


@pytest.mark.slow
def test_corruption_and_disconnect_during_a_short_run():
    faults = [("corruption 1 %", FaultEvent("bytes", 5.0, 2.0, {"corrupt_p": 0.01})),
              ("garbage bursts", FaultEvent("bytes", 8.0, 1.5, {"garbage_p": 0.5})),
              ("disconnect", FaultEvent("disconnect", 10.5, 1.5))]
    res = run_campaign([ev for _, ev in faults], 14.0, seed=3, keep_hz=400.0, rss_every_s=5.0)
    assert res["n_exceptions"] == 0, res["exceptions"]
    per = analyse(res, faults)
    tr = res["trace"]
    assert np.any(tr["mode"] != MODE_ACQUIRE), "the loop acquired"
    for f in per:
        assert f["resync_frames"] is not None and f["resync_frames"] <= 2, f
        assert f["valid_fraction_during"] == 1.0, f            # attitude kept (coasting on the gyro)
        assert f.get("bad_frames_accounted", True), f
    assert per[0]["injected"]["mangled"] > 0 and per[0]["frames_good_during"] == 0
    assert per[1]["injected"]["garbage_bursts"] > 0 and per[1]["host_corrupt_frames"] > 0
    assert res["counters"]["head_reconnects"] >= 1
