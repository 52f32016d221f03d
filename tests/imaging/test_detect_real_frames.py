"""Star detection on frames with what real night-sky images hold (gyrostar.imaging.detect):
truth is the rendered star positions (tests/imaging/imaging_synth.py) and, on tetra3's real frames, the
peer tetra3rs's own centroids."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from gyrostar.imaging.detect import FLAG_EDGE, FLAG_EXTENDED, FLAG_HOT, FLAG_SATURATED, detect_stars
from gyrostar.imaging.read import read_frames
from imaging_synth import gaussian_star, match, star_field

TETRA3 = Path(__file__).resolve().parents[1] / "data" / "tetra3"


def test_sky_glow_gradient_all_stars_found_and_centroids_unbiased():
    rng = np.random.default_rng(1)
    img, truth = star_field(rng, gradient=3000.0, noise=8.0)
    det = detect_stars(img)
    xy, _ = det.for_solving(100)
    j, dist = match(xy, truth[:, :2])
    assert (j >= 0).all(), f"missed {np.sum(j < 0)} stars"
    assert np.sqrt(np.mean(dist ** 2)) < 0.05      # px: high-SNR Gaussian stars
    assert len(xy) == len(truth)                    # the glow makes no false spot


def test_hot_pixels_flagged_and_left_out():
    rng = np.random.default_rng(2)
    img, truth = star_field(rng, n=20)
    hot = np.column_stack([rng.integers(5, 635, 30), rng.integers(5, 475, 30)])
    img[hot[:, 1], hot[:, 0]] += rng.uniform(2e3, 2e4, 30)    # brighter than most stars
    det = detect_stars(img)
    jh, _ = match(det.spots[:, :2], hot.astype(float), tol=0.5)
    near_star = np.min(np.hypot(hot[:, None, 0] - truth[None, :, 0], hot[:, None, 1] - truth[None, :, 1]), 1) < 8
    got = jh[~near_star]
    assert (got >= 0).all()
    assert all(det.flags[k] & FLAG_HOT for k in got)
    xy, _ = det.for_solving(100)
    js, _ = match(xy, truth[:, :2])
    clean = np.min(np.hypot(truth[:, None, 0] - hot[None, :, 0], truth[:, None, 1] - hot[None, :, 1]), 1) > 5
    assert (js[clean] >= 0).all()             # a star with a hot pixel on it may go: the pixel spoils it
    assert len(xy) <= len(truth)


def test_saturated_bloomed_star_is_one_flagged_spot_near_its_centre():
    rng = np.random.default_rng(3)
    img, truth = star_field(rng, n=15, flux=(3e3, 2e4))
    gaussian_star(img, 320.3, 240.7, 5e6, 1.5)           # far above full scale
    img[236:246, 300:341] += 3e4                           # bloom along the row
    img = np.clip(img, 0, 4095)
    det = detect_stars(img, saturation=4095)
    k = int(np.argmin(np.hypot(det.spots[:, 0] - 320.3, det.spots[:, 1] - 240.7)))
    assert det.flags[k] & FLAG_SATURATED
    assert abs(det.spots[k, 0] - 320.3) < 1.0 and abs(det.spots[k, 1] - 240.7) < 1.0
    near = np.hypot(det.spots[:, 0] - 320, det.spots[:, 1] - 240) < 25
    assert near.sum() == 1                                 # one spot, not a row of maxima


def test_bright_extended_object_cannot_take_the_ranks():
    """A moon-like disc with many local maxima, and its glow, is one flagged spot; the stars keep
    the ranks."""
    rng = np.random.default_rng(4)
    img, truth = star_field(rng, n=30)
    yy, xx = np.mgrid[0:480, 0:640]
    r = np.hypot(xx - 450, yy - 200)
    disc = r < 40
    img[disc] += 2e4 + 3e3 * rng.standard_normal(disc.sum())   # mottled: maxima everywhere
    img += 3e3 * np.exp(-(r - 40) / 250.0) * ~disc               # its scattered light (a glow degrees wide)
    det = detect_stars(img)
    ext = (det.flags & FLAG_EXTENDED) != 0
    assert ext.sum() >= 1
    far = truth[r[truth[:, 1].astype(int), truth[:, 0].astype(int)] > 120]
    xy, rows = det.for_solving(len(truth))
    assert not np.any(det.flags[rows] & FLAG_EXTENDED)
    j, _ = match(xy, far[:, :2])
    assert (j >= 0).mean() >= 0.95
    jt, _ = match(truth[:, :2], xy)                 # the spots taken are stars (but a faint one)
    assert (jt < 0).sum() <= 1, xy[jt < 0]


def test_trees_and_roof_across_the_bottom():
    """Sky glow above a ragged dark silhouette (trees, roof): the stars next to the edge are
    found (the sky there keeps the sky's level), the edge itself is one flagged spot, and the
    spots a solver tries first are mostly stars (sky seen between branches looks like a
    defocused star: the solver's verification has to reject those)."""
    rng = np.random.default_rng(5)
    h, w = 480, 640
    img, truth = star_field(rng, n=30, bg=3000.0, noise=15.0)
    xx = np.arange(w)
    edge = (330 + 25 * np.sin(xx / 23.0) + 12 * np.sin(xx / 5.3) + rng.normal(0, 3, w)).astype(int)
    rows = np.arange(h)[:, None]
    dark = rows >= edge[None, :]
    img[dark] = 300.0 + rng.normal(0, 4.0, dark.sum())
    img[200:330, 500:560] = 250.0 + rng.normal(0, 4, (130, 60))       # a roof
    seen = (truth[:, 1] < edge[truth[:, 0].astype(int)] - 3) & ~((truth[:, 0] > 497) & (truth[:, 0] < 563)
                                                                  & (truth[:, 1] > 197))
    clear = seen & (truth[:, 1] < edge[truth[:, 0].astype(int)] - 15) & (truth[:, 0] < w - 20)
    det = detect_stars(img)
    xy, _ = det.for_solving(100)
    j, _ = match(xy, truth[clear, :2])
    assert (j >= 0).all(), truth[clear][j < 0]
    assert np.any(det.flags & FLAG_EXTENDED)
    jt, _ = match(truth[seen, :2], xy[:10])
    assert (jt < 0).sum() <= 3, xy[:10][jt < 0]


def test_jpeg_compressed_8bit_frame():
    from PIL import Image

    rng = np.random.default_rng(6)
    img, truth = star_field(rng, n=30, bg=30.0, noise=3.0, flux=(400, 4000), gradient=40.0)
    buf = io.BytesIO()
    Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(buf, format="JPEG", quality=70)
    frame = np.array(Image.open(io.BytesIO(buf.getvalue())), float)
    det = detect_stars(frame, saturation=255)
    xy, _ = det.for_solving(100)
    j, dist = match(xy, truth[:, :2])
    assert (j >= 0).mean() >= 0.95
    assert np.median(dist[j >= 0]) < 0.25
    assert len(xy) - (j >= 0).sum() <= 2          # block edges make (almost) no spot


def test_elongated_trailed_frame_still_gives_spots():
    """Every star trailed (a long exposure on a fixed tripod): the elongated spots are the stars."""
    rng = np.random.default_rng(7)
    img = np.full((480, 640), 500.0)
    truth = np.column_stack([rng.uniform(30, 610, 25), rng.uniform(30, 450, 25)])
    for u, v in truth:
        for t in np.linspace(-6, 6, 25):
            gaussian_star(img, u + t, v + 0.3 * t, 800.0, 1.0)
    img += rng.normal(0, 6, img.shape)
    det = detect_stars(img)
    xy, _ = det.for_solving(100)
    j, _ = match(xy, truth, tol=1.5)
    assert (j >= 0).mean() >= 0.9


def test_edge_spot_flagged():
    img = np.full((200, 200), 100.0) + np.random.default_rng(8).normal(0, 3, (200, 200))
    gaussian_star(img, 0.4, 100.0, 5e4, 1.2)
    det = detect_stars(img)
    assert det.flags[0] & FLAG_EDGE


def test_loop_acquisition_detector_unchanged():
    """The flatsat loop's own detector keeps its output (the real-frame detector is a separate function)."""
    from gyrostar.loop.acquire import detect_spots

    img = np.full((64, 64), 100.0)
    gaussian_star(img, 20.25, 30.5, 5000.0, 1.0)
    out = detect_spots(img, 5.0, 10, 5)
    assert out.shape == (1, 3)
    # plain thresholded centre of gravity over the box (what the loop has always computed)
    box = img[28:33, 18:23] - 100.0
    box = np.where(box + 100.0 > 100.0 + 2 * 0.5, box, 0.0)
    rr, cc = np.mgrid[28:33, 18:23]
    assert out[0, 0] == pytest.approx((box * cc).sum() / box.sum(), abs=1e-9)
    assert out[0, 1] == pytest.approx((box * rr).sum() / box.sum(), abs=1e-9)


@pytest.mark.parametrize("name", sorted(p.name for p in TETRA3.glob("*.tiff"))[:3])
def test_real_frames_agree_with_tetra3rs_centroids(name):
    tetra3rs = pytest.importorskip("tetra3rs")
    fr = read_frames(TETRA3 / name)[0]
    det = detect_stars(fr.pixels, fr.saturation)
    xy, rows = det.for_solving(30)
    ex = tetra3rs.extract_centroids(fr.pixels)
    peer = np.array([[c.x + fr.width / 2 - 0.5, c.y + fr.height / 2 - 0.5] for c in ex.centroids[:40]])
    j, dist = match(peer, xy, tol=1.0)
    ok = (det.flags[rows] & FLAG_SATURATED) == 0
    assert (j[ok] >= 0).mean() >= 0.9
    assert np.median(dist[ok & (j >= 0)]) < 0.1
