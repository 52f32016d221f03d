"""The smeared-spot renderer (:mod:`gyrostar.mocks.render`) against a plain numpy reference:
each sub-step's Gaussian integrated over every pixel of the star's box (erf at the pixel
edges, scipy). Long trails (a fast slew) and trails leaving the sensor; the windowed
renderer gives the full frame's pixels bit for bit."""

import math

import numpy as np
import pytest
from gyrostar.mocks import render
from scipy.special import erf

H, W, SIGMA = 64, 80, 0.85


def _reference(paths, electrons, boxes):
    img = np.zeros((H, W))
    inv = 1.0 / (math.sqrt(2.0) * SIGMA)
    for s in range(paths.shape[0]):
        r0, r1, c0, c1 = boxes[s]
        if r1 <= r0:
            continue
        for u, v in paths[s]:
            ex = 0.5 * np.diff(erf((np.arange(c0, c1 + 1) - 0.5 - u) * inv))
            ey = 0.5 * np.diff(erf((np.arange(r0, r1 + 1) - 0.5 - v) * inv))
            img[r0:r1, c0:c1] += electrons[s] / paths.shape[1] * np.outer(ey, ex)
    return img


@pytest.mark.parametrize("trail", [
    ((10.0, 12.0), (10.5, 12.2)),      # at rest, nearly
    ((5.0, 8.0), (70.0, 50.0)),        # a 77 px trail: the box is 12x the spot's area
    ((40.0, 30.0), (120.0, -30.0)),    # leaves the sensor through two edges
    ((-20.0, 90.0), (30.0, 40.0)),     # comes in from off the sensor
])
def test_trail_matches_the_pixel_integral(trail):
    (u0, v0), (u1, v1) = trail
    m = 400
    t = (np.arange(m) + 0.5) / m
    paths = np.stack([np.stack([u0 + (u1 - u0) * t, v0 + (v1 - v0) * t], 1)])
    electrons = np.array([5000.0])
    boxes = render.star_boxes(paths, SIGMA, W, H)
    img = np.zeros((H, W))
    render.add_stars_full(img, paths, electrons, boxes, SIGMA)
    ref = _reference(paths, electrons, boxes)
    assert np.max(np.abs(img - ref)) < 1e-6 * electrons[0]
    assert abs(img.sum() - ref.sum()) < 1e-5 * electrons[0]
    # every span of the frame, rendered through the window path: the same pixels, bit for bit
    spans = np.array([[0, r, 0, W] for r in range(H)], dtype=np.int64)
    flat = np.zeros(H * W)
    render.add_stars_spans(flat, spans, paths, electrons, boxes, SIGMA)
    assert np.array_equal(flat.reshape(H, W), img)


def test_many_windows_and_stars_outside_them_give_the_full_frame_pixels():
    """Windows (some overlapping, one reaching no star) among stars most of which no window
    reaches: each span's pixels are the full frame's, bit for bit, and the stars outside every
    window add nothing."""
    rng = np.random.default_rng(7)
    n, m = 40, 6
    starts = rng.uniform([0, 0], [W, H], (n, 2))
    paths = starts[:, None, :] + np.linspace(0.0, 1.0, m)[None, :, None] * rng.normal(0, 3.0, (n, 1, 2))
    electrons = rng.uniform(1e3, 1e4, n)
    boxes = render.star_boxes(paths, SIGMA, W, H)
    img = np.zeros((H, W))
    render.add_stars_full(img, paths, electrons, boxes, SIGMA)
    rects = [(5, 14, 3, 20), (10, 20, 15, 30), (40, 60, 60, 80), (0, 3, 77, 80), (30, 31, 0, 80)]
    rows = [[w, r, c0, c1] for w, (r0, r1, c0, c1) in enumerate(rects) for r in range(r0, r1)]
    spans = np.array(rows, dtype=np.int64)
    flat = np.zeros(int((spans[:, 3] - spans[:, 2]).sum()))
    render.add_stars_spans(flat, spans, paths, electrons, boxes, SIGMA)
    ref = np.concatenate([img[r, c0:c1] for _, r, c0, c1 in spans])
    assert np.array_equal(flat, ref)
    # only the stars whose boxes reach a window: the same pixels
    reach = [s for s in range(n) if any(boxes[s, 0] < r1 and boxes[s, 1] > r0 and boxes[s, 2] < c1
                                        and boxes[s, 3] > c0 for r0, r1, c0, c1 in rects)]
    assert 0 < len(reach) < n
    few = np.zeros_like(flat)
    render.add_stars_spans(few, spans, np.ascontiguousarray(paths[reach]), electrons[reach], boxes[reach], SIGMA)
    assert np.array_equal(few, flat)
