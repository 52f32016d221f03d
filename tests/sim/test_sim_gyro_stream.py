"""The simulated gyro for runs of any length (issue 18: a run longer than the scenario + 60 s
got a frozen gyro that repeated its last sample).

Truth: the datasheet noise density (0.014 °/s/√Hz) through the sensor's 47 Hz Butterworth
(noise bandwidth computed from the filter's own impulse response), the LSB at the range the
driver sets, and :func:`simulate_gyro` (the fixed-span generator) for the first chunk.
"""

import math

import numpy as np
from gyrostar.clock import SimulatedClock
from gyrostar.gyro import FLAG_GAP, FLAG_STUCK_AXIS, Bmi088Gyro, GyroSamples
from gyrostar.hil import config as hc
from gyrostar.hil.flatsat import simulated_gyro
from gyrostar.mocks import gyro_truth as gt
from gyrostar.mocks.bmi088_model import Bmi088GyroModel
from gyrostar.mocks.fake_rates import StreamRates
from gyrostar.mocks.trajectory import Ramp
from gyrostar.transport import I2CBus, I2CRegisters

DEG = math.pi / 180


def expected_sigma_dps(p, range_dps):
    """Rate noise σ (°/s) per output sample: density² × the filter's noise bandwidth, plus
    the quantisation of the range's LSB."""
    b, a = gt.butterworth2(p.filter_hz, p.internal_hz)
    h = np.zeros(20000)
    x1 = x2 = y1 = y2 = 0.0
    for n in range(len(h)):   # impulse response of the biquad
        x = 1.0 if n == 0 else 0.0
        y = b[0] * x + b[1] * x1 + b[2] * x2 - a[1] * y1 - a[2] * y2
        x2, x1, y2, y1 = x1, x, y1, y
        h[n] = y
    enbw_hz = p.internal_hz / 2.0 * np.sum(h * h)
    lsb = range_dps / 32768.0
    return math.sqrt(p.noise_density_dps_rthz ** 2 * enbw_hz + lsb ** 2 / 12.0)


def test_flatsat_gyro_past_scenario_plus_60s_is_fresh_and_keeps_its_noise():
    cfg = hc.load_flatsat()
    scen = hc.load_scenario("sim2")      # 5 s at a constant 0.01 °/s per axis
    stream = simulated_gyro(cfg, scen, seed=3)
    clock = SimulatedClock(100.0)
    t_origin = clock.now()
    model = Bmi088GyroModel(clock, StreamRates(stream, lambda: t_origin))
    model.truth_log = False
    gyro = Bmi088Gyro(I2CRegisters(I2CBus(model.smbus(), name="sim"), 0x68), clock=clock)
    gyro.configure(odr_hz=cfg.gyro.odr_hz, range_dps=cfg.gyro.range_dps, watermark=10)
    gyro.start()
    run_s = scen.duration_s + 80.0       # 20 s past the old end of the precomputed truth
    out = GyroSamples(int(run_s * 400) + 1000)
    while clock.now() - t_origin < run_s:
        clock.advance(0.025)
        gyro.read(out, event_time=model.watermark_time())
    t, _, rate, flags = out.view()
    assert out.n > 0.99 * run_s * 400 and not np.any(flags & FLAG_GAP)
    assert not np.any(flags & FLAG_STUCK_AXIS), "no axis repeats itself (the frozen gyro did, 60 s in)"
    ts = t - t_origin
    sigma = expected_sigma_dps(stream.params, cfg.gyro.range_dps)
    bias_dps = np.asarray(stream.params.bias_dps)
    true_dps = np.asarray(scen.segments[0].rate_dps)
    for lo, hi in ((1.0, scen.duration_s), (scen.duration_s + 62.0, run_s)):
        sel = (ts > lo) & (ts < hi)
        err = np.degrees(rate[sel]) - true_dps
        assert np.all(np.abs(err.mean(axis=0) - bias_dps) < 0.01), (lo, err.mean(axis=0))
        assert np.all(np.abs(err.std(axis=0) / sigma - 1.0) < 0.1), (lo, err.std(axis=0), sigma)
        assert len(np.unique(np.round(np.degrees(rate[sel, 0]) / (cfg.gyro.range_dps / 32768.0)))) > 20


def test_stream_is_a_pure_function_of_the_seed_and_matches_simulate_gyro():
    prof = Ramp((0.0, 0.0, 0.0), (0.2, -0.1, 0.05), 0.0, 30.0, 40.0)
    p = gt.gyro_params("bmi088")
    whole = gt.simulate_gyro(prof, 5.0, p, seed=11)
    a = gt.GyroStream(prof, p, seed=11, chunk=1000, cache_chunks=2)
    n = len(whole.t)
    assert np.array_equal(a.meas(np.arange(1000)), whole.omega_meas[:1000])   # first chunk: the same draws
    assert np.array_equal(a.bias(np.arange(1000)), whole.bias[:1000])
    late = np.arange(20000, 20500)
    b = gt.GyroStream(prof, p, seed=11, chunk=1000, cache_chunks=2)
    got_b = b.meas(late)                  # asked for first: chunks 0..20 generated in order
    got_a = a.meas(late)
    assert np.array_equal(got_a, got_b)
    early_again = a.meas(np.arange(1500, 2500))   # evicted from the 2-chunk cache: regenerated
    fresh = gt.GyroStream(prof, p, seed=11, chunk=1000).meas(np.arange(1500, 2500))
    assert np.array_equal(early_again, fresh)
    assert not np.array_equal(gt.GyroStream(prof, p, seed=12, chunk=1000).meas(late), got_a)
    # chunk boundaries are seamless: the biases carry over (GM τ 100 s, RRW), no jump
    bias = a.bias(np.arange(0, 25000))
    step = np.abs(np.diff(bias, axis=0))
    boundary = np.arange(999, 24000, 1000)
    assert step[boundary].max() < 5 * np.percentile(step, 99.9)
    assert n == 2000


def test_sample_content_is_the_rate_at_its_own_instant_whatever_the_clock_phase():
    """On a rate ramp a 2nd-order low-pass reports a·(t − τ), τ its DC group delay (datasheet
    47 Hz at 1600 Hz internal: √2/(2π·47) ≈ 4.8 ms). A sample the register model takes at time
    t, between two of the stream's 2.5 ms output instants, must report that value at t itself:
    nearest-sample content would be up to 1.25 ms (a·1.25 ms) off, a timing error no real part has."""
    p = gt.gyro_params("bmi088", bias_sigma_dps=0.0, bias_instability_dph=0.0, rrw_dps_per_rts=0.0,
                       noise_density_dps_rthz=0.0, scale_factor_sigma_ppm=0.0, misalignment_sigma_mrad=0.0,
                       range_dps=0.0)
    slope = 10.0 * DEG                                    # rad/s²
    stream = gt.GyroStream(Ramp((0.0, 0.0, 0.0), (slope * 20.0, 0.0, 0.0), 0.0, 20.0), p, seed=1)
    b, a = gt.butterworth2(p.filter_hz, p.internal_hz)
    k = np.arange(3)
    tau = ((k * b).sum() / b.sum() - (k * a).sum() / a.sum()) / p.internal_hz
    assert abs(tau - math.sqrt(2) / (2 * math.pi * 47.0)) < 2e-4
    for phase in (0.0, 0.2, 0.37, 0.5, 0.81):
        t = 2.0 + (np.arange(400) + phase) / p.odr_hz       # model sample instants off the stream's grid
        got = StreamRates(stream, lambda: 0.0)(np.arange(400), t)[:, 0]
        err_dps = np.degrees(got - slope * (t - tau))
        assert np.max(np.abs(err_dps)) < 1e-3, (phase, np.max(np.abs(err_dps)))
    # on the grid: the same value as the stream's own sample
    i = np.arange(800, 900)
    assert np.allclose(stream.meas_at(i.astype(float)), stream.meas(i), atol=1e-12)
