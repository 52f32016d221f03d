"""Truth-free run figures (hil.health) against hand-built output records."""

import numpy as np
import pytest
from gyrostar.hil.health import health, plot_overview
from gyrostar.loop import record as R


def test_health_figures_from_outputs_alone(tmp_path):
    n = 800                                            # 2 s at 400 Hz
    out = R.empty(n)
    out["t"] = 100.0 + np.arange(n) / 400.0
    out["seq"] = np.arange(n)
    out["seq"][500:] += 3                              # three outputs lost
    out["mode"][:200] = R.MODE_ACQUIRE
    out["mode"][200:600] = R.MODE_TRACK
    out["mode"][600:] = R.MODE_COAST
    out["flags"][200:] = R.FLAG_ATTITUDE_VALID
    out["flags"][300:310] |= R.FLAG_LINK_ERROR
    out["n_stars"][200:600] = 9
    out["omega"][:, 2] = np.radians(2.0)               # 2 °/s about z
    sig_att = np.radians(5.0 / 3600.0)                 # 5″ 1σ per axis
    sig_b = np.radians(0.01)                           # 0.01 °/s
    out["cov"][:] = np.diag([sig_att ** 2] * 3 + [sig_b ** 2] * 3)
    out["bias"][-1] = np.radians([0.1, -0.2, 0.3])
    h = health(out, 400.0, counters={"frames": 150, "frames_failed": 2}, link={"corrupt": 4, "retries": 1})
    assert h["track_fraction"] == pytest.approx(0.5)
    assert h["mode_timeline"] == [[0.0, 0.4975, "ACQUIRE"], [0.5, 1.4975, "TRACK"], [1.5, 1.9975, "COAST"]]
    assert h["mode_switches"] == 2 and h["output_seq_gaps"] == 1
    assert h["stars_tracked_median"] == 9 and h["stars_tracked_min_in_track"] == 9
    assert h["rate_dps_max"] == pytest.approx(2.0)
    assert h["attitude_3sigma_arcsec_cross_median"] == pytest.approx(15.0)
    assert h["bias_3sigma_dps_final"] == pytest.approx([0.03] * 3)
    assert h["bias_estimate_dps_final"] == pytest.approx([0.1, -0.2, 0.3])
    assert h["frames_hz"] == pytest.approx(75.0) and h["link_error_outputs"] == 10 and h["link_corrupt_frames"] == 4
    assert plot_overview(tmp_path, out).stat().st_size > 10_000
