"""Star-identification safety (small version of ``python -m gyrostar.hil.reliability.starid_safety``):
false stars and magnitude noise through the tracker never give a wrong attitude."""

from gyrostar.hil.reliability.starid_safety import WRONG_BORESIGHT_PX, run


def test_false_stars_never_give_a_wrong_attitude():
    r = run(trials=300, seed=11)
    assert r["wrong_attitudes"] == 0 and r["outputs_with_wrong_ids"] == 0
    assert r["output_fraction"] > 0.4                       # the identifiers did answer
    assert r["by_false_stars"][5]["outputs"] > 0           # including with 5 false stars
    assert r["boresight_err_arcsec_max"] < r["wrong_boresight_threshold_arcsec"] / WRONG_BORESIGHT_PX * 3
    assert r["tracker_counts"]["tracked"] > 0 and r["tracker_counts"]["acquired"] > 0


class _Stub:
    """An identifier returning a fixed result (counts its calls)."""

    def __init__(self, n_ids, ok=True):
        import numpy as np
        from gyrostar.starid.result import StarIdResult

        idx = np.array([0] * n_ids + [-1] * 2)
        self.result = StarIdResult(idx, idx, np.array([0.0, 0.0, 0.0, 1.0]), ok, "ok" if ok else "x", 0.0, "stub")
        self.calls = 0

    def identify(self, uv, q_pred=None):
        self.calls += 1
        return self.result


def test_tracking_result_with_three_stars_goes_to_pyramid():
    import numpy as np
    from gyrostar.starid.tracker import Mode, StarTracker

    pyr, ext = _Stub(5), _Stub(3)
    tr = StarTracker(pyr, ext)
    tr.update(np.zeros((7, 2)))                 # LOST → Pyramid → TRACKING
    assert tr.mode is Mode.TRACKING and pyr.calls == 1
    r = tr.update(np.zeros((5, 2)), omega=np.zeros(3), dt=0.1)
    assert ext.calls == 1 and pyr.calls == 2 and r is pyr.result   # 3 tracked stars are not trusted
    assert tr.counts["fallback"] == 1
    ext4 = _Stub(4)
    tr2 = StarTracker(_Stub(5), ext4)
    tr2.update(np.zeros((7, 2)))
    assert tr2.update(np.zeros((5, 2)), omega=np.zeros(3), dt=0.1) is ext4.result
