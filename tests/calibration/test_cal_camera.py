"""Camera intrinsics: the fit's projection and Jacobians against gyrostar.camera, and the
camera command on the simulator's sky."""

import json

import numpy as np
import pytest
from gyrostar.calibration.intrinsics import StarFields, model_difference, project
from gyrostar.camera import camera_preset, project_many
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError

THETA = np.array([6700.0, 515.0, 508.0, 0.3, 4.0, 20.0, 2e-4, -1e-4])


def _dirs(n, rng, half=0.07):
    s = np.column_stack([rng.uniform(-half, half, (n, 2)), np.ones(n)])
    return s / np.linalg.norm(s, axis=1)[:, None]


def test_projection_matches_the_camera_model():
    s = _dirs(50, np.random.default_rng(1))
    uv = project(THETA, s)
    ref, _ = project_many(np.array([*THETA, 1024, 1024]), s)
    np.testing.assert_allclose(uv, ref, atol=1e-9)


def test_jacobians_match_finite_differences():
    s = _dirs(20, np.random.default_rng(2))
    _, jt, js = project(THETA, s, jac=True)
    for i in range(8):
        h = 1e-6 * max(abs(THETA[i]), 1e-3)
        d = THETA.copy()
        d[i] += h
        num = (project(d, s) - project(THETA, s)) / h
        np.testing.assert_allclose(jt[:, :, i], num, rtol=1e-4, atol=1e-6)
    for k in range(3):
        d = s.copy()
        d[:, k] += 1e-7
        num = (project(THETA, d) - project(THETA, s)) / 1e-7
        np.testing.assert_allclose(js[:, :, k], num, rtol=1e-4, atol=1e-3)


def test_model_difference_ignores_a_common_rotation_but_not_distortion():
    p = np.array([*THETA, 1024, 1024])
    assert model_difference(p, p)[0] < 1e-9
    shifted = p.copy()
    shifted[1] += 0.01  # a principal-point shift this small is almost a rotation
    assert model_difference(shifted, p)[1] < 1e-3
    bent = p.copy()
    bent[3] += 0.1
    assert model_difference(bent, p)[1] > 0.1


def test_star_table_validation():
    with pytest.raises(ConfigError):
        StarFields(np.zeros(2, int), np.zeros((2, 2)), np.ones((2, 3)))  # < 3 stars in a field
    with pytest.raises(ConfigError):
        StarFields(np.zeros(3, int), np.full((3, 2), np.nan), np.ones((3, 3)))


def test_camera_simulated_meets_acceptance(tmp_path, capsys):
    # 1,500 fields × ~29 stars at 0.02 px: σ(principal point) ≈ 0.12 px (see camera.py)
    code = main(["calibrate", "camera", "--simulate", "--seed", "4", "--fields", "1500", "--json", "--no-plots",
                 "--report", str(tmp_path)])
    out = json.loads(capsys.readouterr().out)
    par = out["parameters"]
    assert abs(par["focal_length_rel_error"]["value"]) < 5e-4
    assert np.hypot(par["cx_px"]["error"], par["cy_px"]["error"]) < 0.5
    assert par["distortion_residual_px"]["value"] <= 0.05
    assert par["k1"]["error"] == pytest.approx(0.0, abs=0.03)
    assert out["residual_rms_after_px"] < 0.03 < out["residual_rms_before_px"]
    assert out["outliers_caught"] >= 0.9 * out["outliers_injected"]
    assert code == 0
    assert (tmp_path / "calibration.toml").exists()


def test_camera_from_a_csv_star_table(tmp_path, capsys):
    import dataclasses

    from gyrostar.attitude import quat_to_dcm, random_attitudes
    from gyrostar.calibration import calfile
    from gyrostar.catalog import load_catalog

    nominal = camera_preset("xing2012")
    true = dataclasses.replace(nominal, focal_length_m=nominal.focal_length_m * 0.999, k1=-0.2)
    cat = load_catalog("hip2", 6.5)
    rng = np.random.default_rng(8)
    rows = []
    for j, q in enumerate(random_attitudes(300, rng)):
        a = quat_to_dcm(q)
        sel = cat.vectors @ a[2] > np.cos(np.radians(7.0))
        uv, ok = project_many(true.as_array(), np.ascontiguousarray(cat.vectors[sel] @ a.T))
        v = cat.vectors[sel][ok]
        if ok.sum() < 4:
            continue
        uv = uv[ok] + 0.02 * rng.standard_normal((ok.sum(), 2))
        ra, dec = np.degrees(np.arctan2(v[:, 1], v[:, 0])), np.degrees(np.arcsin(v[:, 2]))
        rows += [(j, *p, r, d) for p, r, d in zip(uv, ra, dec)]
    path = tmp_path / "stars.csv"
    np.savetxt(path, np.array(rows), delimiter=",", header="field,u,v,ra_deg,dec_deg", comments="")
    code = main(["calibrate", "camera", str(path), "--json", "--no-plots", "--report", str(tmp_path / "r")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["parameters"]["f_px"]["value"] == pytest.approx(true.focal_length_px, rel=1e-4)
    assert out["parameters"]["k1"]["value"] == pytest.approx(-0.2, abs=0.02)
    cam = calfile.load(tmp_path / "r" / "calibration.toml").camera
    assert cam.residual_rms_px < 0.03
    # the principal point's σ goes into the file with it (the loop's pointing bias)
    assert cam.principal_point_sigma_px == (out["parameters"]["cx_px"]["sigma"], out["parameters"]["cy_px"]["sigma"])
    assert 0 < cam.principal_point_sigma_px[0] < 1.0


def _tracked_fields(seed, per_star_px, noise_px=0.05, n_stars=40, n_fields=400):
    """A tracker's calibration table: the same stars in every field (small attitude changes),
    each star with its own fixed centroid error of ``per_star_px`` RMS plus independent
    noise; truth k1 = 0.3 on an 8.8° field."""
    from gyrostar.calibration.intrinsics import StarFields, project, rotvec_dcm

    rng = np.random.default_rng(seed)
    theta = np.array([6640.0, 515.5, 508.5, 0.3, 0.0, 0.0, 0.0, 0.0])
    xy = rng.uniform(-0.07, 0.07, (n_stars, 2))
    ref = np.column_stack([xy, np.ones(n_stars)])
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    bias = rng.normal(0.0, per_star_px, (n_stars, 2))
    att = rotvec_dcm(rng.normal(0.0, 2e-3, (n_fields, 3)))
    field = np.repeat(np.arange(n_fields), n_stars)
    star = np.tile(np.arange(n_stars), n_fields)
    s = np.einsum("nij,nj->ni", att[field], ref[star])
    uv = project(theta, s) + bias[star] + rng.normal(0.0, noise_px, (len(field), 2))
    return StarFields(field, uv, ref[star], star=star), theta


def test_per_star_sigma_counts_stars_not_observations():
    """With per-star centroid errors the principal point's σ from iid observations is far too
    small; the per-star (cluster) σ covers the real scatter over seeds, and equals the iid σ
    when the errors are independent."""
    from gyrostar.calibration.intrinsics import fit

    free = np.array([1, 1, 1, 1, 0, 0, 0, 0], bool)
    errs, sig, sig_iid = [], [], []
    for seed in range(6):
        stars, theta = _tracked_fields(seed, per_star_px=0.02)
        r = fit(stars, theta + np.array([3.0, 1.0, -1.0, 0.01, 0, 0, 0, 0]), free=free)
        errs.append(r.theta[1] - theta[1])
        sig.append(r.sigma[1])
        sig_iid.append(r.sigma_iid[1])
    errs, sig, sig_iid = np.array(errs), np.array(sig), np.array(sig_iid)
    assert np.all(sig > 4 * sig_iid)                          # 40 stars, not 16 000 observations
    assert np.sqrt(np.mean(errs ** 2)) > 3 * np.mean(sig_iid)  # the iid σ does not cover the scatter
    assert np.all(np.abs(errs) < 4 * sig)                     # the per-star σ does
    # independent errors: the two agree (on average: 40 clusters make one estimate scatter ±20 %)
    ratio = []
    for seed in range(10, 16):
        stars, theta = _tracked_fields(seed, per_star_px=0.0)
        r = fit(stars, theta, free=free)
        ratio.append(r.sigma[1:3] / r.sigma_iid[1:3])
    assert 0.75 < np.mean(ratio) < 1.25


def test_weight_sigma_floors_and_clusters():
    """σ_eff by hand: σ² + the floor of one centroid + n × the error shared by the n
    observations of one star in one half-pixel cell; no σ given: all ones."""
    from gyrostar.calibration.intrinsics import CLUSTER_FLOOR_PX, OBS_FLOOR_PX, StarFields
    from gyrostar.errors import ConfigError

    uv = np.array([[100.1, 200.1], [100.2, 200.2], [100.3, 200.3], [300.0, 50.0], [100.1, 200.1], [10.0, 10.0]])
    ref = np.tile([0.0, 0.0, 1.0], (6, 1))
    field = np.array([0, 0, 0, 1, 1, 1])
    star = np.array([7, 7, 7, 7, 8, 9])
    sigma = np.array([0.05, 0.05, np.nan, 0.1, 0.05, 0.2])
    st = StarFields(field, uv, ref, star=star, sigma=sigma)
    assert st.sigma[2] == pytest.approx(0.05)                # NaN → the median of the others
    got = st.weight_sigma()
    f2, c2 = OBS_FLOOR_PX ** 2, CLUSTER_FLOOR_PX ** 2
    want = np.sqrt(np.array([0.05 ** 2 + f2 + 3 * c2, 0.05 ** 2 + f2 + 3 * c2, 0.05 ** 2 + f2 + 3 * c2,
                             0.1 ** 2 + f2 + c2, 0.05 ** 2 + f2 + c2, 0.2 ** 2 + f2 + c2]))
    assert np.allclose(got, want)
    assert np.allclose(StarFields(field, uv, ref, star=star).weight_sigma(), 1.0)
    with pytest.raises(ConfigError, match="sigmas"):
        StarFields(field, uv, ref, sigma=np.ones(5))
    with pytest.raises(ConfigError, match="finite"):
        StarFields(field, uv, ref, sigma=np.full(6, np.nan))


def test_centroid_sigmas_weight_the_fit():
    """Bright and faint stars (σ 0.02 and 0.25 px): weighting each centroid by its σ brings
    the principal point's scatter over seeds well below the unweighted fit's, and the
    weighted fit's σ covers it."""
    from gyrostar.calibration.intrinsics import StarFields, fit, project, rotvec_dcm

    free = np.array([1, 1, 1, 1, 0, 0, 0, 0], bool)
    theta = np.array([6640.0, 515.5, 508.5, 0.3, 0.0, 0.0, 0.0, 0.0])
    err_w, err_u, sig_w = [], [], []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        n_fields, n_stars = 300, 12
        xy = rng.uniform(-0.07, 0.07, (n_fields * n_stars, 2))      # new sky in every field
        ref = np.column_stack([xy, np.ones(len(xy))])
        ref /= np.linalg.norm(ref, axis=1)[:, None]
        field = np.repeat(np.arange(n_fields), n_stars)
        att = rotvec_dcm(rng.normal(0.0, 2e-3, (n_fields, 3)))
        sig = np.where(rng.random(len(field)) < 0.3, 0.02, 0.25)
        uv = project(theta, np.einsum("nij,nj->ni", att[field], ref)) + sig[:, None] * rng.normal(size=(len(field), 2))
        start = theta + np.array([2.0, 1.0, -1.0, 0.01, 0, 0, 0, 0])
        rw = fit(StarFields(field, uv, ref, sigma=sig), start, free=free)
        ru = fit(StarFields(field, uv, ref), start, free=free)
        err_w.append(rw.theta[1:3] - theta[1:3])
        err_u.append(ru.theta[1:3] - theta[1:3])
        sig_w.append(rw.sigma[1:3])
    err_w, err_u, sig_w = np.array(err_w), np.array(err_u), np.array(sig_w)
    rms_w, rms_u = np.sqrt(np.mean(err_w ** 2)), np.sqrt(np.mean(err_u ** 2))
    assert rms_w < 0.6 * rms_u, (rms_w, rms_u)
    assert 0.6 < rms_w / np.mean(sig_w) < 1.6, (rms_w, np.mean(sig_w))


def test_frame_attitudes_fill_unknown_sigmas_as_the_camera_fit_does():
    """A centroid without σ (NaN: a plain CoG) weighs in a frame's QUEST attitude as the
    median of the usable σ — the camera fit's rule — not a fixed 0.1 px: the attitude equals
    the one with those σ written out, and differs from the 0.1 px fill."""
    from gyrostar.attitude import quat_to_dcm
    from gyrostar.calibration.intrinsics import rotvec_dcm
    from gyrostar.calibration.star_fields import field_attitudes

    cam = camera_preset("xing2012")
    rng = np.random.default_rng(5)
    n = 8
    xy = rng.uniform(-0.06, 0.06, (n, 2))
    ref = np.column_stack([xy, np.ones(n)])
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    a_true = rotvec_dcm(np.array([[1e-3, -2e-3, 5e-3]]))[0]
    sig = np.array([0.02, 0.02, 0.03, 0.3, 0.3, 0.3, np.nan, np.nan])
    noise = np.where(np.isfinite(sig), sig, 0.02)
    uv = project_many(cam.as_array(), np.ascontiguousarray((a_true @ ref.T).T))[0]
    uv = uv + noise[:, None] * rng.normal(size=(n, 2))
    field = np.zeros(n, np.int64)
    ok, q_nan = field_attitudes(field, uv, ref, cam, uv_sigma=sig)
    _, q_med = field_attitudes(field, uv, ref, cam, uv_sigma=np.where(np.isfinite(sig), sig, np.median(sig[:6])))
    _, q_fix = field_attitudes(field, uv, ref, cam, uv_sigma=np.where(np.isfinite(sig), sig, 0.1))
    assert ok.all()
    def arcsec(q1, q2):                     # small angle between two attitudes: ‖A₁ − A₂‖_F / √2 (rad)
        return np.linalg.norm(quat_to_dcm(q1) - quat_to_dcm(q2)) / np.sqrt(2.0) * 180 / np.pi * 3600

    assert arcsec(q_nan[0], q_med[0]) < 1e-6
    assert arcsec(q_nan[0], q_fix[0]) > 1e-3


def test_noiseless_star_fields_give_the_true_camera_with_the_default_priors():
    # Exact centroids from the simulator's sky through the 'real' camera: the fit must land on
    # the truth. With its priors weighed against px-unit data (2,500× too strong at 0.02 px) it
    # settled 0.0009 px RMS from exact data, k2 4 → 1.6 and k3 0 → 132, along the near-degenerate
    # f–k1–k2–k3 direction of an 8.8° field.
    import argparse

    from gyrostar.calibration.intrinsics import fit
    from gyrostar.hil.calibrate import camera as cc

    nominal = camera_preset("xing2012")
    args = argparse.Namespace(seed=1, camera="xing2012", fields=150, mag_limit=7.0, centroid_noise=0.0,
                              outliers=0.0, verbose=-1, json=False)
    stars, truth, _ = cc.simulate(args, nominal)
    f0 = nominal.focal_length_px
    r = np.hypot(nominal.width_px, nominal.height_px) / 2.0 / f0
    res = fit(stars, nominal.as_array()[:8], prior_k2=1.0 / (f0 * r**5), prior_k3=1.0 / (f0 * r**7))
    assert res.rms_px < 1e-6
    np.testing.assert_allclose(res.theta, truth.as_array()[:8], rtol=1e-6, atol=1e-6)


def test_camera_fit_far_from_the_truth_or_implausible_does_not_pass():
    from gyrostar.hil.calibrate.camera import PLAUSIBLE_CORNER_PX, corner_px, implausible

    f0, r = 6667.0, 0.1086
    free = np.ones(8, bool)
    theta = np.array([f0, 511.5, 511.5, 0.3, 4.0, 0.0, 2e-4, -1e-4])
    sigma = np.array([0.01, 0.1, 0.1, 1e-3, 0.2, 11.0, 1e-5, 1e-5])
    assert implausible(theta, sigma, free, f0, r) == {}
    wild = theta.copy()
    wild[5] = 2.0 * PLAUSIBLE_CORNER_PX["k3"] / (f0 * r**7)            # k3 moving the corner 10 px
    assert corner_px("k3", wild[5], f0, r) == pytest.approx(10.0)
    assert set(implausible(wild, sigma, free, f0, r)) == {"k3"}
    assert implausible(wild, sigma, np.array([1, 1, 1, 1, 1, 0, 1, 1], bool), f0, r) == {}   # held, not fitted
