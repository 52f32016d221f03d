"""Synthetic sky frames with known star positions for the detector's tests (truth: the positions
the stars are rendered at; each star is a pixel-integrated Gaussian)."""

from __future__ import annotations

import math

import numpy as np


def gaussian_star(img: np.ndarray, u: float, v: float, flux: float, sigma: float) -> None:
    """Add a star of total ``flux`` DN at [column ``u``, row ``v``], PSF σ px, integrated over pixels."""
    h, w = img.shape
    rad = int(math.ceil(5 * sigma)) + 1
    c0, c1 = max(0, int(u) - rad), min(w, int(u) + rad + 2)
    r0, r1 = max(0, int(v) - rad), min(h, int(v) + rad + 2)
    from scipy.special import erf

    def edges(a, b, centre):
        x = (np.arange(a, b + 1) - 0.5 - centre) / (math.sqrt(2) * sigma)
        return np.diff(0.5 * (1 + erf(x)))

    img[r0:r1, c0:c1] += flux * np.outer(edges(r0, r1, v), edges(c0, c1, u))


def star_field(rng, h=480, w=640, n=40, sigma_psf=1.2, bg=1000.0, noise=8.0, flux=(3e3, 6e4), gradient=0.0,
               margin=12):
    """(image float64, truth (n, 3) [u, v, flux]) — stars at least 12 px apart and from the border;
    ``gradient`` DN added across the frame (sky glow rising to the right and down)."""
    img = np.full((h, w), bg, float)
    if gradient:
        yy, xx = np.mgrid[0:h, 0:w]
        img += gradient * (0.6 * xx / w + 0.4 * yy / h)
    truth = []
    while len(truth) < n:
        u, v = rng.uniform(margin, w - margin), rng.uniform(margin, h - margin)
        if all(math.hypot(u - a, v - b) > 12 for a, b, _ in truth):
            truth.append((u, v, float(np.exp(rng.uniform(*np.log(flux))))))
    for u, v, f in truth:
        gaussian_star(img, u, v, f, sigma_psf)
    img += rng.normal(0.0, noise, img.shape)
    return img, np.array(truth)


def match(found_uv: np.ndarray, truth_uv: np.ndarray, tol: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """For each truth star the index of the nearest found spot within ``tol`` px (-1: none), and that distance."""
    if len(found_uv) == 0:
        return np.full(len(truth_uv), -1), np.full(len(truth_uv), np.inf)
    d = np.hypot(truth_uv[:, None, 0] - found_uv[None, :, 0], truth_uv[:, None, 1] - found_uv[None, :, 1])
    j = d.argmin(axis=1)
    dist = d[np.arange(len(truth_uv)), j]
    return np.where(dist <= tol, j, -1), dist
