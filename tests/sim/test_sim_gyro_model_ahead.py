"""The BMI088 register model's samples computed ahead (issue 15: the model's per-sample numpy
work). Truth: the same model fed by the same rates through a source without ``state()``,
which computes every sample when it is due. Every FIFO byte and every interrupt edge must be
the same, whatever the read pattern: one sample per read, bursts after a gap (n > 1 samples
per advance), a FIFO overflow, a range change, a soft reset and an origin that moves."""

import math

import numpy as np
from gyrostar.clock import SimulatedClock
from gyrostar.mocks.bmi088_model import Bmi088GyroModel
from gyrostar.mocks.fake_rates import StreamRates
from gyrostar.mocks.gyro_truth import GyroStream
from gyrostar.mocks.trajectory import Ramp


class _NoState:
    """The same rates, but no ``state()``: the model may not compute ahead."""

    def __init__(self, src):
        self.src = src

    def __call__(self, k, t):
        return self.src(k, t)


def _setup(origin, ahead: bool):
    clk = SimulatedClock(50.0)
    stream = GyroStream(Ramp((0.05, -0.03, 0.02), (0.3, 0.1, -0.2), 0.0, 20.0), "bmi088", seed=3)
    src = StreamRates(stream, lambda: origin[0])
    m = Bmi088GyroModel(clk, src if ahead else _NoState(src))
    m.write(0x0F, bytes([0x01]))          # ±1000 °/s
    m.write(0x10, bytes([0x03]))          # 400 Hz
    m.write(0x3E, bytes([0x80]))          # stream mode
    m.write(0x3D, bytes([1]))
    m.write(0x1E, bytes([0x80]))
    return clk, m


def _drive(ahead: bool):
    origin = [50.0]
    clk, m = _setup(origin, ahead)
    rng = np.random.default_rng(7)
    out = []
    for i in range(3000):
        r = rng.random()
        if r < 0.80:
            dt = 0.0025                   # the loop's one sample per step
        elif r < 0.95:
            dt = 0.0025 * rng.integers(2, 9)    # a late step: several samples in one advance
        else:
            dt = 0.3                      # past the 100-frame FIFO: overflow
        clk.advance(float(dt))
        edge = m.watermark_time()
        level = m.read(0x0E, 1)[0] & 0x7F
        data = m.read(0x3F, 6 * max(level, 1))
        out.append((edge, level, data))
        if i == 1000:
            m.write(0x0F, bytes([0x02]))  # ±500 °/s: another LSB
        if i == 1800:
            origin[0] = 50.37             # the scenario restarts: the rates move in time
        if i == 2400:
            m.write(0x14, bytes([0xB6]))  # soft reset (ODR back to its default)
            clk.advance(0.05)
            m.write(0x10, bytes([0x03]))
            m.write(0x3E, bytes([0x80]))
            m.write(0x3D, bytes([1]))
            m.write(0x1E, bytes([0x80]))
    return out


def test_samples_computed_ahead_are_bit_identical_to_samples_computed_when_due():
    a = _drive(ahead=True)
    b = _drive(ahead=False)
    assert len(a) == len(b)
    for (ea, la, da), (eb, lb, db) in zip(a, b):
        assert la == lb
        assert da == db
        assert (ea is None and eb is None) or ea == eb or (math.isnan(ea) and math.isnan(eb))
    # the pattern really exercised the paths: overflows, multi-sample advances, data moved
    assert any(lvl > 1 for _, lvl, _ in a) and any(lvl >= 99 for _, lvl, _ in a)


def test_a_sample_is_the_same_whatever_the_reads_batch():
    """Sample k is taken at t0 + k·T on the ODR grid, so reading one sample per 2.5 ms or four
    per 10 ms (the loop's FIFO watermark) yields the same FIFO bytes for the same samples, and
    the block computed ahead serves the batched reads too (one source call per AHEAD samples)."""
    from gyrostar.mocks.bmi088_model import AHEAD

    class Counting:
        def __init__(self, src):
            self.src, self.calls = src, 0

        def state(self):
            return self.src.state()

        def __call__(self, k, t):
            self.calls += 1
            return self.src(k, t)

    streams = []
    for every in (1, 4):
        clk, m = _setup([50.0], ahead=True)
        m.source = Counting(m.source)
        got = bytearray()
        for _ in range(800 // every):
            clk.advance(0.0025 * every)
            level = m.read(0x0E, 1)[0] & 0x7F
            got += m.read(0x3F, 6 * level)
        streams.append(bytes(got))
        assert m.source.calls <= 800 // AHEAD + 2, (every, m.source.calls)
    n = min(len(s) for s in streams)
    assert n >= 6 * 790
    assert streams[0][:n] == streams[1][:n]
