"""HIL scenarios end to end through the devices, each followed by a bit-exact replay.

Every scenario runs the whole flatsat (gyro register bus, head link, loop, recorder) in
real time and is checked against the simulator's truth; then ``gyrostar replay`` feeds
the log back through the same driver and must reproduce every output byte. On a flatsat
with real devices (``--flatsat bench.toml``) only :func:`test_bench_without_truth` runs: it
checks what a run can show about itself (the head must see a star field).
"""

from __future__ import annotations

import numpy as np
import pytest
from gyrostar.hil import config as hc
from gyrostar.hil.replay import load_log, replay
from gyrostar.hil.runner import run_flatsat
from gyrostar.loop import record as R

pytestmark = pytest.mark.hil

ARCSEC_TRACK_MAX = 12.0   # 1σ cross-boresight while tracking (BMI088-class gyro noise: ~4–6″)


def _run(cfg, name, folder, needs_truth=True, duration=None):
    scen = hc.load_scenario(name)
    if needs_truth and not cfg.simulated:
        pytest.skip("checked against the simulator's truth: needs the simulated devices")
    res = run_flatsat(cfg, scen, duration=duration or scen.duration_s, seed=3, folder=folder, plots=False,
                      status=False)
    log = load_log(res["log"])
    return scen, res, log


def _check_replay(res):
    rep = replay(res["log"])
    assert rep["bit_exact"], rep
    assert rep["replayed_outputs"] == rep["recorded_outputs"] > 0


@pytest.mark.parametrize("name", ["sim1", "sim2", "sim3", "sim4", "slew10"])
def test_paper_sims_and_slew(flatsat_config, run_dir, name):
    scen, res, log = _run(flatsat_config, name, run_dir)
    out = log["outputs"]
    assert res["samples_lost"] == 0
    assert res["track_fraction"] >= scen.min_track_fraction, res["mode_seconds"]
    assert res["attitude_error_arcsec_1sigma"] is not None
    assert res["attitude_error_arcsec_1sigma"] <= ARCSEC_TRACK_MAX, res
    # tracking holds through the fastest part of the profile (last second of the slew)
    rates = np.degrees(np.linalg.norm(log["truth"]["omega"], axis=1))
    fast = rates >= 0.9 * rates.max()
    if rates.max() > 1.0:
        assert np.mean(out["mode"][fast] == R.MODE_TRACK) > 0.8
    # the drift estimate moved from 0 towards the simulator's truth (paper 000: 0.02 °/s per
    # axis) and agrees with it within 4σ of the filter's own covariance (angle random walk
    # limits it to ~N/√T: 0.007 °/s after 4 s of tracking with N = 0.014 °/s/√Hz)
    err = np.abs(res["bias_error_dps_final"])
    sig = np.degrees(np.sqrt(np.diag(out["cov"][-1])[3:]))
    assert np.all(err <= 4.0 * sig + 1e-4), (err, sig)
    assert np.max(err) < 0.6 * 0.02 * np.sqrt(3)
    _check_replay(res)


def test_eclipse_coasts_and_recovers(flatsat_config, run_dir):
    from gyrostar.hil.analysis import ARCSEC, attitude_errors

    scen, res, log = _run(flatsat_config, "eclipse", run_dir)
    out = log["outputs"]
    a, b = scen.eclipse[0]
    t = out["t"] - log["t0"]
    dark = (t > a + 0.3) & (t < b)
    assert np.all(out["mode"][dark] == R.MODE_COAST), np.unique(out["mode"][dark])
    assert np.all(out["flags"][dark] & R.FLAG_FEW_STARS)
    assert np.all(out["flags"][dark] & R.FLAG_ATTITUDE_VALID)
    # the gyro-only attitude stays consistent with the filter's own covariance (4σ)
    err = attitude_errors(out, log["truth"])
    end = np.flatnonzero(dark)[-1]
    sig = np.sqrt(np.max(np.diag(out["cov"][end])[:3]))
    assert np.hypot(err[end, 0], err[end, 1]) <= 4.0 * np.sqrt(2.0) * sig, (err[end] * ARCSEC, sig * ARCSEC)
    # TRACK again after the eclipse (windows re-find the stars, or a re-acquisition)
    back = np.flatnonzero((t > b) & (out["mode"] == R.MODE_TRACK))
    assert len(back) and t[back[0]] < b + scen_coast_timeout(flatsat_config) + 2.0
    assert np.all(out["mode"][t > t[-1] - 1.0] == R.MODE_TRACK)
    _check_replay(res)


def scen_coast_timeout(cfg) -> float:
    return cfg.loop.coast_timeout_s


def test_head_disconnect_and_reconnect(flatsat_config, run_dir):
    scen, res, log = _run(flatsat_config, "disconnect", run_dir)
    out = log["outputs"]
    f = scen.faults[0]
    t = out["t"] - log["t0"]
    assert res["counters"]["head_reconnects"] >= 1
    lost = (out["flags"] & R.FLAG_HEAD_LOST) != 0
    assert lost.any() and not lost[t > f.at_s + f.seconds + 1.5].any()
    assert np.all(out["mode"][(t > f.at_s + 0.6) & (t < f.at_s + f.seconds)] != R.MODE_TRACK)
    assert np.mean(out["mode"][t > f.at_s + f.seconds + 1.5] == R.MODE_TRACK) > 0.9
    assert res["samples_lost"] == 0          # the gyro path never stopped
    _check_replay(res)


def test_gyro_fifo_overrun_is_flagged(flatsat_config, run_dir):
    scen, res, log = _run(flatsat_config, "fifo_overrun", run_dir)
    out = log["outputs"]
    f = scen.faults[0]
    lost_expected = f.seconds * flatsat_config.gyro.odr_hz - 100      # FIFO holds 100 frames
    assert res["samples_lost"] >= 0.8 * lost_expected, res["samples_lost"]
    assert res["counters"]["gyro_gaps"] >= 1
    gap = np.flatnonzero(out["flags"] & R.FLAG_GYRO_GAP)
    assert len(gap) >= 1
    t = out["t"] - log["t0"]
    # flagged on the oldest frame the FIFO still held when the loop resumed (it keeps 100)
    assert abs(t[gap[0]] - (f.at_s + f.seconds - 100 / flatsat_config.gyro.odr_hz)) < 0.05
    assert np.mean(out["mode"][t > f.at_s + f.seconds + 1.0] == R.MODE_TRACK) > 0.75
    _check_replay(res)


def test_link_corruption_counted_and_tracking_kept(flatsat_config, run_dir):
    scen, res, log = _run(flatsat_config, "corruption", run_dir)
    assert res["link"]["corrupt"] + res["counters"]["frames_failed"] > 0
    assert res["track_fraction"] >= scen.min_track_fraction
    assert res["samples_lost"] == 0
    _check_replay(res)


def test_bench_without_truth(flatsat_config, run_dir):
    """Any devices, no truth: continuity, gyro rate, tracking, covariance sanity, replay."""
    duration = 20.0 if flatsat_config.simulated else 30.0
    scen, res, log = _run(flatsat_config, "bench", run_dir, needs_truth=False, duration=duration)
    out = log["outputs"]
    h = res["health"]
    assert res["samples_lost"] == 0 and h["output_seq_gaps"] == 0
    assert np.all(np.diff(out["t"]) > 0)
    odr = flatsat_config.gyro.odr_hz
    assert abs(res["gyro_samples"] / (odr * duration) - 1.0) < 0.02       # the gyro keeps its rate
    assert h["track_fraction"] >= 0.8 and h["stars_tracked_median"] >= flatsat_config.loop.min_stars
    assert h["frames_hz"] > 0.3 * flatsat_config.loop.frame_hz
    tr = out["mode"] == R.MODE_TRACK
    cov = out["cov"][tr]
    assert np.allclose(cov, np.transpose(cov, (0, 2, 1)), rtol=0, atol=1e-18)
    assert np.all(np.linalg.eigvalsh(cov[:, :3, :3])[:, 0] > 0)
    # at rest the 3σ attitude bound holds a few arcsec to tens of arcsec, not degrees
    assert 0 < h["attitude_3sigma_arcsec_cross_median"] < 120.0
    _check_replay(res)


def test_head_clock_steps_keep_tracking(flatsat_config, run_dir):
    """The head MCU's clock jumps 3 s ahead and 1.5 s back with the link open: each jump
    costs the frames stamped outside their arrival, a TIME_SYNC restarts the clock model,
    and the loop tracks on with its mid-exposure times on the new clock — coasting, and saying
    so, only while no frame is used (≤ 0.1 s a jump: on a 921.6 kBd UART the resynchronising
    exchanges share the wire with the frames, 80 ms without a used frame). In request mode
    (``head.mode = "request"``) the capture after a jump is re-timed inside its job; one
    whose exposure straddles the jump is lost, a frame period of COAST at most."""
    if flatsat_config.head.kind != "emulator":
        pytest.skip("the clock step is the head emulator's (the firmware host program keeps its own clock)")
    scen, res, log = _run(flatsat_config, "clock_step", run_dir)
    out = log["outputs"]
    t = out["t"] - log["t0"]
    assert res["link"]["clock_steps"] == 2 and res["counters"]["head_reconnects"] == 0
    if "stream" in res:     # the frames stamped outside their arrival are not used
        assert 1 <= res["stream"]["unmatched_why"].get("clock", 0) <= 4
    changes = [(round(tc - log["t0"], 3), a, b) for tc, a, b in res["counters"]["mode_changes"]]
    track = out["mode"][t > 2.0] == R.MODE_TRACK
    if "stream" in res:
        assert np.sum(~track) / flatsat_config.gyro.odr_hz <= 0.1 * len(scen.faults), changes
    else:   # request mode: a capture that straddles a step has no host time, one frame lost
        assert res["counters"]["frames_failed"] <= len(scen.faults), res["counters"]
        assert np.sum(~track) / flatsat_config.gyro.odr_hz <= 0.05 * len(scen.faults), changes
    assert res["attitude_error_arcsec_1sigma"] <= ARCSEC_TRACK_MAX, res
    for f in scen.faults:
        mid = out[(t > f.at_s + 0.5) & (t < f.at_s + 1.5) & np.isfinite(out["t_mid"])]
        assert len(mid) and np.all((mid["t"] - mid["t_mid"] > 0.0) & (mid["t"] - mid["t_mid"] < 0.1))
    assert res["samples_lost"] == 0
    _check_replay(res)


def test_head_clock_steps_of_a_few_ms_are_found(flatsat_config, run_dir):
    """The clock_step_small scenario: the head MCU's clock steps 8 ms back and 5 ms ahead
    during a 3 °/s slew. Both are found by the clock model's hard bounds (a fixed 20 ms test
    missed them: 12.6″ and 242 frames refused on usb-hs), and the attitude stays within 1.3×
    its floor (3.2″ against 3.5″ on usb-hs, 4.9″ against 4.7″ on uart-921k)."""
    if flatsat_config.head.kind != "emulator":
        pytest.skip("the clock step is the head emulator's (the firmware host program keeps its own clock)")
    scen, res, log = _run(flatsat_config, "clock_step_small", run_dir, duration=18.0)
    assert res["link"]["clock_steps"] == 2 and res["counters"]["head_reconnects"] == 0
    assert res["attitude_error_arcsec_1sigma"] <= 1.3 * res["floor_arcsec"], res
    assert res["samples_lost"] == 0
