"""Star detection in real sky frames (numba): local background, connected components, windowed
centroids and a quality flag per spot.

The flatsat loop's own acquisition (:func:`gyrostar.loop.acquire.detect_spots`: one global
background, 3×3 maxima) is untouched; this is the detector of still images from any camera —
ground night-sky frames with sky glow, trees and roofs, JPEG compression, hot pixels, bright
extended objects.

Steps (pixel values as stored, float32; coordinates ``[u, v]`` = [column, row], pixel centres
at integers):

1. Background and noise per ``tile``×``tile`` tile from ≤ 144 samples: a plane fitted to the
   samples within 3σ (σ = 1.4826·MAD of the residuals; stars, hot pixels and a gradient across
   the tile do not raise it), its value at the tile centre; a tile unlike its 8
   neighbours (level or σ: filled by a moon, a lit cloud, a roof edge) takes their median,
   the grid continued linearly past its edges (a smooth glow or ramp keeps its values);
   bilinear between tile centres. A noise of 0 (quantised flat sky: JPEG, 8-bit) takes the
   clipped standard deviation, at least ``SIGMA_FLOOR``.
2. Detection: the background-subtracted frame smoothed with the 3×3 binomial kernel (a
   matched filter for a star of σ ≈ 1 px) above ``n_sigma`` × the smoothed frame's own noise,
   measured per tile like the background: correlated noise (JPEG 8×8 blocks, demosaiced
   colour, binning) smooths less than white noise, and the threshold follows it.
3. 8-connected components of the detection mask (one bright star, bloom or extended object is
   one component, whatever its local maxima). Per component: area, flux Σ(I − B), peak,
   saturated pixels, second moments (size, elongation), sharpness of the peak
   ``(peak − mean of its 8 neighbours) / peak`` (background subtracted).
4. Centroid: a Gaussian-windowed centroid (the iteration of SExtractor's XWIN: window σ from
   the component's size) on the background-subtracted pixels — unbiased for a symmetric PSF,
   insensitive to the threshold; saturated or extended components keep the plain centre of
   gravity of their pixels (a flat top has no peak).
5. Flags (:data:`FLAG_NAMES`): ``saturated``; ``hot`` (sharpness > ``max_sharpness``, not
   saturated: one pixel, no PSF); ``elongated`` (axis ratio > ``max_elongation``);
   ``extended`` (more than ``max_area`` px, or an RMS radius above ``max_radius_px`` or above
   ``max_radius_factor`` × the median radius of the frame's brightest compact spots, or an
   unsaturated flat top — flux / (peak × area) above ``FLAT_FILL``: moon, comet, glow, lit
   cloud, roof edge, sky seen between branches); ``edge`` (touches the frame border: the centroid is cut).
6. The list a solver takes (:meth:`Detection.for_solving`): brightest first, without hot and
   extended spots, and without elongated ones unless most spots are elongated (a trailed
   frame), capped at ``max_spots`` — one bright extended object is one flagged entry, so it
   cannot take the ranks of the stars.

Spots are returned brightest first (all of them, flagged), with the frame's median background
and noise.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

FLAG_SATURATED, FLAG_HOT, FLAG_ELONGATED, FLAG_EXTENDED, FLAG_EDGE = 1, 2, 4, 8, 16
FLAG_NAMES = {FLAG_SATURATED: "saturated", FLAG_HOT: "hot", FLAG_ELONGATED: "elongated",
              FLAG_EXTENDED: "extended", FLAG_EDGE: "edge"}
SIGMA_FLOOR = 0.3            # DN: least noise assumed (a perfectly flat quantised sky)
MAX_COMPONENTS = 20000       # components kept per frame (the brightest by peak are kept first)
STEP_SIGMA = 30.0            # σ: tile levels this far apart around a pixel are a step (horizon, roof)
FLAT_FILL = 0.6              # flux / (peak × area) above this: a flat-topped blob (sky through trees), not a star
N_STATS = 13                 # per-component columns of the numba kernel (see _components)


@njit(cache=True)
def _robust_sigma(res, keep, med):
    m = 0
    dev = np.empty(res.shape[0])
    for i in range(res.shape[0]):
        if keep[i]:
            dev[m] = abs(res[i] - med)
            m += 1
    sig = 1.4826 * np.sort(dev[:m])[m // 2]
    if sig <= 0.0:                       # quantised flat sky: the clipped standard deviation
        s2 = 0.0
        for i in range(m):
            s2 += dev[i] * dev[i]
        sig = math.sqrt(s2 / max(m - 1, 1))
    return max(sig, SIGMA_FLOOR)


@njit(cache=True)
def tile_stats(vals, rr, cc, n, r0, c0):
    """Level at (``r0``, ``c0``), σ and slopes (per column, per row) of the samples ``vals[:n]``
    at rows ``rr`` / columns ``cc``: a plane fitted to the samples within 3σ (three rounds, the first a plain median),
    so a gradient across the tile (sky glow, a moon's halo) does not count as noise."""
    v = vals[:n]
    y = rr[:n] - r0
    x = cc[:n] - c0
    keep = np.ones(n, np.bool_)
    a0, ax, ay = np.median(v), 0.0, 0.0
    res = v - a0
    med = 0.0
    sig = _robust_sigma(res, keep, med)
    for _ in range(3):
        for i in range(n):
            keep[i] = abs(res[i] - med) <= 3.0 * sig
        m = 0
        sx = sy = sxx = syy = sxy = sv = svx = svy = 0.0
        for i in range(n):
            if keep[i]:
                m += 1
                sx += x[i]
                sy += y[i]
                sxx += x[i] * x[i]
                syy += y[i] * y[i]
                sxy += x[i] * y[i]
                sv += v[i]
                svx += v[i] * x[i]
                svy += v[i] * y[i]
        if m < 8:
            break
        # 3×3 normal equations [[m, sx, sy], [sx, sxx, sxy], [sy, sxy, syy]] · (a0, ax, ay) = (sv, svx, svy)
        c00 = sxx * syy - sxy * sxy
        c01 = sy * sxy - sx * syy
        c02 = sx * sxy - sy * sxx
        det = m * c00 + sx * c01 + sy * c02
        if abs(det) < 1e-9:
            break
        c11 = m * syy - sy * sy
        c12 = sx * sy - m * sxy
        c22 = m * sxx - sx * sx
        a0 = (c00 * sv + c01 * svx + c02 * svy) / det
        ax = (c01 * sv + c11 * svx + c12 * svy) / det
        ay = (c02 * sv + c12 * svx + c22 * svy) / det
        res = v - (a0 + ax * x + ay * y)
        kept = np.empty(m)
        k = 0
        for i in range(n):
            if keep[i]:
                kept[k] = res[i]
                k += 1
        med = np.median(kept)
        sig = _robust_sigma(res, keep, med)
    return a0 + med, sig, ax, ay


@njit(cache=True)
def _padded(a):
    """``a`` (ny, nx) with a border of one tile continued linearly (2·edge − next), so a 3×3
    median over a ramp keeps the ramp at the frame's edges."""
    ny, nx = a.shape
    p = np.empty((ny + 2, nx + 2))
    p[1:-1, 1:-1] = a
    for r in range(1, ny + 1):
        p[r, 0] = 2.0 * p[r, 1] - p[r, 2] if nx > 1 else p[r, 1]
        p[r, nx + 1] = 2.0 * p[r, nx] - p[r, nx - 1] if nx > 1 else p[r, nx]
    for c in range(nx + 2):
        p[0, c] = 2.0 * p[1, c] - p[2, c] if ny > 1 else p[1, c]
        p[ny + 1, c] = 2.0 * p[ny, c] - p[ny - 1, c] if ny > 1 else p[ny, c]
    return p


@njit(cache=True)
def _mend_outlier_tiles(bg, sg, gx, gy):
    """Tiles unlike their 8 neighbours take the neighbours' median: a level more than 3 ×
    (1.4826 × the neighbours' MAD, at least 3σ) away from it, or a σ above twice theirs (a
    tile filled by a moon, a lit cloud or a roof edge). A smooth glow keeps its own values."""
    ny, nx = bg.shape
    pb = _padded(bg)
    ps = _padded(sg)
    px = _padded(gx)
    py = _padded(gy)
    ob = bg.copy()
    os_ = sg.copy()
    ox = gx.copy()
    oy = gy.copy()
    nb = np.empty(8)
    ns = np.empty(8)
    nx_ = np.empty(8)
    ny_ = np.empty(8)
    for r in range(ny):
        for c in range(nx):
            k = 0
            for dr in range(3):
                for dc in range(3):
                    if dr != 1 or dc != 1:
                        nb[k] = pb[r + dr, c + dc]
                        ns[k] = ps[r + dr, c + dc]
                        nx_[k] = px[r + dr, c + dc]
                        ny_[k] = py[r + dr, c + dc]
                        k += 1
            mb = np.median(nb)
            msg = max(np.median(ns), SIGMA_FLOOR)
            spread = 1.4826 * np.median(np.abs(nb - mb))
            if abs(bg[r, c] - mb) > 3.0 * max(spread, 3.0 * msg) or sg[r, c] > 2.0 * msg:
                ob[r, c] = mb
                os_[r, c] = msg
                ox[r, c] = np.median(nx_)
                oy[r, c] = np.median(ny_)
    return ob, os_, ox, oy


@njit(cache=True)
def background_grid(img, tile):
    """Per-tile level and σ (ny, nx) (see :func:`background_planes`)."""
    bg, sg, gx, gy = background_planes(img, tile)
    return bg, sg


@njit(cache=True)
def background_planes(img, tile):
    """Per-tile level, σ and slopes per column and per row (ny, nx) of :func:`tile_stats`,
    outlier tiles mended."""
    h, w = img.shape
    ny = (h + tile - 1) // tile
    nx = (w + tile - 1) // tile
    step = max(1, tile // 12)
    bg = np.empty((ny, nx))
    sg = np.empty((ny, nx))
    gx = np.empty((ny, nx))
    gy = np.empty((ny, nx))
    m = ((tile + step - 1) // step) ** 2
    vals = np.empty(m)
    rr = np.empty(m)
    cc = np.empty(m)
    for ty in range(ny):
        for tx in range(nx):
            n = 0
            for r in range(ty * tile + step // 2, min(h, (ty + 1) * tile), step):
                for c in range(tx * tile + step // 2, min(w, (tx + 1) * tile), step):
                    vals[n] = img[r, c]
                    rr[n] = r
                    cc[n] = c
                    n += 1
            if n < 3:
                n = 0
                for r in range(ty * tile, min(h, (ty + 1) * tile)):
                    for c in range(tx * tile, min(w, (tx + 1) * tile)):
                        if n < m:
                            vals[n] = img[r, c]
                            rr[n] = r
                            cc[n] = c
                            n += 1
            r0 = (ty * tile + min(h, (ty + 1) * tile) - 1) / 2.0
            c0 = (tx * tile + min(w, (tx + 1) * tile) - 1) / 2.0
            bg[ty, tx], sg[ty, tx], gx[ty, tx], gy[ty, tx] = tile_stats(vals, rr, cc, n, r0, c0)
    return _mend_outlier_tiles(bg, sg, gx, gy)


@njit(cache=True)
def _axis_table(n, tile, ng):
    """Linear table along one axis: per pixel the lower tile index and the weight of the next
    tile (tile centres as :func:`background_grid` measures them; outside the first and last
    centres the line is continued, so a gradient reaches the frame's edges)."""
    i0 = np.zeros(n, np.int64)
    f = np.zeros(n)
    if ng < 2:
        return i0, f
    centre = np.empty(ng)
    for k in range(ng):
        centre[k] = (k * tile + min(n, (k + 1) * tile) - 1) / 2.0
    k = 0
    for i in range(n):
        while k < ng - 2 and i > centre[k + 1]:
            k += 1
        i0[i] = k
        f[i] = (i - centre[k]) / (centre[k + 1] - centre[k])
    return i0, f


@njit(cache=True)
def excess_and_noise(img, tile):
    """Background-subtracted frame and noise map (h, w) float32, bilinear between the tile
    centres of :func:`background_planes`, and the level and σ grids. Across a step — the
    planes of the four tiles around a cell, each extended over it, disagree by more than
    ``STEP_SIGMA`` σ: a horizon, a roof, a lit wall; a smooth glow's planes agree — a pixel of
    that cell takes the plane nearest its own value instead, so the sky next to a dark edge keeps the
    sky's level and its stars are not swallowed by the edge."""
    h, w = img.shape
    bgg, sgg, gxx, gyy = background_planes(img, tile)
    ny, nx = bgg.shape
    y0, fy = _axis_table(h, tile, ny)
    x0, fx = _axis_table(w, tile, nx)
    cy = np.empty(ny)
    for k in range(ny):
        cy[k] = (k * tile + min(h, (k + 1) * tile) - 1) / 2.0
    cx = np.empty(nx)
    for k in range(nx):
        cx[k] = (k * tile + min(w, (k + 1) * tile) - 1) / 2.0
    # a cell (between four tile centres) is a step when the four planes, each extended to the
    # cell's corners and centre, disagree there by more than STEP_SIGMA σ
    step = np.zeros((max(ny - 1, 1), max(nx - 1, 1)), np.bool_)
    for a in range(max(ny - 1, 1)):
        b = min(a + 1, ny - 1)
        for k in range(max(nx - 1, 1)):
            k1 = min(k + 1, nx - 1)
            smin = min(min(sgg[a, k], sgg[a, k1]), min(sgg[b, k], sgg[b, k1]))
            for py in (cy[a], 0.5 * (cy[a] + cy[b]), cy[b]):
                for px in (cx[k], 0.5 * (cx[k] + cx[k1]), cx[k1]):
                    lo = 1e300
                    hi = -1e300
                    for ty, tx in ((a, k), (a, k1), (b, k), (b, k1)):
                        p = bgg[ty, tx] + gxx[ty, tx] * (px - cx[tx]) + gyy[ty, tx] * (py - cy[ty])
                        lo = min(lo, p)
                        hi = max(hi, p)
                    if hi - lo > STEP_SIGMA * smin:
                        step[a, k] = True
    d = np.empty((h, w), np.float32)
    sg = np.empty((h, w), np.float32)
    lv = np.empty(4)
    sv = np.empty(4)
    for r in range(h):
        a = y0[r]
        b = min(a + 1, ny - 1)
        t = fy[r]
        for c in range(w):
            k = x0[c]
            k1 = min(k + 1, nx - 1)
            u = fx[c]
            if step[min(a, step.shape[0] - 1), min(k, step.shape[1] - 1)]:
                j = 0
                for ty, tx in ((a, k), (a, k1), (b, k), (b, k1)):
                    lv[j] = bgg[ty, tx] + gxx[ty, tx] * (c - cx[tx]) + gyy[ty, tx] * (r - cy[ty])
                    sv[j] = sgg[ty, tx]
                    j += 1
                x = img[r, c]
                best = 0
                for j in range(1, 4):
                    if abs(x - lv[j]) < abs(x - lv[best]):
                        best = j
                d[r, c] = x - lv[best]
                sg[r, c] = sv[best]
            else:
                w00 = (1.0 - t) * (1.0 - u)
                w01 = (1.0 - t) * u
                w10 = t * (1.0 - u)
                w11 = t * u
                d[r, c] = img[r, c] - (w00 * bgg[a, k] + w01 * bgg[a, k1] + w10 * bgg[b, k] + w11 * bgg[b, k1])
                sg[r, c] = w00 * sgg[a, k] + w01 * sgg[a, k1] + w10 * sgg[b, k] + w11 * sgg[b, k1]
    return d, sg, bgg, sgg


@njit(cache=True)
def smooth3(d):
    """3×3 binomial smoothing ([1 2 1]ᵀ[1 2 1]/16, border pixels replicated)."""
    h, w = d.shape
    tmp = np.empty((h, w), np.float32)
    for r in range(h):
        for c in range(w):
            tmp[r, c] = d[r, max(c - 1, 0)] + 2.0 * d[r, c] + d[r, min(c + 1, w - 1)]
    out = np.empty((h, w), np.float32)
    for r in range(h):
        ra = max(r - 1, 0)
        rb = min(r + 1, h - 1)
        for c in range(w):
            out[r, c] = (tmp[ra, c] + 2.0 * tmp[r, c] + tmp[rb, c]) * 0.0625
    return out


@njit(cache=True)
def detection_mask(d, tile, n_sigma):
    """Pixels where the smoothed excess exceeds its own local level by ``n_sigma`` × its own
    local noise (both per tile, bilinear): correlated noise (JPEG blocks, demosaiced colour,
    binned sensors) raises the smoothed noise, and the threshold with it."""
    h, w = d.shape
    s = smooth3(d)
    mg, sgm = background_grid(s, tile)
    ny, nx = mg.shape
    y0, fy = _axis_table(h, tile, ny)
    x0, fx = _axis_table(w, tile, nx)
    rm = np.empty(nx)
    rs = np.empty(nx)
    mask = np.empty((h, w), np.bool_)
    for r in range(h):
        a = y0[r]
        b = min(a + 1, ny - 1)
        t = fy[r]
        for k in range(nx):
            rm[k] = (1.0 - t) * mg[a, k] + t * mg[b, k]
            rs[k] = (1.0 - t) * sgm[a, k] + t * sgm[b, k]
        for c in range(w):
            k = x0[c]
            k1 = min(k + 1, nx - 1)
            u = fx[c]
            lev = (1.0 - u) * rm[k] + u * rm[k1]
            sig = (1.0 - u) * rs[k] + u * rs[k1]
            mask[r, c] = s[r, c] > lev + n_sigma * sig
    return mask


@njit(cache=True)
def _components(img, d, tile, n_sigma, saturation):
    """Label the smoothed-excess mask; per component (row of the returned (m, N_STATS)):
    0 area, 1 flux Σ(I−B), 2 peak I−B, 3 peak row, 4 peak col, 5 Σw·c, 6 Σw·r, 7 Σw·c²,
    8 Σw·r², 9 Σw·c·r (w = max(I−B, 0)), 10 saturated pixels, 11 touches border, 12 Σw."""
    h, w = img.shape
    mask = detection_mask(d, tile, n_sigma)
    labels = np.zeros((h, w), np.int32)
    stack = np.empty(h * w, np.int64)
    stats = np.zeros((MAX_COMPONENTS, N_STATS))
    m = 0
    for r0 in range(h):
        for c0 in range(w):
            if not mask[r0, c0] or labels[r0, c0] != 0:
                continue
            if m == MAX_COMPONENTS:      # full (frames of noise or daylight, which fail anyway)
                continue
            m += 1
            labels[r0, c0] = m
            top = 0
            stack[top] = r0 * w + c0
            top += 1
            st = stats[m - 1]
            st[2] = -1e30
            while top > 0:
                top -= 1
                p = stack[top]
                r = p // w
                c = p - r * w
                v = d[r, c]
                st[0] += 1
                st[1] += v
                if v > st[2]:
                    st[2] = v
                    st[3] = r
                    st[4] = c
                wv = max(v, 0.0)
                st[5] += wv * c
                st[6] += wv * r
                st[7] += wv * c * c
                st[8] += wv * r * r
                st[9] += wv * c * r
                st[12] += wv
                if img[r, c] >= saturation:
                    st[10] += 1
                if r == 0 or c == 0 or r == h - 1 or c == w - 1:
                    st[11] = 1
                for dr in range(-1, 2):
                    rr = r + dr
                    if rr < 0 or rr >= h:
                        continue
                    for dc in range(-1, 2):
                        cc = c + dc
                        if cc < 0 or cc >= w:
                            continue
                        if mask[rr, cc] and labels[rr, cc] == 0:
                            labels[rr, cc] = m
                            stack[top] = rr * w + cc
                            top += 1
    return stats[:m]


@njit(cache=True)
def _window_centroid(d, u0, v0, sigma_w, iters):
    """Gaussian-windowed centroid (XWIN iteration) of the background-subtracted frame ``d``."""
    h, w = d.shape
    u, v = u0, v0
    rad = int(math.ceil(3.5 * sigma_w)) + 1
    inv2s2 = 1.0 / (2.0 * sigma_w * sigma_w)
    for _ in range(iters):
        su = 0.0
        sv = 0.0
        sw = 0.0
        ic = int(round(u))
        ir = int(round(v))
        for r in range(max(0, ir - rad), min(h, ir + rad + 1)):
            for c in range(max(0, ic - rad), min(w, ic + rad + 1)):
                du = c - u
                dv = r - v
                g = math.exp(-(du * du + dv * dv) * inv2s2) * d[r, c]
                su += g * du
                sv += g * dv
                sw += g
        if sw <= 0.0:
            return u0, v0
        du = 2.0 * su / sw
        dv = 2.0 * sv / sw
        if abs(du) > rad or abs(dv) > rad:
            return u0, v0
        u += du
        v += dv
        if du * du + dv * dv < 1e-8:
            break
    if abs(u - u0) > rad or abs(v - v0) > rad:
        return u0, v0
    return u, v


@njit(cache=True)
def measure(img, d, sg, tile, n_sigma, saturation, max_area, max_radius_px, max_sharpness, max_elongation):
    """Spots of one frame (``d`` background-subtracted, ``sg`` noise map): (n, 11) [u, v, flux,
    peak, area, radius, elongation, sharpness, snr, flags, noise], unsorted."""
    stats = _components(img, d, tile, n_sigma, saturation)
    h, w = img.shape
    n = stats.shape[0]
    out = np.empty((n, 11))
    k = 0
    for i in range(n):
        st = stats[i]
        if st[12] <= 0.0 or st[0] < 2:
            continue
        sw = st[12]
        cu = st[5] / sw
        cv = st[6] / sw
        cuu = max(st[7] / sw - cu * cu, 0.0)
        cvv = max(st[8] / sw - cv * cv, 0.0)
        cuv = st[9] / sw - cu * cv
        tr = cuu + cvv
        det = cuu * cvv - cuv * cuv
        disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
        l1 = tr / 2.0 + disc
        l2 = max(tr / 2.0 - disc, 1e-6)
        elong = math.sqrt(l1 / l2)
        radius = math.sqrt(tr)
        pr = int(st[3])
        pc = int(st[4])
        peak = st[2]
        s8 = 0.0
        n8 = 0
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if (dr != 0 or dc != 0) and 0 <= pr + dr < h and 0 <= pc + dc < w:
                    s8 += d[pr + dr, pc + dc]
                    n8 += 1
        sharp = (peak - s8 / max(n8, 1)) / peak if peak > 0 else 0.0
        flags = 0
        if st[10] > 0:
            flags |= FLAG_SATURATED
        if sharp > max_sharpness and st[10] == 0:
            flags |= FLAG_HOT
        if elong > max_elongation:
            flags |= FLAG_ELONGATED
        fill = st[1] / (peak * st[0]) if peak > 0 else 1.0
        if st[0] > max_area or radius > max_radius_px or (st[10] == 0 and st[0] >= 12 and fill > FLAT_FILL):
            flags |= FLAG_EXTENDED
        if st[11] > 0:
            flags |= FLAG_EDGE
        u, v = cu, cv
        if (flags & (FLAG_SATURATED | FLAG_EXTENDED | FLAG_HOT)) == 0:
            sig_w = min(max(radius / math.sqrt(2.0) * 1.2, 0.8), 6.0)
            u, v = _window_centroid(d, cu, cv, sig_w, 20)
        noise = sg[pr, pc]
        out[k, 0] = u
        out[k, 1] = v
        out[k, 2] = st[1]
        out[k, 3] = peak
        out[k, 4] = st[0]
        out[k, 5] = radius
        out[k, 6] = elong
        out[k, 7] = sharp
        out[k, 8] = st[1] / (noise * math.sqrt(st[0]))
        out[k, 9] = flags
        out[k, 10] = noise
        k += 1
    return out[:k]


@dataclasses.dataclass(frozen=True)
class Detection:
    """Spots of one frame, brightest first. Columns of ``spots`` (n, 11): u, v (px, [column,
    row]), flux (DN, Σ of background-subtracted pixels), peak (DN above background), area (px),
    radius (px, RMS), elongation (axis ratio), sharpness, snr, flags (:data:`FLAG_NAMES` bits),
    noise (DN, local σ). ``background_dn``/``noise_dn``: the frame's median background and σ."""

    spots: np.ndarray
    background_dn: float
    noise_dn: float
    width: int
    height: int

    COLUMNS = ("u", "v", "flux", "peak", "area", "radius", "elongation", "sharpness", "snr", "flags", "noise")

    def col(self, name: str) -> np.ndarray:
        return self.spots[:, self.COLUMNS.index(name)]

    @property
    def flags(self) -> np.ndarray:
        return self.col("flags").astype(np.int64)

    def usable(self) -> np.ndarray:
        """(n,) bool: spots a solver takes (not hot or extended; elongated only in a trailed frame)."""
        flags = self.flags
        bad = (flags & (FLAG_HOT | FLAG_EXTENDED)) != 0
        good = ~bad
        trailed = good.sum() >= 5 and np.mean((flags[good] & FLAG_ELONGATED) != 0) > 0.5
        if not trailed:
            bad |= (flags & FLAG_ELONGATED) != 0
        return ~bad

    def for_solving(self, max_spots: int) -> tuple[np.ndarray, np.ndarray]:
        """(xy (k, 2) [column, row] px, rows (k,) into ``spots``) of the usable spots, brightest first."""
        rows = np.flatnonzero(self.usable())[:max_spots]
        return self.spots[rows, :2].copy(), rows


def _flag_large(raw: np.ndarray, factor: float) -> None:
    """Flag as extended the spots wider than ``factor`` × the median RMS radius of the frame's
    20 brightest compact spots (at least 2 px): a diffuse glow or cloud is wider than the
    frame's stars, whatever their focus."""
    compact = (raw[:, 9].astype(np.int64) & (FLAG_SATURATED | FLAG_HOT | FLAG_EXTENDED | FLAG_EDGE)) == 0
    if compact.sum() < 5:
        return
    top = np.argsort(-raw[compact, 2])[:20]
    typical = max(float(np.median(raw[compact][top, 5])), 2.0 / factor)
    wide = raw[:, 5] > factor * typical
    raw[wide, 9] = raw[wide, 9].astype(np.int64) | FLAG_EXTENDED


def flag_text(flags: int) -> str:
    return ",".join(name for bit, name in FLAG_NAMES.items() if flags & bit) or "ok"


def detect_stars(img: np.ndarray, saturation: float | None = None, n_sigma: float = 5.0, tile: int = 64,
                 max_area: int | None = None, max_radius_px: float = 8.0, max_sharpness: float = 0.9,
                 max_elongation: float = 3.0, max_radius_factor: float = 3.0) -> Detection:
    """Spots of the frame ``img`` (h, w) (see the module docstring). ``saturation``: the full-scale
    pixel value (None: the frame's own maximum counts as saturated only if ≥ 3 pixels share it)."""
    img = np.ascontiguousarray(img, dtype=np.float32)
    h, w = img.shape
    if saturation is None:
        top = float(img.max())
        saturation = top if np.count_nonzero(img >= top) >= 3 else math.inf
    if max_area is None:
        max_area = max(400, h * w // 2000)
    tile = int(min(tile, max(8, min(h, w) // 2)))
    d, sg, bgg, sgg = excess_and_noise(img, tile)
    raw = measure(img, d, sg, tile, float(n_sigma), float(saturation), float(max_area), float(max_radius_px),
                  float(max_sharpness), float(max_elongation))
    _flag_large(raw, max_radius_factor)
    order = np.argsort(-raw[:, 2], kind="stable")
    return Detection(raw[order], float(np.median(bgg)), float(np.median(sgg)), w, h)
