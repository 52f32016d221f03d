"""Per-star verification (gyrostar.starid.star_check): a false star placed where the
identifiers would label it as a catalog star is left unlabelled, against simulator truth."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_error_angles, quat_to_dcm, random_attitudes
from gyrostar.camera import camera_preset, project_many
from gyrostar.errors import ConfigError
from gyrostar.starid.extended import ExtendedIdentifier
from gyrostar.starid.index import load_index
from gyrostar.starid.pyramid import Pyramid
from gyrostar.starid.star_check import StarCheck, chi2_gate

SIG_PX = 0.5
SIG_MAG = 0.3


@pytest.fixture(scope="module")
def parts():
    cam = camera_preset("qian2015")
    check = StarCheck(SIG_PX, cam.focal_length_px, SIG_MAG, 7.5, min_stars=3)
    pyr = Pyramid(load_index("hip2", 7.5, 5.67, 0), cam, sigma_px=SIG_PX, check=check)
    ext = ExtendedIdentifier(load_index("hip2", 8.0, 5.67, 0), cam, sigma_px=SIG_PX, mag_max=7.5,
                             check=StarCheck(SIG_PX, cam.focal_length_px, SIG_MAG, 7.5, min_stars=2))
    return cam, pyr, ext


def _scene(cam, ix, v_safe, seed=7):
    """A field whose faint star F (v_safe < V ≤ 7.5, not among the 4 brightest, isolated) went
    undetected; everything else in the index is seen at its true place with its catalog V.
    Returns (q, uv, mag, true index per spot, F's index, F's true pixel position)."""
    rng = np.random.default_rng(seed)
    for q in random_attitudes(400, rng):
        a = quat_to_dcm(q)
        body = ix.vectors @ a.T
        near = np.flatnonzero(body[:, 2] > math.cos(math.radians(3.0)))
        uv, _ = project_many(cam.as_array(), np.ascontiguousarray(body[near]))
        on = ~np.isnan(uv[:, 0])
        near, uv = near[on], uv[on]
        if len(near) < 9:
            continue
        order = np.argsort(ix.vmag[near], kind="stable")
        near, uv = near[order], uv[order]
        for k in range(4, len(near)):
            d = np.hypot(*(uv - uv[k]).T)
            d[k] = np.inf
            edge = min(uv[k, 0], uv[k, 1], 511 - uv[k, 0], 511 - uv[k, 1])
            if v_safe < ix.vmag[near[k]] <= 7.5 and d.min() > 20 and edge > 10:
                keep = np.arange(len(near)) != k
                return q, uv[keep], ix.vmag[near[keep]], near[keep], near[k], uv[k]
    raise AssertionError("no suitable field")


def _with_false(uv, mag, truth, f_uv, f_mag):
    uv = np.vstack([uv, f_uv])
    mag = np.append(mag, f_mag)
    truth = np.append(truth, -1)
    o = np.argsort(mag, kind="stable")
    return np.ascontiguousarray(uv[o]), mag[o], truth[o]


def test_chi2_gates_match_scipy():
    from scipy.stats import chi2

    for p in (1e-2, 1e-3, 1e-5):
        assert chi2_gate(p, 2) == pytest.approx(chi2.isf(p, 2), rel=1e-9)
        assert chi2_gate(p, 3) == pytest.approx(chi2.isf(p, 3), rel=1e-9)
    with pytest.raises(ConfigError):
        chi2_gate(0.0, 3)
    with pytest.raises(ConfigError):
        StarCheck(0.0, 1000.0)


def test_hand_built_labels_one_wrong_is_dropped_and_attitude_resolved():
    # five catalog directions seen through a known attitude; a sixth spot 6σ off its label
    rng = np.random.default_rng(1)
    f = 7000.0
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    a = quat_to_dcm(q)
    bore = a[2]
    ref = bore + rng.normal(0, 0.02, (6, 3))
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    b = ref @ a.T
    perp = np.cross(b[5], [0.0, 0.0, 1.0])
    b[5] = b[5] + perp / np.linalg.norm(perp) * 6 * SIG_PX / f     # 6σ off: a wrong label
    b[5] /= np.linalg.norm(b[5])
    vmag = np.full(6, 5.0)
    chk = StarCheck(SIG_PX, f, SIG_MAG, 7.5)
    qs, match, n = chk.apply(b, None, ref, vmag, np.arange(6))
    assert n == 5 and list(match) == [0, 1, 2, 3, 4, -1]
    assert np.degrees(np.abs(quat_error_angles(qs, q))).max() * 3600 < 0.01   # from the five exact stars
    # a measured magnitude 2 mag off its catalog V fails though the position is exact
    mag = vmag.copy()
    mag[2] = 3.0
    _, match, n = chk.apply(b, mag, ref, vmag, np.arange(6))
    assert n == 4 and match[2] == -1 and match[5] == -1
    # three labels, one of them far off (the joint fit spreads a small error over all three,
    # so only a clear one shows with three stars): fewer than three verified → rejected
    b3 = b[3:].copy()
    b3[2] = ref[5] @ a.T + perp / np.linalg.norm(perp) * 20 * SIG_PX / f
    b3[2] /= np.linalg.norm(b3[2])
    _, match, n = chk.apply(b3, None, ref[3:], vmag[3:], np.arange(3))
    assert n == 0 and np.all(match == -1)
    with pytest.raises(ConfigError):
        chk.apply(b, mag[:3], ref, vmag, np.arange(6))


def test_pyramid_false_star_at_an_undetected_faint_star(parts):
    cam, pyr, _ = parts
    ix = pyr.index
    q, uv, mag, truth_rows, f_row, f_uv = _scene(cam, ix, pyr.check.v_safe)
    truth = ix.ids[truth_rows]
    # a brighter false spot 1 px from F: inside the labelling tolerance (3.75σ)
    uv2, mag2, truth2 = _with_false(uv, mag, truth, f_uv + [1.0, 0.0], ix.vmag[f_row] - 1.2)
    blind = pyr.identify(uv2)                       # position-only: it is labelled F
    assert blind.ok and ix.ids[f_row] in blind.ids[truth2 == -1]
    r = pyr.identify(uv2, mag=mag2)
    assert r.ok and r.n_identified >= 3
    assert np.all(r.ids[truth2 == -1] == -1)                     # the false spot is not named
    got = r.ids >= 0
    assert np.all(r.ids[got] == truth2[got])                       # every name is right
    assert np.degrees(np.hypot(*quat_error_angles(r.q, q)[:2])) * 3600 < 5.0
    # a false spot of F's own brightness, 0.5 px off: only the detection rule can drop it
    uv3, mag3, truth3 = _with_false(uv, mag, truth, f_uv + [0.5, 0.0], ix.vmag[f_row])
    r = pyr.identify(uv3, mag=mag3)
    assert r.ok and np.all(r.ids[truth3 == -1] == -1)
    assert np.all(r.ids[r.ids >= 0] == truth3[r.ids >= 0])


def test_tracking_identifier_false_star_and_verified_attitude(parts):
    cam, pyr, ext = parts
    ix = ext.index
    q, uv, mag, truth_rows, f_row, f_uv = _scene(cam, pyr.index, ext.check.v_safe, seed=11)
    truth = pyr.index.ids[truth_rows]
    f_v = pyr.index.vmag[f_row]
    uv2, mag2, truth2 = _with_false(uv, mag, truth, f_uv + [0.0, 1.2], f_v - 1.0)
    for r in (ext.identify(uv2, q, mag=mag2), ext.identify_vectors(cam.unproject(uv2), q, mag=mag2)):
        assert r.ok and r.n_identified >= 4
        assert np.all(r.ids[truth2 == -1] == -1)
        assert np.all(r.ids[r.ids >= 0] == truth2[r.ids >= 0])
        # the attitude output is QUEST over exactly the labelled stars
        b = cam.unproject(uv2)[r.index >= 0]
        res = np.arccos(np.clip(np.sum(b * (ix.vectors[r.index[r.index >= 0]] @ quat_to_dcm(r.q).T), 1), -1, 1))
        assert res.max() * cam.focal_length_px < 1e-3                  # noise-free stars: exact fit
    with pytest.raises(ConfigError):
        ext.identify(uv2, q, mag=mag2[:2])
