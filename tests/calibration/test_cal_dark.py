"""Dark-frame maps against known per-pixel truth, FITS products, and the dark command on
the simulator's detector."""

import json

import numpy as np
import pytest
from gyrostar.calibration import calfile
from gyrostar.calibration.dark_frames import read_hot_pixels, solve, stack, write_fits
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError


def _frames(rate, offset, read, t, n, rng):
    return offset + rate * t + read * rng.standard_normal((n, *rate.shape))


def test_dark_solve_recovers_rate_offset_read_noise_and_hot_pixels(tmp_path):
    rng = np.random.default_rng(2)
    h, w = 64, 80
    rate = rng.uniform(40, 60, (h, w))
    hot = [(5, 7), (70, 3), (33, 60)]
    for c, r in hot:
        rate[r, c] = 5000.0
    offset = rng.normal(20.0, 1.0, (h, w))
    stacks = [stack(_frames(rate, offset, 2.0, t, 10, rng), t) for t in (0.01, 0.1, 0.2, 0.4)]
    res = solve(stacks)
    assert res.read_noise == pytest.approx(2.0, rel=0.03)
    normal = rate < 1000
    assert np.sqrt(np.mean((res.rate - rate)[normal] ** 2)) < 5.0
    assert np.sqrt(np.mean((res.offset - offset) ** 2)) < 1.0
    assert sorted(map(tuple, res.hot.tolist())) == sorted(hot)
    path = write_fits(tmp_path / "d.fits", res, temperature_c=21.5)
    assert sorted(map(tuple, read_hot_pixels(path).tolist())) == sorted(hot)
    from astropy.io import fits

    with fits.open(path) as hdul:
        assert hdul[0].header["BUNIT"] == "DN/s"
        assert hdul[0].header["NEXPOS"] == 4
        assert hdul[0].header["RDNOISE"] == pytest.approx(res.read_noise)
        assert hdul["OFFSET"].data.shape == (h, w)


def test_dark_needs_two_exposures_and_two_frames():
    with pytest.raises(ConfigError):
        stack(np.zeros((1, 4, 4)), 0.1)
    with pytest.raises(ConfigError):
        solve([stack(np.zeros((3, 4, 4)), 0.1), stack(np.ones((3, 4, 4)), 0.1)])


def test_dark_simulated_detector(tmp_path, capsys):
    code = main(["calibrate", "dark", "--simulate", "--frames", "4", "--json", "--no-plots",
                 "--report", str(tmp_path)])
    out = json.loads(capsys.readouterr().out)
    par = out["parameters"]
    assert par["read_noise_dn"]["value"] == pytest.approx(par["read_noise_dn"]["truth"], rel=0.05)
    assert par["hot_pixels"]["truth"] > 50
    assert out["hot_missed"] == 0 and out["hot_false"] == 0
    assert par["hot_pixel_rate_rel_error_rms"]["value"] < 0.02
    assert code == 0
    cal = calfile.load(tmp_path / "calibration.toml")
    assert len(cal.dark.hot_pixels) == par["hot_pixels"]["value"]
    assert (tmp_path / "dark.fits").exists()


def test_dark_live_path_through_the_head_client_and_emulator(tmp_path, capsys):
    # --live: HeadClient over a pty to the head emulator (lens capped: empty sky)
    import dataclasses

    from gyrostar.catalog import StarCatalog
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator
    from gyrostar.mocks.sim_preset import load_preset
    from gyrostar.mocks.sky import Sky

    base = load_preset("qian2015")
    preset = dataclasses.replace(base, photometry=dataclasses.replace(base.photometry, sky_mag_arcsec2=60.0))
    empty = StarCatalog("none", np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), 2025.0)
    sky = Sky(empty, preset, seed=11)
    em = HeadEmulator(sky, ConstantRateScene(np.array([0.0, 0.0, 0.0, 1.0])))
    path = em.start()
    try:
        code = main(["calibrate", "dark", "--live", "--port", path, "--frames", "3", "--exposures", "0.005,0.08",
                     "--head-timeout", "5",
                     "--json", "--no-plots", "--report", str(tmp_path)])
    finally:
        em.stop()
    captured = capsys.readouterr()
    assert code == 0, captured.err
    out = json.loads(captured.out)
    det = preset.detector
    assert out["parameters"]["read_noise_dn"]["value"] == pytest.approx(det.read_noise_e / det.gain_e_per_adu, rel=0.1)
    _, dark_e = sky.fixed_pattern
    hot = np.argwhere(np.isclose(dark_e / det.exposure_s, det.hot_pixel_dark_e_s, rtol=1e-4))[:, ::-1]
    found = read_hot_pixels(tmp_path / "dark.fits")
    assert sorted(map(tuple, found.tolist())) == sorted(map(tuple, hot.tolist()))
    with np.load(tmp_path / "dark_frames.npz") as z:
        assert z["frames"].shape == (6, 512, 512)


def test_dark_figure_labels_its_axes(monkeypatch, tmp_path):
    """dark_current.png: the image has column/row labels and a labelled colour bar (it had none)."""
    from types import SimpleNamespace

    from gyrostar.calibration import report
    from gyrostar.hil.calibrate import dark

    figs = []
    monkeypatch.setattr(report, "save_figure", lambda fig, path: figs.append(fig) or path)
    rng = np.random.default_rng(0)
    res = SimpleNamespace(rate=rng.normal(100.0, 10.0, (64, 64)), hot=np.array([[3, 4], [10, 20]]),
                          hot_threshold=300.0)
    dark._plots(tmp_path, res)
    image_ax, hist_ax, bar_ax = figs[0].axes
    assert (image_ax.get_xlabel(), image_ax.get_ylabel()) == ("column (px)", "row (px)")
    assert "2 hot pixels" in image_ax.get_title()
    assert bar_ax.get_ylabel() == "dark current (DN/s)"
    assert hist_ax.get_xlabel() == "dark current (DN/s)" and hist_ax.get_ylabel() == "pixels"
