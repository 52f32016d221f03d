"""Extended grid tracking (paper 001) and the extended triangle baseline on qian2015 fields."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate, random_attitudes
from gyrostar.hil.evaluation import eval_starid as ev
from gyrostar.mocks.star_lists import score


def _run(method, n, **kw):
    cfg = ev.TrialConfig(method=method, pos_noise_px=kw.pop("pn", 1.0), mag_noise=0.2, **kw)
    return ev.summarize([ev.run_chunk(cfg, 21, n)])


def test_extended_grid_meets_paper_level_on_small_run():
    r = _run("extended-grid", 150)
    assert r["false_ids"] == 0
    assert r["success_rate"] >= 0.96  # paper: 97.4 % at 1 px (the acceptance run uses 10,000 trials)
    assert r["neighbor_success_rate"] >= 0.88


def test_extended_grid_beats_extended_triangle_at_high_noise():
    g = _run("extended-grid", 80, pn=1.5)
    t = _run("extended-triangle", 80, pn=1.5)
    assert g["false_ids"] == 0 and t["false_ids"] == 0
    assert g["success_rate"] > t["success_rate"]  # paper 001 Fig. 10


def test_wrong_prediction_is_rejected_not_misidentified():
    cfg = ev.TrialConfig(method="extended-grid", pos_noise_px=0.5, mag_noise=0.1)
    s = ev.setup(cfg)
    cam, sky, ident = s["camera"], s["sky"], s["ident"]
    rng = np.random.default_rng(9)
    for q in random_attitudes(25, rng):
        f = sky.observe(cam, q, 7.5, 0.5, 0.1, 0, rng)
        # the gyro prediction is off by 1.5° about a random axis: the grid cannot be trusted
        axis = rng.normal(size=3)
        q_bad = quat_propagate(q, axis / np.linalg.norm(axis) * math.radians(1.5), 1.0)
        r = ident.identify(f.uv, q_bad)
        c, w = score(r.ids, f.truth, f.alt)
        assert w == 0
        assert not r.ok or c >= 2


@pytest.mark.parametrize("method", ["extended-grid", "extended-triangle"])
def test_empty_and_single_star_images(method):
    cfg = ev.TrialConfig(method=method)
    ident = ev.setup(cfg)["ident"]
    q = np.array([0.0, 0.0, 0.0, 1.0])
    assert not ident.identify(np.empty((0, 2)), q).ok
    assert not ident.identify(np.array([[100.0, 200.0]]), q).ok


def test_leave_one_out_rejects_a_wrong_match_the_joint_fit_hides():
    from gyrostar.starid.verify import loo_reject, verify_matches

    rng = np.random.default_rng(2)
    ifov = math.radians(4.0) / 512
    # four stars across a 4° field (body = ICRS here), measured with 1 px noise
    xy = np.array([[-1.5, -1.2], [1.4, -1.0], [0.2, 1.5], [-1.6, 1.1]])
    ref = np.column_stack([np.tan(np.radians(xy)), np.ones(4)])
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    b = ref + rng.normal(0, ifov, ref.shape)
    b /= np.linalg.norm(b, axis=1)[:, None]
    # a fifth catalog star 7 px from star 3: matching star 3 to it is wrong
    wrong = ref[3] + np.array([7 * ifov, 0.0, 0.0])
    cat = np.vstack([ref, wrong / np.linalg.norm(wrong)])
    match = np.array([0, 1, 2, 4])
    tol = 5 * ifov
    _, kept, nok, _ = verify_matches(b, cat, match, tol)
    assert nok == 4  # the joint fit bends enough to pass the plain residual test
    assert loo_reject(b, cat, kept, tol) and kept[3] == -1 and list(kept[:3]) == [0, 1, 2]
