"""Counter-based per-pixel random numbers and the detector chain (numba, ``cache=True``).

Every random number is a pure function of ``(seed, frame, row, col, draw)`` through a
splitmix64-style hash, so any subset of pixels (a window readout) gets exactly the values
the full frame gets. Fixed-pattern noise (PRNU, DSNU, hot pixels) uses ``frame = -1``,
so it is the same in every frame of a sensor (same seed).

Detector chain for one pixel with mean photo-signal ``s`` electrons (stars + sky):

    λ = (s + sky) · (1 + PRNU) + dark_rate · exposure   (dark_rate: DSNU lognormal or hot;
                                                        s = 0: the float32 map λ_bg)
    n = Poisson(λ)  (exact inversion for λ < 40, else round(λ + √λ·z))
    e = min(n, full_well) + read_noise · z'
    ADU = clip(round(e / gain + bias), 0, 2^bits − 1)  → uint16

Per pixel one 64-bit hash ``h = mix64(frame_key ^ row << 20 ^ col)`` feeds the Poisson
inversion (low 32 bits) and the read-noise normal (high 32 bits, inverse CDF from a 2¹⁶
table with linear interpolation; exact in the two end cells), which keeps the whole
1024² chain at a few ns per pixel.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit, prange

from .sim_preset import (
    D_ADCMAX,
    D_BIAS,
    D_DARK,
    D_DSNU,
    D_EXPOSURE,
    D_FULLWELL,
    D_GAIN,
    D_HOTDARK,
    D_HOTF,
    D_PRNU,
    D_READ,
    D_SKY_E,
)

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLD = np.uint64(0x9E3779B97F4A7C15)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_POISSON_EXACT = 40.0
_INV_N = np.array([0.0] + [1.0 / n for n in range(1, 200)])


@njit(cache=True, inline="always")
def mix64(x):
    """splitmix64 finaliser (bijective 64-bit mixer)."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@njit(cache=True, inline="always")
def pixel_key(seed, frame, row, col):
    """64-bit key of one pixel of one frame (frame −1 = the fixed pattern)."""
    k = mix64(np.uint64(seed) * _GOLD + np.uint64(frame + 1))
    return mix64(k ^ (np.uint64(row) << np.uint64(20)) ^ np.uint64(col))


@njit(cache=True, inline="always")
def uniform(key, draw):
    """The ``draw``-th uniform in (0, 1) of a pixel key."""
    h = mix64(key + np.uint64(draw + 1) * _GOLD)
    return (np.float64(h >> _S11) + 0.5) * _INV53


@njit(cache=True, inline="always")
def normal_pair(key, draw):
    """Two independent standard normals (Box–Muller on draws ``draw``, ``draw + 1``)."""
    r = math.sqrt(-2.0 * math.log(uniform(key, draw)))
    t = 2.0 * math.pi * uniform(key, draw + 1)
    return r * math.cos(t), r * math.sin(t)


@njit(cache=True)
def fixed_pattern(seed, height, width, det):
    """PRNU gain (1 + δ) and dark electrons per exposure, float32 (height, width) each."""
    gain = np.empty((height, width), dtype=np.float32)
    dark = np.empty((height, width), dtype=np.float32)
    exp_s = det[D_EXPOSURE]
    s_ln = det[D_DSNU]
    for r in prange(height):
        for c in range(width):
            key = pixel_key(seed, -1, r, c)
            z1, z2 = normal_pair(key, 0)
            gain[r, c] = 1.0 + det[D_PRNU] * z1
            if uniform(key, 2) < det[D_HOTF]:
                dark[r, c] = det[D_HOTDARK] * exp_s
            else:
                # lognormal with mean dark rate and relative spread s_ln
                sig = math.sqrt(math.log(1.0 + s_ln * s_ln))
                dark[r, c] = det[D_DARK] * exp_s * math.exp(sig * z2 - 0.5 * sig * sig)
    return gain, dark


@njit(cache=True)
def ndtri(u):
    """Inverse standard normal CDF (Acklam's rational approximation + one Halley step)."""
    a = (-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02, 1.383577518672690e02,
         -3.066479806614716e01, 2.506628277459239e00)
    b = (-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02, 6.680131188771972e01,
         -1.328068155288572e01)
    c = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00, -2.549732539343734e00,
         4.374664141464968e00, 2.938163982698783e00)
    d = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00)
    if u < 0.02425:
        q = math.sqrt(-2.0 * math.log(u))
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
    elif u > 1.0 - 0.02425:
        q = math.sqrt(-2.0 * math.log(1.0 - u))
        x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
    else:
        q = u - 0.5
        r = q * q
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q / \
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)
    e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - u
    g = e * math.sqrt(2.0 * math.pi) * math.exp(0.5 * x * x)
    return x - g / (1.0 + 0.5 * x * g)


_TABLE_BITS = 12
_TABLE_N = 1 << _TABLE_BITS


@njit(cache=True)
def _normal_table():
    t = np.empty(_TABLE_N + 1)
    t[0] = -np.inf
    t[_TABLE_N] = np.inf
    for i in range(1, _TABLE_N):
        t[i] = ndtri(i / _TABLE_N)
    return t


@functools.lru_cache(maxsize=1)
def normal_table() -> np.ndarray:
    """Inverse normal CDF at i / 2¹², i = 0..2¹² (ends ±inf; 32 KiB, stays in L1), for :func:`table_normal`."""
    return _normal_table()

_S48 = np.uint64(48)
_S32 = np.uint64(32)
_M20 = np.uint64(0xFFFFF)
_M32 = np.uint64(0xFFFFFFFF)


@njit(cache=True, inline="always")
def table_normal(bits32, table):
    """Standard normal from 32 random bits: inverse CDF by table (12 bits) + interpolation (20 bits).

    Interpolation error < 1e-5 for |z| < 2.5 and < 2e-3 up to 3.4; the two end cells
    (|z| > 3.35, probability 5e-4) use the exact inverse CDF.
    """
    i = int(bits32 >> np.uint64(20))
    frac = (np.float64(bits32 & _M20) + 0.5) * (1.0 / 1048576.0)
    if i == 0 or i == _TABLE_N - 1:
        return ndtri((i + frac) / _TABLE_N)
    return table[i] + frac * (table[i + 1] - table[i])


@njit(cache=True)
def poisson(lam, u32, key):
    """Poisson sample of mean ``lam``: inversion from the 32-bit uniform ``u32`` for small λ."""
    if lam <= 0.0:
        return 0.0
    if lam < _POISSON_EXACT:
        u = (np.float64(u32) + 0.5) * (1.0 / 4294967296.0)
        p = math.exp(-lam)
        f = p
        n = 0
        while u > f and n < 199:
            n += 1
            p *= lam * _INV_N[n]
            f += p
        return float(n)
    z, _ = normal_pair(key, 1)
    return max(0.0, math.floor(lam + math.sqrt(lam) * z + 0.5))


@njit(cache=True, inline="always")
def frame_key(seed, frame):
    """Key of one frame of one sensor (frame −1 = the fixed pattern)."""
    return mix64(np.uint64(seed) * _GOLD + np.uint64(frame + 1))


_K_VEC = 12  # Poisson terms evaluated branch-free (vectorised) before the scalar tail


@njit(cache=True)
def background_maps(gain_fp, dark, det):
    """Star-free mean λ_bg = sky·(1 + PRNU) + dark and exp(−λ_bg) per pixel, float32 (H, W) each.

    Fixed per sensor. Pixels without star light take their λ and the first Poisson term
    from these maps (no exponential per pixel, half the memory traffic); the full-frame
    and span digitisers apply the same rule, so they stay identical.
    """
    h, w = gain_fp.shape
    lam_bg = np.empty((h, w), dtype=np.float32)
    exp_bg = np.empty((h, w), dtype=np.float32)
    for r in range(h):
        for c in range(w):
            lam = det[D_SKY_E] * gain_fp[r, c] + dark[r, c]
            lam_bg[r, c] = lam
            exp_bg[r, c] = math.exp(-min(np.float64(np.float32(lam)), _POISSON_EXACT))
    return lam_bg, exp_bg


@njit(cache=True, nogil=True)
def digitise_run(signal, gain_fp, dark, lam_bg, exp_bg, keys, det, noise, table, out,
                 lam, u, p, f, cnt, hs):
    """ADU of a run of pixels (1-D arrays of one length); see the module docstring.

    ``keys`` (uint64): each pixel's ``fkey ^ row << 20 ^ col`` (:func:`pixel_keys`); its
    random bits are ``h = mix64(key)``: the low 32 bits drive the Poisson inversion, the
    high 32 bits the read-noise normal. The inversion counts the CDF terms below u for
    n ≤ 12 across the run with no branches (SIMD), then finishes the pixels beyond by the
    scalar recurrence; λ ≥ 40 uses round(λ + √λ z). Every pixel's result depends only on
    its own inputs, so any run (a row, a span, every span of a readout) gives the same values.
    ``lam, u, p, f, cnt`` (float64) and ``hs`` (uint64), each ≥ len, are scratch buffers.
    """
    m = signal.shape[0]
    # detector constants as locals: indexing ``det`` inside the pixel loops stops LLVM from
    # hoisting them (stores to ``out`` may alias) and cost ~60x in the ADC loop
    sky_e, full_well, read_e = det[D_SKY_E], det[D_FULLWELL], det[D_READ]
    inv_gain, bias, adc_max = 1.0 / det[D_GAIN], det[D_BIAS], det[D_ADCMAX]
    for i in range(m):
        if signal[i] == 0.0:
            lam[i] = lam_bg[i]
        else:
            lam[i] = (signal[i] + sky_e) * gain_fp[i] + dark[i]
    if noise:
        for i in range(m):
            h = mix64(keys[i])
            hs[i] = h
            u[i] = (np.float64(h & _M32) + 0.5) * (1.0 / 4294967296.0)
        for i in range(m):
            p[i] = exp_bg[i] if signal[i] == 0.0 else math.exp(-min(lam[i], _POISSON_EXACT))
        for i in range(m):  # fixed trip count, no branches: unrolled and vectorised across pixels
            pi = p[i]
            fi = pi
            ui = u[i]
            li = lam[i]
            ci = 1.0 if ui > fi else 0.0
            for n in range(1, _K_VEC + 1):
                pi = pi * (li * _INV_N[n])
                fi = fi + pi
                ci += 1.0 if ui > fi else 0.0
            p[i] = pi
            f[i] = fi
            cnt[i] = ci
        for i in range(m):
            lm = lam[i]
            if lm <= 0.0:
                k = 0.0
            elif lm >= _POISSON_EXACT:
                z, _ = normal_pair(hs[i], 1)
                k = max(0.0, math.floor(lm + math.sqrt(lm) * z + 0.5))
            else:
                k = cnt[i]
                if k > _K_VEC:  # u beyond F(12): continue the recurrence
                    n = _K_VEC
                    pp, ff = p[i], f[i]
                    while u[i] > ff and n < 199:
                        n += 1
                        pp *= lm * _INV_N[n]
                        ff += pp
                    k = float(n)
            e = min(k, full_well) + read_e * table_normal(hs[i] >> _S32, table)
            out[i] = _adc(e, inv_gain, bias, adc_max)
    else:
        for i in range(m):
            out[i] = _adc(min(lam[i], full_well), inv_gain, bias, adc_max)


@njit(cache=True, inline="always")
def _adc(e, inv_gain, bias, adc_max):
    """Electrons → ADU: round(e / gain + bias), clipped to [0, adc_max]."""
    adu = math.floor(e * inv_gain + bias + 0.5)
    if adu < 0.0:
        adu = 0.0
    elif adu > adc_max:
        adu = adc_max
    return np.uint16(adu)


@njit(cache=True, nogil=True)
def digitise_frame(signal, gain_fp, dark, lam_bg, exp_bg, seed, frame, det, noise, table, row_lit):
    """Whole frame: mean photo-signal (H, W) float64 → uint16 ADU (H, W).

    ``row_lit`` (H,) bool: rows that may hold star light; the others read a zero row
    instead of ``signal`` (same values, less memory traffic). Single-threaded on purpose:
    on a shared 2-core host a threaded loop ran 2-3x slower.
    """
    h, w = signal.shape
    zero_row = np.zeros(w)
    out = np.empty((h, w), dtype=np.uint16)
    fkey = frame_key(seed, frame)
    lam, u, p, f, cnt = np.empty(w), np.empty(w), np.empty(w), np.empty(w), np.empty(w)
    hs = np.empty(w, dtype=np.uint64)
    keys = np.empty(w, dtype=np.uint64)
    for r in range(h):
        pixel_keys(fkey, r, 0, keys)
        digitise_run(signal[r] if row_lit[r] else zero_row, gain_fp[r], dark[r], lam_bg[r], exp_bg[r], keys,
                     det, noise, table, out[r],
                     lam, u, p, f, cnt, hs)
    return out


@njit(cache=True, inline="always")
def pixel_keys(fkey, row, col0, keys):
    """``keys[i] = fkey ^ row << 20 ^ (col0 + i)``: the noise keys of a run of pixels of one row."""
    rkey = fkey ^ (np.uint64(row) << np.uint64(20))
    for i in range(keys.shape[0]):
        keys[i] = rkey ^ np.uint64(col0 + i)


def span_maps(gain_fp, dark, lam_bg, exp_bg) -> np.ndarray:
    """The four per-pixel maps interleaved, float32 (H, W, 4) ``[gain, dark, λ_bg, exp(−λ_bg)]``:
    a span's inputs in one run of memory (the span digitiser's reads stay in a few cache
    lines wherever the windows lie; four separate maps cost four lines per row)."""
    return np.ascontiguousarray(np.stack([gain_fp, dark, lam_bg, exp_bg], axis=-1), dtype=np.float32)


@njit(cache=True, nogil=True)
def digitise_spans(signal, spans, maps, seed, frame, det, noise, table):
    """Span pixels: mean photo-signal (m,) in span order → uint16 ADU (m,); ``maps`` from
    :func:`span_maps` (the same values as the full-frame digitiser's four maps). Every span's
    inputs are gathered first, then one run digitises the whole readout."""
    m = signal.shape[0]
    out = np.empty(m, dtype=np.uint16)
    fkey = frame_key(seed, frame)
    gain = np.empty(m, np.float32)
    dk = np.empty(m, np.float32)
    lb = np.empty(m, np.float32)
    eb = np.empty(m, np.float32)
    keys = np.empty(m, np.uint64)
    k = 0
    for i in range(spans.shape[0]):
        r, a, b = spans[i, 1], spans[i, 2], spans[i, 3]
        pixel_keys(fkey, r, a, keys[k:k + b - a])
        for c in range(a, b):
            gain[k] = maps[r, c, 0]
            dk[k] = maps[r, c, 1]
            lb[k] = maps[r, c, 2]
            eb[k] = maps[r, c, 3]
            k += 1
    digitise_run(signal, gain, dk, lb, eb, keys, det, noise, table, out,
                 np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m, np.uint64))
    return out
