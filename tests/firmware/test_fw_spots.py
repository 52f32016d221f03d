"""FIND_SPOTS: the firmware (host program over a pty) and its Python mirror
(gyrostar.mocks.spot_finder, which the head emulator uses) agree spot for spot and pixel
for pixel on random star fields, and the C unit test's hand-worked image gives the same
hand-worked answer in Python."""

import numpy as np
import pytest
from gyrostar.head import HeadClient
from gyrostar.mocks.spot_finder import check_settings, find_spots
from gyrostar.transport import SerialLink


def _field(rng, h, w, n_stars, bg=80.0, noise=3.0):
    img = rng.normal(bg, noise, (h, w))
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(n_stars):
        r, c, a, s = rng.uniform(1, h - 1), rng.uniform(1, w - 1), rng.uniform(30, 4000), rng.uniform(0.6, 2.0)
        img += a / (2 * np.pi * s * s) * np.exp(-((yy - r) ** 2 + (xx - c) ** 2) / (2 * s * s))
    return np.clip(np.round(img), 0, 1200).astype(np.uint16)


def test_hand_worked_image():
    """The image of firmware/tests/test_spots.c, with its hand-worked answers."""
    h, w = 48, 64
    img = np.full((h, w), 100, np.uint16)
    img[1::2, 1::2] = 101
    for r, c, p, ring in [(10, 10, 900, 300), (12, 14, 500, 250), (30, 40, 600, 200), (40, 5, 700, 280),
                          (1, 60, 650, 260)]:
        img[r - 1:r + 2, c - 1:c + 2] = ring
        img[r, c] = p
    img[20, 20], img[25, 30], img[25, 31] = 2000, 400, 400
    d = find_spots(img, 96, 8, 7)
    assert (d["background_x16"], d["sigma_x16"], d["threshold_x16"], d["candidates"]) == (1600, 8, 1648, 7)
    # score: the 8 neighbours' excess over 100 DN (blob: 8 × (ring − 100); the hot pixel 4 × 1; the
    # earlier of the equal pair: its twin's 300 and one 101)
    assert d["spots"].tolist() == [[10, 10, 1600], [40, 5, 1440], [1, 60, 1280], [30, 40, 800], [25, 30, 301],
                                   [20, 20, 4]]
    assert int(np.sum(d["spans"][:, 3] - d["spans"][:, 2])) == 5 * 49 + 35
    assert find_spots(img, 96, 3, 7)["spots"][:, 2].tolist() == [1600, 1440, 1280]
    assert [check_settings(*s) for s in [(0, 8, 7), (96, 0, 7), (96, 8, 6), (96, 64, 9), (96, 8, 7)]] == [1, 2, 3, 4, 0]


@pytest.mark.parametrize("seed,settings", [(1, (80, 40, 7)), (2, (96, 12, 5)), (3, (48, 64, 3)), (4, (160, 30, 9))])
def test_firmware_and_mirror_agree(seed, settings):
    from gyrostar.mocks.firmware_host import FirmwareHost, is_built

    if not is_built():
        pytest.skip("firmware host program not built (make -C firmware host)")
    rng = np.random.default_rng(seed)
    h, w = 160, 224
    img = _field(rng, h, w, 70)
    n_sigma_x16, max_spots, box = settings
    with FirmwareHost(w, h) as host:
        host.pixels.write_frame(img)
        link = SerialLink(host.path)
        try:
            got = HeadClient(link, timeout=2.0).find_spots(n_sigma_x16 / 16, max_spots, box)
        finally:
            link.close()
    want = find_spots(img, n_sigma_x16, max_spots, box)
    assert got.spots.tolist() == want["spots"].tolist()
    assert got.candidates == want["candidates"] and got.candidates >= len(got.spots) > 0
    assert (got.background_dn * 16, got.sigma_dn * 16, got.threshold_dn * 16) == (
        want["background_x16"], want["sigma_x16"], want["threshold_x16"])
    pixels = np.concatenate([w_.pixels for w_ in got.capture.windows])
    truth = np.concatenate([np.minimum(img, 1023)[r, c0:c1] for _, r, c0, c1 in want["spans"]])
    assert np.array_equal(pixels, truth)
