"""The loop carries the gyro driver's fault flags into every output and counts them: a stuck
axis (FLAG_GYRO_STUCK within STUCK_RUN frames) and saturation (FLAG_GYRO_SATURATED on exactly
the saturated samples). Gyro: BMI088 register model on a simulated clock; the head is a
stand-in that never finishes a job (the gyro path must not depend on it)."""

import math
import sys
from pathlib import Path

import numpy as np
from gyrostar.camera import camera_preset
from gyrostar.gyro.convert import STUCK_RUN
from gyrostar.loop import record as R
from gyrostar.loop.coupled import CoupledLoop, LoopParams
from gyrostar.loop.sinks import CallbackSink
from gyrostar.mocks.fake_rates import ProfileRates

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "reliability"))
from test_rel_gyro_faults import StuckAxis, make  # noqa: E402

DPS = math.pi / 180


class SilentHead:
    """Accepts jobs and never answers (a head that is busy forever)."""

    busy = False
    jobs = 0

    def start(self, exposure_s):
        pass

    def poll(self):
        return None

    def submit_frame(self, post=None):
        self.jobs += 1

    def submit_windows(self, spans):
        self.jobs += 1


def run_loop(source, range_dps, seconds):
    clock, model, bus, gyro = make(source, range_dps=range_dps)
    chunks = []
    loop = CoupledLoop(LoopParams(), clock, gyro, SilentHead(), camera_preset("xing2012"), None, None,
                       [CallbackSink(lambda recs: chunks.append(recs.copy()))])
    t_end = clock.now() + seconds
    while clock.now() < t_end:
        clock.advance(0.0025)
        loop.step()
    loop.close()
    return model, np.concatenate(chunks), loop.counters()


def test_stuck_axis_reaches_the_outputs():
    src = StuckAxis(ProfileRates(seed=6), axis=1, t_stuck=14.0)
    model, out, c = run_loop(src, 2000, 8.0)
    healthy = out["t"] < 14.0
    assert np.count_nonzero(healthy) > 1000
    assert not np.any(out["flags"][healthy] & R.FLAG_GYRO_STUCK), "no false stuck flags on a live gyro"
    stuck = np.flatnonzero(~healthy)
    flagged = stuck[(out["flags"][stuck] & R.FLAG_GYRO_STUCK) != 0]
    assert len(flagged) and flagged[0] - stuck[0] <= STUCK_RUN + 1
    assert np.all(out["flags"][flagged[0]:] & R.FLAG_GYRO_STUCK)
    assert c["gyro_stuck"] == len(flagged) and c["gyro_saturated"] == 0


def test_saturation_reaches_the_outputs_and_is_counted():
    src = ProfileRates(mean_dps=(400.0, 0.0, 0.0), amp_dps=(300.0, 10.0, 10.0), seed=2)
    model, out, c = run_loop(src, 500, 3.0)
    truth = model.popped_indices()
    over = np.abs(src(truth, model.sample_time(truth))[:, 0]) >= 32767.5 * 500 / 32768 * DPS
    assert len(out) == len(truth) and over.sum() > 100
    assert np.array_equal((out["flags"] & R.FLAG_GYRO_SATURATED) != 0, over)
    assert c["gyro_saturated"] == int(over.sum()) and c["gyro_stuck"] == 0
