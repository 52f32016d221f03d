"""A gyro that resets silently mid-run (issue 18): the loop's counters show the register fault
once, the outputs flag the gap (FLAG_GYRO_GAP) and ``samples_lost`` counts it, and the gyro
delivers again at its configured range. Gyro: BMI088 register model on a simulated clock."""

import sys
from pathlib import Path

import numpy as np
from gyrostar.camera import camera_preset
from gyrostar.loop import record as R
from gyrostar.loop.coupled import CoupledLoop, LoopParams
from gyrostar.loop.sinks import CallbackSink
from gyrostar.mocks.fake_rates import ProfileRates

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "reliability"))
from test_loop_gyro_flags import SilentHead  # noqa: E402
from test_rel_gyro_faults import make  # noqa: E402


def test_silent_gyro_reset_is_counted_flagged_and_repaired():
    src = ProfileRates(seed=4)
    clock, model, bus, gyro = make(src, range_dps=500)
    chunks = []
    loop = CoupledLoop(LoopParams(), clock, gyro, SilentHead(), camera_preset("xing2012"), None, None,
                       [CallbackSink(lambda recs: chunks.append(recs.copy()))])
    t_glitch = clock.now() + 1.5
    glitched = False
    t_end = clock.now() + 3.0
    while clock.now() < t_end:
        clock.advance(0.0025)
        if not glitched and clock.now() >= t_glitch:
            model.brownout()
            glitched = True
        loop.step()
    loop.close()
    out = np.concatenate(chunks)
    c = loop.counters()
    assert c["gyro_register_faults"] == 1
    assert model.regs[0x0F] == 0x02 and model.regs[0x3E] == 0x80   # ±500 °/s and stream mode again
    gap = np.flatnonzero(out["flags"] & R.FLAG_GYRO_GAP)
    assert len(gap) == 1 and abs(out["t"][gap[0]] - t_glitch) < 0.1
    dt = out["t"][gap[0]] - out["t"][gap[0] - 1]
    assert c["gyro_gaps"] == 1 and abs(c["samples_lost"] - (dt * 400 - 1)) <= 1
    after = out["t"] > t_glitch + 0.2
    assert np.count_nonzero(after) > 0.95 * 400 * (t_end - t_glitch - 0.2)
