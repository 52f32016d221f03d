"""Link faults during a short run of the coupled loop on the simulated flatsat (the 30 s
campaign is ``python -m gyrostar.hil.reliability.linkfaults``): the loop never raises, coasts on
the gyro with a valid attitude, gets a good frame back within 2 frames, counts bad frames."""

import numpy as np
import pytest
from gyrostar.hil.config import Fault
from gyrostar.hil.reliability.campaign import run_campaign
from gyrostar.hil.reliability.linkfaults import analyse, cumulative
from gyrostar.loop.record import MODE_ACQUIRE


def test_cum_counter_survives_client_restart():
    assert list(cumulative(np.array([0, 2, 5, 0, 1, 4]))) == [0, 2, 5, 5, 6, 9]


def test_campaign_faults_are_checked():
    """The campaign's faults are the scenario's, checked the same way before anything runs."""
    for bad, what in ((Fault("meteor", 1.0, 1.0), "kind"), (Fault("head-clock-step", 1.0), "step_s"),
                      (Fault("head-clock-step", 1.0, step_s=0.0005), "step_s"),
                      (Fault("head-clock-step", 1.0, step_s=float("nan")), "step_s"),
                      (Fault("link-corruption", 1.0, 1.0, rate=0.0), "injects nothing"),
                      (Fault("link-corruption", 1.0, 1.0, garbage_rate=1.5), "garbage_rate"),
                      (Fault("gyro-nack", 1.0, 0.0), "seconds")):
        with pytest.raises(ValueError, match=what):
            run_campaign([bad], 1.0)


@pytest.mark.slow
def test_head_clock_steps_during_a_short_run():
    """The soak's clock-step fault: the head emulator (its own process) jumps its MCU clock
    3 s ahead at 4 s and 1.5 s back at 7 s, the link open. The clock model finds both steps,
    the loop never raises and stays in TRACK across them, on the simulator's attitude."""
    from gyrostar.hil.reliability.campaign import cross_boresight_error_arcsec
    from gyrostar.loop.record import MODE_TRACK

    steps = [Fault("head-clock-step", 4.0, step_s=3.0), Fault("head-clock-step", 7.0, step_s=-1.5)]
    res = run_campaign(steps, 10.0, seed=3, keep_hz=400.0, rss_every_s=5.0)
    assert res["n_exceptions"] == 0, res["exceptions"]
    tr = res["trace"]
    t = tr["t"] - res["t_origin"]
    assert int(cumulative(tr["link_clock_steps"])[-1]) == 2
    around = (t > 3.0) & (t < 9.5)
    assert np.all(tr["mode"][around] == MODE_TRACK) and res["counters"]["head_reconnects"] == 0
    err = cross_boresight_error_arcsec(tr, res["truth"])[around]
    print(f"error in TRACK around the steps: median {np.median(err):.2f}″, p99 {np.percentile(err, 99):.2f}″")
    assert np.all(np.isfinite(err)) and np.percentile(err, 99) < 30.0     # ~5″ median, as without steps


@pytest.mark.slow
def test_corruption_and_disconnect_during_a_short_run():
    faults = [("corruption 1 %", Fault("link-corruption", 5.0, 2.0, rate=0.01)),
              ("garbage bursts", Fault("link-corruption", 8.0, 1.5, rate=0.0, garbage_rate=0.5)),
              ("disconnect", Fault("head-disconnect", 10.5, 1.5))]
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
