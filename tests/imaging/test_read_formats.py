"""Image files → frames: every format ``gyrostar solve`` reads gives back the pixels written
(lossless formats exactly, JPEG within its quantisation), colour as Rec. 709 luminance, the
full scale of the pixel type, and the head's full-frame dumps frame by frame."""

from __future__ import annotations

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.imaging.read import expand_paths, read_frames


@pytest.fixture
def grey16():
    rng = np.random.default_rng(0)
    return rng.integers(0, 4096, (48, 64)).astype(np.uint16)


def test_fits_16bit_and_sim_frame_layout(tmp_path, grey16):
    from astropy.io import fits

    hdul = fits.HDUList([fits.PrimaryHDU(grey16), fits.BinTableHDU.from_columns(
        [fits.Column(name="id", format="K", array=np.arange(3))], name="TRUTH")])
    hdul.writeto(tmp_path / "a.fits")
    (fr,) = read_frames(tmp_path / "a.fits")
    assert np.array_equal(fr.pixels, grey16.astype(np.float32))
    assert fr.saturation == 4095.0          # a 12-bit sensor in a 16-bit container


def test_tiff_8_and_16_bit(tmp_path, grey16):
    import tifffile

    tifffile.imwrite(tmp_path / "a16.tiff", grey16 * 16)
    tifffile.imwrite(tmp_path / "a8.tif", (grey16 // 16).astype(np.uint8))
    (f16,) = read_frames(tmp_path / "a16.tiff")
    (f8,) = read_frames(tmp_path / "a8.tif")
    assert np.array_equal(f16.pixels, (grey16 * 16).astype(np.float32)) and f16.saturation == 65535.0
    assert np.array_equal(f8.pixels, (grey16 // 16).astype(np.float32)) and f8.saturation == 255.0


def test_png_16bit_bmp_and_colour_jpeg(tmp_path, grey16):
    from PIL import Image

    Image.fromarray(grey16).save(tmp_path / "a.png")
    (fp,) = read_frames(tmp_path / "a.png")
    assert np.array_equal(fp.pixels, grey16.astype(np.float32))
    rgb = np.zeros((48, 64, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 200, 100, 50
    Image.fromarray(rgb).save(tmp_path / "a.bmp")
    (fb,) = read_frames(tmp_path / "a.bmp")
    assert fb.colour and np.allclose(fb.pixels, 0.2126 * 200 + 0.7152 * 100 + 0.0722 * 50, atol=1e-3)
    Image.fromarray(rgb).save(tmp_path / "a.jpg", quality=95)
    (fj,) = read_frames(tmp_path / "a.jpg")
    assert fj.colour and abs(float(np.median(fj.pixels)) - (0.2126 * 200 + 0.7152 * 100 + 0.0722 * 50)) < 3.0


def test_head_full_frame_dumps(tmp_path, grey16):
    np.save(tmp_path / "ff.npy", grey16)
    np.savez(tmp_path / "dark_frames.npz", frames=np.stack([grey16, grey16 + 1]), exposure=np.array([0.1, 0.1]))
    (f1,) = read_frames(tmp_path / "ff.npy")
    assert np.array_equal(f1.pixels, grey16.astype(np.float32))
    frames = read_frames(tmp_path / "dark_frames.npz")
    assert [f.name.rsplit("#", 1)[1] for f in frames] == ["0", "1"]
    assert np.array_equal(frames[1].pixels, (grey16 + 1).astype(np.float32))


def test_folders_and_bad_files(tmp_path, grey16):
    np.save(tmp_path / "b.npy", grey16)
    np.save(tmp_path / "a.npy", grey16)
    (tmp_path / "notes.txt").write_text("x")
    assert [p.name for p in expand_paths([tmp_path])] == ["a.npy", "b.npy"]
    np.save(tmp_path / "vec.npy", np.zeros(5))
    with pytest.raises(ConfigError, match="vec.npy"):
        read_frames(tmp_path / "vec.npy")
    np.save(tmp_path / "tiny.npy", np.zeros((4, 4)))
    with pytest.raises(ConfigError, match="too small"):
        read_frames(tmp_path / "tiny.npy")
    with pytest.raises(ConfigError, match="notes.txt"):
        read_frames(tmp_path / "notes.txt")
