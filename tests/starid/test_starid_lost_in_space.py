"""The no-hint plate solver (gyrostar.starid.lost_in_space) against independent truth:
tetra3rs's solutions of tetra3's real night-sky images, the simulator's attitude and
camera, hand-made projections, and frames that hold no stars."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight, quat_to_dcm, random_attitudes
from gyrostar.imaging.detect import detect_stars
from gyrostar.loop.acquire import detect_spots
from gyrostar.starid.lost_in_space import LostInSpace, boresight_radec_roll, build_pyramid
from gyrostar.starid.plate_fit import fit_plate, pixel_residuals

TETRA3 = Path(__file__).resolve().parents[1] / "data" / "tetra3"
ARCSEC = math.pi / 180.0 / 3600.0


def _angle_arcsec(q1, q2) -> float:
    d = quat_to_dcm(np.asarray(q1, float)) @ quat_to_dcm(np.asarray(q2, float)).T
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(d) - 1.0) / 2.0)))) * 3600.0


def _sep_arcsec(ra1, dec1, ra2, dec2) -> float:
    a = np.radians([ra1, dec1, ra2, dec2])
    c = math.sin(a[1]) * math.sin(a[3]) + math.cos(a[1]) * math.cos(a[3]) * math.cos(a[0] - a[2])
    return math.degrees(math.acos(max(-1.0, min(1.0, c)))) * 3600.0


@pytest.fixture(scope="module")
def sensor_1024x768():
    return LostInSpace.for_sensor(1024, 768).prepare()


# ------------------------------------------------------------------ conventions and the fit
def test_roll_convention_round_trips_quat_from_boresight():
    for ra, dec, roll in ((10.0, 20.0, 0.0), (200.0, -45.0, 30.0), (359.0, 80.0, 290.0)):
        q = quat_from_boresight(math.radians(ra), math.radians(dec), math.radians(roll))
        got = boresight_radec_roll(q)
        assert got[0] == pytest.approx(ra, abs=1e-9)
        assert got[1] == pytest.approx(dec, abs=1e-9)
        assert got[2] == pytest.approx(roll, abs=1e-9)


def test_plate_fit_recovers_focal_length_and_k1_of_a_hand_projection():
    rng = np.random.default_rng(3)
    q_true = quat_from_boresight(1.0, 0.4, 0.3)
    a = quat_to_dcm(q_true)
    f, k1, cx, cy = 2400.0, -0.08, 511.5, 383.5
    # directions across the field (body), their ICRS vectors and pixel positions by hand
    xn = rng.uniform(-0.2, 0.2, 60)
    yn = rng.uniform(-0.15, 0.15, 60)
    body = np.stack([xn, yn, np.ones_like(xn)], axis=1)
    body /= np.linalg.norm(body, axis=1)[:, None]
    ref = body @ a                    # ICRS = Aᵀ b
    r2 = xn ** 2 + yn ** 2
    uv = np.stack([cx + f * xn * (1 + k1 * r2), cy + f * yn * (1 + k1 * r2)], axis=1)
    uv += rng.normal(0.0, 0.05, uv.shape)
    q0 = quat_from_boresight(1.001, 0.4005, 0.301)
    q, f_fit, k1_fit, _, _, cov = fit_plate(uv, ref, q0, 2300.0, 0.0, cx, cy, True, False, 30)
    assert f_fit == pytest.approx(f, rel=2e-4)
    assert k1_fit == pytest.approx(k1, abs=3e-3)
    assert _angle_arcsec(q, q_true) < 2.0
    assert np.sqrt(np.mean(pixel_residuals(uv, ref, q, f_fit, k1_fit, cx, cy) ** 2)) < 0.1
    assert np.all(np.isfinite(np.diag(cov)))


# ------------------------------------------------------------------ the public builder
def _assert_same_identifications(one, other, cam, seed):
    """Two identifiers give the same result on the same synthetic fields (V ≤ 6.5, 0.3 px, 1 false star)."""
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.star_lists import Sky

    sky = Sky(load_catalog("hip2", 7.0))
    for q in random_attitudes(5, np.random.default_rng(seed)):
        frame = sky.observe(cam, q, 6.5, 0.3, 0.0, 1, np.random.default_rng(seed))
        a, b = one.identify(frame.uv), other.identify(frame.uv)
        assert a.ok == b.ok and a.status == b.status
        np.testing.assert_array_equal(a.ids, b.ids)
        np.testing.assert_array_equal(a.q, b.q)


def test_build_pyramid_is_the_pyramid_eval_starid_built_by_hand():
    """The builder gives the identifier the hand-built construction gave (same labels, attitude)."""
    from gyrostar.catalog import deepest_limit, load_catalog
    from gyrostar.mocks.star_lists import camera_for_fov
    from gyrostar.starid.faint import DEPTH_MAG, faint_stars
    from gyrostar.starid.index import load_index
    from gyrostar.starid.pyramid import Pyramid

    cam = camera_for_fov(10.0, 1024)
    sep = round(2 * math.degrees(math.atan(0.5 * math.hypot(1024, 1024) / cam.focal_length_px)) + 0.01, 3)
    index = load_index("hip2", 6.5, sep, 0)
    fast = load_index("hip2", 6.5, sep, 10)
    below = load_catalog("hip2", deepest_limit("hip2", 6.5 + DEPTH_MAG))
    by_hand = Pyramid(index, cam, sigma_px=0.5, fast_index=fast, faint=faint_stars(below, index))
    built = build_pyramid(cam, "hip2", 6.5, sigma_px=0.5)
    _assert_same_identifications(by_hand, built, cam, 11)


def test_pyramid_with_camera_is_a_pyramid_built_for_that_camera():
    """``Pyramid.with_camera`` (shared tables, the camera's tolerances recomputed) identifies
    exactly as a Pyramid constructed for the second camera."""
    from gyrostar.mocks.star_lists import camera_for_fov
    from gyrostar.starid.index import load_index
    from gyrostar.starid.pyramid import Pyramid

    cam1, cam2 = camera_for_fov(10.0, 1024), camera_for_fov(9.7, 1024)
    sep = round(2 * math.degrees(math.atan(0.5 * math.hypot(1024, 1024) / cam1.focal_length_px)) + 0.01, 3)
    index = load_index("hip2", 6.5, sep, 0)
    moved = Pyramid(index, cam1, sigma_px=0.7).with_camera(cam2)
    fresh = Pyramid(index, cam2, sigma_px=0.7)
    assert moved.eps == fresh.eps and moved.label_tol == fresh.label_tol and moved.camera == cam2
    _assert_same_identifications(moved, fresh, cam2, 12)


def test_for_camera_solves_a_known_camera_like_its_pyramid():
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.star_lists import Sky, camera_for_fov

    cam = camera_for_fov(10.0, 1024)
    lis = LostInSpace.for_camera(cam, mag_limit=6.5)
    sky = Sky(load_catalog("hip2", 7.0))
    q_true = random_attitudes(1, np.random.default_rng(5))[0]
    frame = sky.observe(cam, q_true, 6.5, 0.2, 0.0, 0, np.random.default_rng(2))
    sol = lis.solve(frame.uv)
    assert sol.solved, sol.status
    assert _angle_arcsec(sol.q_icrs_to_camera, q_true) < 10.0
    assert sol.focal_length_px == cam.focal_length_px and sol.fov_deg == pytest.approx(cam.fov_x_deg)
    assert sol.stars_matched >= 4 and np.count_nonzero(sol.match >= 0) == sol.stars_matched
    assert sol.residual_arcsec_rms < 10.0


# ------------------------------------------------------------------ synthetic frames, no hint
_FIELDS = [(fov, seed) for seed in (1, 2) for fov in (5.0, 10.0, 20.0, 30.0)]
# seed 1 at 5°: the still-image detector returns 60 spots of which 10 of the brightest 12 are not
# stars (around the field's V 4.3 star), so no four-star pattern forms: a known gap, kept visible
_GAPS = {(5.0, 1): "10 of the 12 brightest detections are not stars (around a V 4.3 star)"}


@pytest.mark.slow
@pytest.mark.parametrize("fov,seed", [pytest.param(f, s, marks=pytest.mark.xfail(reason=_GAPS[(f, s)], strict=True))
                                      if (f, s) in _GAPS else (f, s) for f, s in _FIELDS])
def test_simulated_frames_solve_with_no_hint(fov, seed):
    """Rendered frames (``sim frame``'s renderer: xing2012 detector and optics behind a pinhole
    of each field, 100 ms, same seeds), detected as ``gyrostar solve`` does, solve with no hint:
    attitude within the truth's and the focal length within 0.1 %."""
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.sim_preset import load_preset
    from gyrostar.mocks.sky import Sky
    from gyrostar.mocks.star_lists import camera_for_fov

    cam = camera_for_fov(fov, 1024)
    # 100 ms instead of the preset's 10 ms: stars to V ~8.5 (the rendered depth) are detected, as a
    # night-sky camera's exposure gives; at 10 ms a 5° field holds as few as 4 detectable stars
    preset = dataclasses.replace(load_preset("xing2012"), camera=cam).with_exposure(0.1)
    lis = _sensor_1024x1024()
    q0 = random_attitudes(1, np.random.default_rng(seed))[0]
    img, truth = Sky(load_catalog("hip2", 8.5), preset, seed=seed).render_frame(q0, np.zeros(3))
    # the still-image detector (hot pixels and noise peaks flagged out), as `gyrostar solve`
    xy, _ = detect_stars(img, float(2 ** preset.detector.adc_bits - 1)).for_solving(100)
    sol = lis.solve(xy)
    assert sol.solved, f"{fov}° seed {seed}: {sol.status}"
    pix_arcsec = 206264.8 / cam.focal_length_px
    assert _angle_arcsec(sol.q_icrs_to_camera, truth.q_mid) < 0.5 * pix_arcsec + 3.0
    assert sol.focal_length_px == pytest.approx(cam.focal_length_px, rel=1e-3)
    assert sol.p_false < 1e-6


_SOLVERS: dict = {}


def _sensor_1024x1024():
    if "s" not in _SOLVERS:
        _SOLVERS["s"] = LostInSpace.for_sensor(1024, 1024)
    return _SOLVERS["s"]


# ------------------------------------------------------------------ never a wrong attitude
def test_frames_without_stars_are_not_solved(sensor_1024x768):
    rng = np.random.default_rng(0)
    blank = np.full((768, 1024), 100.0)
    noise = rng.normal(100.0, 10.0, (768, 1024))
    for img in (blank, noise):
        spots = detect_spots(img, 5.0, 150, 7)
        sol = sensor_1024x768.solve(spots[:, :2]) if len(spots) else sensor_1024x768.solve(np.empty((0, 2)))
        assert not sol.solved
        assert np.all(sol.match == -1)


def test_random_spot_lists_are_never_solved(sensor_1024x768):
    """Uniformly random spots (a noise-only detection: trees, clouds, hot pixels) never solve."""
    rng = np.random.default_rng(42)
    for _ in range(40):
        n = int(rng.integers(8, 60))
        xy = np.stack([rng.uniform(0, 1023, n), rng.uniform(0, 767, n)], axis=1)
        sol = sensor_1024x768.solve(xy)
        assert not sol.solved, sol


def test_bad_centroids_are_refused(sensor_1024x768):
    from gyrostar.errors import ConfigError

    with pytest.raises(ConfigError):
        sensor_1024x768.solve(np.array([[1.0, np.nan], [2.0, 3.0]]))
    with pytest.raises(ConfigError):
        sensor_1024x768.solve(np.zeros((5, 2)), fov_hint_deg=-3.0)
    with pytest.raises(ConfigError):
        LostInSpace.for_sensor(1024, 768, fov_range_deg=(30.0, 5.0))


# ------------------------------------------------------------------ tetra3's real images
def _tetra3_files():
    return sorted(TETRA3.glob("*.tiff"))


@pytest.fixture(scope="module")
def tetra3rs_solutions():
    """tetra3rs's solution of each image (its own centroids, database for 10–13° fields), and
    its radial camera calibration (``calibrate_camera``, model "radial") from all 8."""
    tetra3rs = pytest.importorskip("tetra3rs")
    tifffile = pytest.importorskip("tifffile")
    from gyrostar.paths import cache_dir

    path = cache_dir("starid") / f"tetra3rs_{tetra3rs.__version__}_f10-13_test.bin"
    if path.exists():
        db = tetra3rs.SolverDatabase.load_from_file(str(path))
    else:
        db = tetra3rs.SolverDatabase.generate_from_gaia(max_fov_deg=13.0, min_fov_deg=10.0)
        db.save_to_file(str(path))
    out, sols, cents = {}, [], []
    for f in _tetra3_files():
        img = tifffile.imread(f)
        c = tetra3rs.extract_centroids(img).centroids
        s = db.solve_from_centroids(c, image_shape=img.shape, fov_estimate_deg=11.5)
        assert s, f"tetra3rs did not solve {f.name}"
        out[f.name] = (s.ra_deg, s.dec_deg, s.fov_deg)
        sols.append(s)
        cents.append(c)
    cal = db.calibrate_camera(sols, cents, image_shape=(768, 1024), model="radial")
    return out, cal.camera_model.focal_length_px


@pytest.mark.slow
@pytest.mark.skipif(len(_tetra3_files()) != 8, reason="tests/data/tetra3 holds the 8 tetra3 images")
def test_tetra3_images_solve_with_no_hint_like_tetra3rs(sensor_1024x768, tetra3rs_solutions):
    """All 8 solve with no hint; each boresight within 10″ of tetra3rs's solution of the image;
    each image's fitted focal length within 0.1 % of tetra3rs's radial calibration from all
    8; the field within 0.3 % of tetra3rs's per-image pinhole field (that one absorbs the
    lens's k1 and scatters 0.2 % between these images of one camera)."""
    tifffile = pytest.importorskip("tifffile")
    solutions, f_cal = tetra3rs_solutions
    for f in _tetra3_files():
        img = tifffile.imread(f).astype(np.float64)
        spots = detect_spots(img, 5.0, 150, 7)
        sol = sensor_1024x768.solve(spots[:, :2])
        assert sol.solved, f"{f.name}: {sol.status}"
        ra, dec, fov = solutions[f.name]
        assert _sep_arcsec(sol.ra_deg, sol.dec_deg, ra, dec) < 10.0, f.name
        assert sol.focal_length_px == pytest.approx(f_cal, rel=1e-3), f.name
        assert sol.fov_deg == pytest.approx(fov, rel=3e-3), f.name
        assert sol.p_false < 1e-6
