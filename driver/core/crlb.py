"""Cramér–Rao bound of a star centroid (Mortensen et al. 2010, Nat. Methods 7:377).

Pixel-integrated Gaussian PSF of σ ``s`` on pixels of side ``a``, ``N`` signal electrons,
``b2`` background electrons per pixel (Poisson), read noise ``sigma_r`` (e⁻ rms):

    Var = (s_a²/N) (1 + 4τ + sqrt(2τ / (1 + 4τ))),   s_a² = s² + a²/12,
    τ = 2π s_a² (b2 + σ_r²) / (N a²)

Returns the per-axis standard deviation in the units of ``a`` (px when a = 1).
"""

from __future__ import annotations

import math


def mortensen_crlb_px(n_e: float, sigma_psf: float, a: float, b2_e: float, read_e: float) -> float:
    """Per-axis centroid CRLB (same units as ``a``) of a static spot."""
    if n_e <= 0 or sigma_psf <= 0 or a <= 0:
        raise ValueError("signal, PSF sigma and pixel size must be positive")
    sa2 = sigma_psf ** 2 + a * a / 12.0
    tau = 2.0 * math.pi * sa2 * (b2_e + read_e ** 2) / (n_e * a * a)
    return math.sqrt(sa2 / n_e * (1.0 + 4.0 * tau + math.sqrt(2.0 * tau / (1.0 + 4.0 * tau))))
