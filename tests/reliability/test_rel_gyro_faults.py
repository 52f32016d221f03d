"""Gyro faults against the BMI088 driver and register model (simulated clock): NACK bursts,
FIFO overruns, a stuck axis, saturation — each flagged, counted, and any gap bounded.

Truth: the model logs the global index of every frame it delivers (``popped_indices``), so
lost frames and their positions are known exactly; the rate source says what each axis did.
"""

import math

import numpy as np
from gyrostar.clock import SimulatedClock
from gyrostar.errors import DeviceError
from gyrostar.gyro import FLAG_GAP, FLAG_SAT_X, FLAG_SATURATED, FLAG_STUCK_AXIS, Bmi088Gyro, GyroSamples, bmi088
from gyrostar.gyro.convert import STUCK_RUN
from gyrostar.mocks.bmi088_model import FIFO_FRAMES, Bmi088GyroModel
from gyrostar.mocks.fake_rates import ProfileRates
from gyrostar.mocks.faults import FaultyBus
from gyrostar.transport import I2CBus, I2CRegisters

DPS = math.pi / 180


def make(source, range_dps=2000, seed=0):
    clock = SimulatedClock(10.0)
    model = Bmi088GyroModel(clock, source, odr_error_ppm=800.0)
    bus = FaultyBus(model.smbus(), clock=clock, seed=seed)
    gyro = Bmi088Gyro(I2CRegisters(I2CBus(bus, name="i2c-sim"), 0x68), clock=clock)
    gyro.configure(400, range_dps, 10)
    gyro.start()
    return clock, model, bus, gyro


def poll(clock, model, gyro, out, seconds, dt=0.025):
    """Read every ``dt`` like the loop does; returns the number of failed reads."""
    failed = 0
    t_end = clock.now() + seconds
    while clock.now() < t_end:
        clock.advance(dt)
        try:
            gyro.read(out, event_time=model.watermark_time())
        except DeviceError:
            failed += 1
    return failed


def gaps_of(model, out):
    """(row, frames lost) for every jump in the delivered indices, and the flagged rows."""
    truth = model.popped_indices()
    jumps = np.diff(truth)
    rows = np.flatnonzero(jumps != 1) + 1
    flagged = np.flatnonzero(out.flags[:out.n] & FLAG_GAP)
    return rows, jumps[rows - 1] - 1, flagged


def test_nack_bursts_flagged_counted_bounded():
    rng = np.random.default_rng(5)
    clock, model, bus, gyro = make(ProfileRates(seed=3))
    out = GyroSamples(20000)
    failed = poll(clock, model, gyro, out, 1.0)
    windows = []
    for _ in range(12):                       # NACK windows of 5 ms … 0.6 s, then 1 s clean
        w = float(rng.uniform(0.005, 0.6))
        bus.nack_between(clock.now(), clock.now() + w)
        windows.append(w)
        failed += poll(clock, model, gyro, out, w + 1.0)
    rows, lost, flagged = gaps_of(model, out)
    assert failed >= len(windows) and bus.injected["nack"] == failed    # every failed read raised, none silent
    assert set(rows) == set(flagged), "every loss is flagged, nothing else"
    assert out.gap_frames == int(lost.sum()) and out.gaps == len(rows)  # counted exactly
    # bounded: a window shorter than the FIFO (100 frames = 0.25 s) loses nothing; a longer
    # one loses at most the frames produced beyond the FIFO's capacity (plus one read period)
    long_frames = [w * 400 for w in windows if w * 400 > FIFO_FRAMES - 10]
    assert len(rows) <= 2 * len(long_frames)
    assert lost.sum() <= sum(f - FIFO_FRAMES + 0.025 * 400 * 2 + 20 for f in long_frames)
    idx = model.popped_indices()
    assert idx[-1] - idx[0] + 1 - out.n == out.gap_frames   # everything else delivered


def test_fifo_overrun_gap_bounded_by_the_stall():
    rng = np.random.default_rng(8)
    clock, model, bus, gyro = make(ProfileRates(seed=4))
    out = GyroSamples(20000)
    poll(clock, model, gyro, out, 1.0)
    stalls = []
    for _ in range(10):
        s = float(rng.uniform(0.1, 1.0))       # the loop does not read the FIFO for s seconds
        clock.advance(s)
        stalls.append(s)
        poll(clock, model, gyro, out, 0.5)
    rows, lost, flagged = gaps_of(model, out)
    assert set(rows) == set(flagged) and out.gap_frames == int(lost.sum())
    overflowing = [s for s in stalls if (s + 0.025) * 400 > FIFO_FRAMES]
    assert 1 <= len(rows) <= 2 * len(overflowing)
    assert lost.max() <= max(overflowing) * 400 + 10 * 2 + 12 - FIFO_FRAMES + 20
    # samples after a gap are timed from the time model: within a tenth of a period
    t_true = model.sample_time(model.popped_indices())
    assert np.max(np.abs(out.t[:out.n] - t_true)[200:]) < 0.1 / 400


class StuckAxis:
    """The wrapped source, with one axis frozen at its value at ``t_stuck`` from then on."""

    def __init__(self, src, axis, t_stuck):
        self.src, self.axis, self.t_stuck, self.value = src, axis, t_stuck, None

    def __call__(self, k, t):
        r = np.array(self.src(k, t), float)
        m = np.asarray(t) >= self.t_stuck
        if m.any():
            if self.value is None:
                self.value = r[np.argmax(m), self.axis]
            r[m, self.axis] = self.value
        return r


def test_stuck_axis_flagged_within_stuck_run_and_counted():
    src = StuckAxis(ProfileRates(seed=6), axis=1, t_stuck=18.0)   # model time (clock starts at 10 s)
    clock, model, bus, gyro = make(src, range_dps=2000)           # smallest noise in LSB: the hardest case
    out = GyroSamples(20000)
    poll(clock, model, gyro, out, 16.0)
    _, _, _, flags = out.view()
    t_true = model.sample_time(model.popped_indices())
    healthy = t_true < 18.0
    assert np.count_nonzero(healthy) > 3000
    assert not np.any(flags[healthy] & FLAG_STUCK_AXIS), "no false stuck flags on a live gyro"
    stuck = np.flatnonzero(~healthy)
    first = stuck[np.argmax(flags[stuck] & FLAG_STUCK_AXIS != 0)]
    assert flags[first] & FLAG_STUCK_AXIS
    assert first - stuck[0] <= STUCK_RUN + 1, "detected within STUCK_RUN frames"
    assert np.all(flags[first:] & FLAG_STUCK_AXIS), "stays flagged while stuck"
    assert out.stuck_axis == np.count_nonzero(flags & FLAG_STUCK_AXIS)


def test_saturation_flagged_counted_not_stuck():
    src = ProfileRates(mean_dps=(400.0, 0.0, 0.0), amp_dps=(300.0, 10.0, 10.0), seed=2)
    clock, model, bus, gyro = make(src, range_dps=500)
    out = GyroSamples(4000)
    poll(clock, model, gyro, out, 4.0)
    _, _, rate, flags = out.view()
    truth = model.popped_indices()
    over = np.abs(src(truth, model.sample_time(truth))[:, 0]) >= 32767.5 * 500 / 32768 * DPS
    assert over.sum() > STUCK_RUN * 4                      # long saturated stretches
    assert np.array_equal((flags & FLAG_SAT_X) != 0, over)
    assert out.saturated == np.count_nonzero(flags & FLAG_SATURATED)
    assert not np.any(flags & FLAG_STUCK_AXIS), "a pinned axis is saturation, not a stuck axis"
    assert np.all(np.abs(rate[over, 0]) <= 500 * DPS * 1.0001)   # the output never exceeds the range


def test_spi_registers_helper_still_constructs():
    assert bmi088.spi_registers(object()).describe()
