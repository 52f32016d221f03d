"""numba kernels of the loop's image cycle: plan a frame's windows, measure their spots.

Both work on whole frames (every tracked star in one call) so the image cycle costs no
per-star Python. Pixel coordinates are (u, v) = (column, row) with integer pixel centres;
``cam`` is :meth:`gyrostar.camera.Camera.as_array`.

* :func:`plan_windows` — for each tracked star (brightest first) predict its spot
  trajectory over the coming exposure from the gyro rates (paper 000's spot motion,
  :func:`gyrostar.core.motion.predict_trajectory`) and build its trajectory window
  (:func:`gyrostar.core.windows.trajectory_window`) within the head's pixel and span
  budgets; returns the span set sorted by window id (= star slot), the chosen slots and
  each one's trajectory offsets about its mean (the smeared-spot model of the fit).
* :func:`measure_windows` — for each planned window: background, thresholded CoG, then
  the smeared-PSF fit (:func:`gyrostar.core.centroid.smear_fit`); returns the measured
  unit direction in the body frame at exposure mid-time and its 1σ (rad). ``nogil``: the
  head port runs it on its worker thread, beside the 400 Hz path.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..camera import P_CX, P_CY, P_F, unproject_point
from ..core.centroid import cog, smear_fit, window_background, window_spans_of
from ..core.motion import predict_trajectory, substeps_for
from ..core.windows import trajectory_window
from .kernels import project_refs

MEAS_OK = 0        # direction measured
MEAS_MISS = 1      # window read, no spot above threshold (or too faint)
SIGMA_FLOOR_PX = 0.005  # px: least centroid σ reported (the fit's own σ is below it only for saturating stars)
MEAS_ABSENT = 2    # the window is not in the readout
MEAS_HIT = 3       # a spot not taken: its shape (one sharp pixel) or its flux (far above what its catalog
                   # magnitude and the frame's other stars predict) says radiation hit, hot pixel or glare
MEAS_BRIGHT = 4    # the window's background is near the converter's full scale (Sun, Earth limb, Moon):
                   # nothing can be measured there; not a miss (the star is not gone)

# Fault detection thresholds (docs/RELIABILITY.md, "what gyrostar tolerates").
# A star's PSF (σ ≥ 0.5 px) puts at most 47 % of its 3×3 flux into one pixel (σ = 0.85 px:
# 23 %); a radiation hit or a hot pixel puts nearly all of it there.
PEAK_FRACTION_MAX = 0.6
PEAK_MIN_SNR = 8.0         # the shape is judged only when the 3×3 excess is this many noise σ
# flux × 10^(0.4·V) is one constant for every star of a frame (the optics' zero point, the same
# exposure): a spot this many times above the frame's median is not its star alone. 10 (2.5 mag)
# leaves room for colour: a red star is up to ~2 mag brighter on silicon than its V says
FLUX_RATIO_MAX = 10.0
FLUX_MIN_STARS = 3         # stars with a magnitude a frame needs before the flux check runs
BRIGHT_FRACTION = 0.75     # a window whose background is above this fraction of full scale is MEAS_BRIGHT


@njit(cache=True)
def plan_windows(uv, slots, rates, dt, bias, cam, model, substeps, skip, k, n_rows, n_cols,
                 pixel_budget, max_window_pixels, max_spans):
    """Windows for the next exposure of the stars ``slots`` (brightest first) at ``uv`` (n, 2).

    ``rates`` (m, 3) rad/s measured rates held ``dt`` s each, from now; the first ``skip``
    trajectory points (the command-to-exposure lag) are dropped. Returns ``(spans (s, 4)
    int32 sorted by window id then row, wins (w,) int64 chosen slots ascending, offsets
    (M, 2) px about each trajectory's mean, off_start (w,), off_len (w,))``. A star whose
    window is empty (off the sensor) or would exceed a budget is left out.
    """
    n = slots.shape[0]
    cx = cam[P_CX]
    cy = cam[P_CY]
    f = cam[P_F]
    all_spans = np.empty((max_spans, 4), np.int32)
    s_start = np.zeros(n, np.int64)
    s_len = np.zeros(n, np.int64)
    npts = rates.shape[0] * substeps + 1 - skip
    if npts < 1:
        npts = 1
        skip = rates.shape[0] * substeps
    trajs = np.empty((n, npts, 2))
    chosen = np.zeros(n, np.bool_)
    used_spans = 0
    budget = pixel_budget
    for j in range(n):
        tr = predict_trajectory(uv[j, 0] - cx, uv[j, 1] - cy, rates, dt, bias, f, model, substeps)
        for i in range(npts):
            trajs[j, i, 0] = tr[skip + i, 0] + cx
            trajs[j, i, 1] = tr[skip + i, 1] + cy
        sp = trajectory_window(trajs[j], k, n_rows, n_cols, slots[j])
        npx = 0
        for i in range(sp.shape[0]):
            npx += sp[i, 3] - sp[i, 2]
        if sp.shape[0] == 0 or npx > max_window_pixels or npx > budget or used_spans + sp.shape[0] > max_spans:
            continue
        budget -= npx
        s_start[j] = used_spans
        s_len[j] = sp.shape[0]
        all_spans[used_spans:used_spans + sp.shape[0]] = sp
        used_spans += sp.shape[0]
        chosen[j] = True
    order = np.argsort(slots)
    nw = 0
    for j in range(n):
        if chosen[j]:
            nw += 1
    spans = np.empty((used_spans, 4), np.int32)
    wins = np.empty(nw, np.int64)
    off = np.empty((nw * npts, 2))
    off_start = np.empty(nw, np.int64)
    off_len = np.empty(nw, np.int64)
    a = 0
    w = 0
    for jj in range(n):
        j = order[jj]
        if not chosen[j]:
            continue
        spans[a:a + s_len[j]] = all_spans[s_start[j]:s_start[j] + s_len[j]]
        a += s_len[j]
        wins[w] = slots[j]
        mu = 0.0
        mv = 0.0
        for i in range(npts):
            mu += trajs[j, i, 0]
            mv += trajs[j, i, 1]
        mu /= npts
        mv /= npts
        off_start[w] = w * npts
        off_len[w] = npts
        for i in range(npts):
            off[w * npts + i, 0] = trajs[j, i, 0] - mu
            off[w * npts + i, 1] = trajs[j, i, 1] - mv
        w += 1
    return spans, wins, off, off_start, off_len


@njit(cache=True)
def plan_tracked(active, nav, vmag, refs, q, omega, bias, m, lag_s, dt, cam, model, k, n_rows, n_cols,
                 pixel_budget, max_window_pixels, max_spans):
    """:func:`plan_windows` for the tracked slots (``active``), brightest first (``vmag`` of
    their navigation stars ``nav``, ties in slot order), at their places under attitude ``q``
    moved on by the rate ``omega`` over the lag ``lag_s`` (s, to the exposure start: exact,
    not in whole gyro samples — at 10 °/s one sample is 2.9 px), with ``omega + bias`` held
    over ``m`` exposure samples of ``dt`` s. Returns plan_windows' arrays and the chosen
    slots' navigation stars."""
    act = np.flatnonzero(active)
    mags = np.empty(act.shape[0])
    for i in range(act.shape[0]):
        mags[i] = vmag[nav[act[i]]]
    order = act[np.argsort(mags, kind="mergesort")].astype(np.int64)
    uv, _ = project_refs(cam, q, np.ascontiguousarray(refs[order]))
    rates = np.empty((m, 3))
    meas = np.empty((m, 3))
    for i in range(m):
        for j in range(3):
            rates[i, j] = omega[j] + bias[j]
            meas[i, j] = rates[i, j] - bias[j]
    if lag_s > 0.0:
        sub_lag = substeps_for(meas[:1], lag_s, cam[P_F], 0.5)
        for j in range(uv.shape[0]):
            tr = predict_trajectory(uv[j, 0] - cam[P_CX], uv[j, 1] - cam[P_CY], rates[:1], lag_s, bias, cam[P_F],
                                    model, sub_lag)
            uv[j, 0] = tr[-1, 0] + cam[P_CX]
            uv[j, 1] = tr[-1, 1] + cam[P_CY]
    sub = substeps_for(meas, dt, cam[P_F], 0.5)
    spans, wins, off, off_start, off_len = plan_windows(uv, order, rates, dt, bias, cam, model, sub, 0, k,
                                                        n_rows, n_cols, pixel_budget, max_window_pixels, max_spans)
    nav_wins = np.empty(wins.shape[0], nav.dtype)
    for i in range(wins.shape[0]):
        nav_wins[i] = nav[wins[i]]
    return spans, wins, off, off_start, off_len, nav_wins


@njit(cache=True, nogil=True)
def measure_windows(spans, values, wins, off, off_start, off_len, cam, psf_sigma, thresh_sigma, min_signal,
                    e_per_dn, n_iter, tol, vmag, bright_dn):
    """Spot directions of the windows ``wins`` in one readout (``values`` in span order).

    Returns ``(state (w,) int8 MEAS_*, b (w, 3) unit body direction at exposure mid-time,
    sigma (w,) rad)``. A window's spot is its thresholded CoG (threshold
    ``thresh_sigma`` noise σ above the window background; ≥ 2 pixels and ``min_signal`` DN
    needed) refined by the smeared-PSF fit along its predicted trajectory offsets; when the
    fit diverges (> 2 px from the CoG) the CoG is kept with σ = 0.3 px.

    Fault detection (no spot is taken that is not its star's): a window whose background is
    above ``bright_dn`` (DN) is ``MEAS_BRIGHT``; a spot whose brightest pixel holds more than
    ``PEAK_FRACTION_MAX`` of its 3×3 excess, or (with ``FLUX_MIN_STARS`` measured stars of known
    ``vmag`` (w,), nan: unknown) whose flux × 10^(0.4·V) is more than ``FLUX_RATIO_MAX`` times
    the frame's median, is ``MEAS_HIT``.
    """
    nw = wins.shape[0]
    state = np.full(nw, MEAS_ABSENT, np.int8)
    b = np.zeros((nw, 3))
    sig = np.full(nw, np.inf)
    zp = np.full(nw, np.nan)          # log10(flux) + 0.4·V of each measured spot
    f = cam[P_F]
    for i in range(nw):
        a, e, v0 = window_spans_of(spans, wins[i])
        if e <= a:
            continue
        sp = spans[a:e]
        npx = 0
        for r in range(sp.shape[0]):
            npx += sp[r, 3] - sp[r, 2]
        if v0 + npx > values.shape[0]:
            continue
        wv = values[v0:v0 + npx]
        bg, noise = window_background(wv, 3.0)
        if bg > bright_dn:
            state[i] = MEAS_BRIGHT
            continue
        u, v, flux, npix = cog(sp, wv, bg, bg + thresh_sigma * noise)
        if npix < 2 or flux < min_signal:
            state[i] = MEAS_MISS
            continue
        peak, box = peak_excess(sp, wv, bg)
        if box > PEAK_MIN_SNR * 3.0 * noise and peak > PEAK_FRACTION_MAX * box:
            state[i] = MEAS_HIT
            continue
        if math.isfinite(vmag[i]):
            zp[i] = math.log10(flux) + 0.4 * vmag[i]
        o = off[off_start[i]:off_start[i] + off_len[i]]
        fu, fv, _, var_u, var_v, _ = smear_fit(sp, wv, bg, u, v, o, psf_sigma, noise * noise, e_per_dn,
                                               n_iter, tol)
        if math.isfinite(fu) and math.isfinite(fv) and abs(fu - u) < 2.0 and abs(fv - v) < 2.0:
            u = fu
            v = fv
            var = max(0.5 * (var_u + var_v), SIGMA_FLOOR_PX ** 2)
        else:
            var = 0.3 ** 2
        d = unproject_point(cam, u, v)
        b[i, 0] = d[0]
        b[i, 1] = d[1]
        b[i, 2] = d[2]
        sig[i] = math.sqrt(var) / f
        state[i] = MEAS_OK
    flux_outliers(state, zp)
    return state, b, sig


@njit(cache=True)
def flux_outliers(state, zp):
    """Mark ``MEAS_HIT`` (in place) the measured spots whose zero point ``zp`` (log10 flux +
    0.4·V; nan: unknown) lies more than log10(``FLUX_RATIO_MAX``) above the median of the
    frame's others, when ``FLUX_MIN_STARS`` or more are known."""
    known = np.flatnonzero((state == MEAS_OK) & np.isfinite(zp))
    if known.shape[0] < FLUX_MIN_STARS:
        return
    lim = math.log10(FLUX_RATIO_MAX)
    vals = zp[known]
    for j in range(known.shape[0]):
        others = np.delete(vals, j)
        if vals[j] - np.median(others) > lim:
            state[known[j]] = MEAS_HIT


@njit(cache=True)
def peak_excess(sp, wv, bg):
    """(brightest pixel's excess over ``bg``, excess summed over the 3×3 pixels around it) of
    one window (its spans ``sp`` and values ``wv``)."""
    best = -np.inf
    r0 = 0
    c0 = 0
    k = 0
    for j in range(sp.shape[0]):
        for col in range(sp[j, 2], sp[j, 3]):
            if wv[k] > best:
                best = wv[k]
                r0 = sp[j, 1]
                c0 = col
            k += 1
    box = 0.0
    k = 0
    for j in range(sp.shape[0]):
        row = sp[j, 1]
        for col in range(sp[j, 2], sp[j, 3]):
            if abs(row - r0) <= 1 and abs(col - c0) <= 1:
                box += wv[k] - bg
            k += 1
    return best - bg, box


@njit(cache=True)
def select_measured(wins, nav_planned, state, b_mid, sig, active, nav, misses, refs, cam_var, coast):
    """The measured stars of one readout the filter may take, in window order: windows whose
    slot still tracks the star the plan was made for (``active[slot]`` and ``nav[slot] ==
    nav_planned``) with a spot measured (``MEAS_OK``); a live window that missed its spot
    counts a miss (``misses`` in place). ``coast``: none is taken (the body turns faster than
    the centroid model holds). σ is combined with the camera model's variance ``cam_var``
    (rad², when > 0). Returns ``(slots (k,), b (k, 3), refs (k, 3), σ (k,) rad)``."""
    n = wins.shape[0]
    take = np.zeros(n, np.bool_)
    k = 0
    for i in range(n):
        s = wins[i]
        if not (active[s] and nav[s] == nav_planned[i]):
            continue
        if state[i] == MEAS_MISS:
            misses[s] += 1
        elif state[i] == MEAS_OK and not coast:
            take[i] = True
            k += 1
    slots = np.empty(k, wins.dtype)
    b = np.empty((k, 3))
    r = np.empty((k, 3))
    sg = np.empty(k)
    j = 0
    for i in range(n):
        if take[i]:
            s = wins[i]
            slots[j] = s
            for a in range(3):
                b[j, a] = b_mid[i, a]
                r[j, a] = refs[s, a]
            sg[j] = math.sqrt(sig[i] * sig[i] + cam_var) if cam_var > 0 else sig[i]
            j += 1
    return slots, b, r, sg


@njit(cache=True)
def lost_slots(active, uv, misses, width, height, max_misses, tracking):
    """Tracked slots whose star has left the sensor (its predicted centroid ``uv`` (S, 2) px
    within 2 px of an edge of the ``width`` × ``height`` px sensor) or, when ``tracking``,
    missed more than ``max_misses`` images in a row. Returns the slots (k,) int64, ascending."""
    n = active.shape[0]
    gone = np.empty(n, np.int64)
    k = 0
    for s in range(n):
        if not active[s]:
            continue
        u = uv[s, 0]
        v = uv[s, 1]
        if u < 2 or v < 2 or u > width - 3 or v > height - 3 or (tracking and misses[s] > max_misses):
            gone[k] = s
            k += 1
    return gone[:k]


@njit(cache=True)
def score_slots(slots, accepted, misses, rejects, wrong_id_rejects):
    """Record the filter's verdict on the measured ``slots`` (k,): an accepted star's miss and
    reject counts restart, a rejected one's reject count grows (``misses``, ``rejects`` (S,)
    in place). Returns the rejected slots that have now failed ``wrong_id_rejects`` times in a
    row (int64, in ``slots`` order)."""
    k = slots.shape[0]
    wrong = np.empty(k, np.int64)
    n = 0
    for i in range(k):
        s = slots[i]
        if accepted[i]:
            misses[s] = 0
            rejects[s] = 0
        else:
            rejects[s] += 1
            if rejects[s] >= wrong_id_rejects:
                wrong[n] = s
                n += 1
    return wrong[:n]
