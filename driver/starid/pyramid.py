"""Pyramid lost-in-space identification (Mortari, Samaan, Bruccoleri & Junkins 2004).

Input: centroids (px) of one image, brightest first, and the camera model; output the
navigation star of each centroid (or -1) and the attitude, accepted only when the
analytic expected number of false matches is below ``p_false_max`` and the QUEST
residuals of every identified star are within ``label_tol``.

1. Triangles (i, j, k) of the observed stars in Mortari's smart order (index gaps
   dj, dk grow slowly, so a spurious star spoils few consecutive triangles), first among
   the brightest 8 spots, then 12, 16, 24 and all (adaptive spot budget; a wider budget
   tries only the triangles with a new spot). With a thinned first tier (``fast_index``:
   the brightest few navigation stars per field) the brightest spots are tried against
   it before the full index.
2. Each side θ looks up the catalog pairs within θ ± ε with the k-vector; candidate
   catalog triangles (x, y, z) need all three sides and the same handedness
   (mirror test: sign of b_i·(b_j×b_k) = sign of r_x·(r_y×r_z)).
3. A fourth observed star r confirms a candidate when exactly one catalog star w has
   all three angles to x, y, z within ε (w is looked up in the voxel grid around r's
   direction predicted by the candidate's triad); a triangle is accepted when exactly
   one of its candidates is confirmed.
4. QUEST on the pyramid, then every other centroid (all of them, whatever the budget) is
   labelled with the nearest catalog star within ``label_tol`` of its predicted direction
   (any indexed star: an index built with ``label_depth_mag`` holds stars fainter than its
   navigation stars, which the sensor sees now and then; only navigation stars form pyramids);
   QUEST again over all and the residual test of :mod:`gyrostar.starid.verify`.
5. The per-star check (:class:`gyrostar.starid.star_check.StarCheck`, swappable): each
   label's own χ² (position, and magnitude when given) after QUEST; failures are
   unlabelled, the attitude re-solved over the rest, and fewer than three reject.
6. The absent-star check (:mod:`gyrostar.starid.absent`): a catalog star the sensor surely
   detects that the attitude puts on the sensor with no spot near it rejects the solution
   (``absent_max`` such stars allowed, default 0).
7. With ``faint`` (:mod:`gyrostar.starid.faint`: the catalog stars the index leaves out, a
   little fainter than its limit), a label whose spot lies within ``label_tol`` of such a
   star is dropped (the spot may be that star, its index neighbour missed), the attitude
   solved again over the rest; fewer than three labels left reject.

Expected false matches for a sky of N navigation stars and tolerance ε (rad): a triangle
with side θ_ij and angle φ_k at vertex k:  E₃ = N ρ² ε³ sin θ_ij / (π sin φ_k)
(N choices of x, ρ ε sin θ_ij stars in the band around x, ρ ε²/(π sin φ_k) stars in the
intersection of the two other bands on the mirror-correct side), where ρ is the star
density around the candidate written as an all-sky count (N for an average sky; the
galactic plane is up to 2–3 N, and a false match is most likely there); the confirming
star multiplies by ρ ε²/(π sin φ_r) and by the n − 3 spots that could have confirmed;
every further labelled star by ρ' δ²/4 (δ = label_tol, a random spot landing on a star;
ρ' counts every indexed star, not only navigation stars). With measured magnitudes
(``sigma_mag`` > 0) a catalog star stands for a spot only within n_sigma·sigma_mag of its V,
and each star's term is multiplied by the share f(m) of stars that window admits. Of the
false matches inside these tolerances only those that fit as well as the one found count:
the product t of the triangle sides' |Δθ|/ε and the labels' (r/δ)² (r measured from the
pyramid's attitude; each uniform on (0, 1) for a false match) multiplies the count by
t·Σ_{j<k}(−ln t)^j/j! (Fisher's combination of k uniforms). ``p_false`` reported is that
product times the number of triangles tried (a union bound over the search); the search
skips a triangle that could not pass even in a sparse sky (the 5th percentile of the star
density) with every spot labelled: that costs success only, never safety.
A 3-star field is accepted on a unique triangle when E₃ allows it.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..camera import unproject_many
from ..core.quest import quest
from ..errors import ConfigError
from .absent import BLEND_PX, EDGE_PX, MARGIN_MAG, absent_stars
from .faint import drop_near_faint
from .index import StarIndex, cone_query, voxel_span
from .kvector import query
from .result import StarIdResult, to_body_vectors
from .star_check import StarCheck, check_stars
from .verify import body_to_icrs, drop_ambiguous, drop_shared, solve, verify_matches

ST_OK, ST_TOO_FEW, ST_NO_MATCH, ST_REJECTED, ST_STAR_CHECK, ST_SPARSE, ST_BAD, ST_ABSENT = range(8)
STATUS_TEXT = {ST_OK: "ok", ST_TOO_FEW: "fewer than 3 stars", ST_NO_MATCH: "no unique pyramid",
               ST_REJECTED: "rejected by verification", ST_STAR_CHECK: "fewer than 3 stars pass the per-star check",
               ST_SPARSE: "every spot fits one pyramid but too few stars for p_false_max",
               ST_BAD: "centroids must be finite pixel coordinates",
               ST_ABSENT: "the attitude puts surely-seen stars where no spot is"}
_MAX_CAND = 256
RELABEL_WIDE = 3.0   # × label_tol, relabel_wide's first pass: one wrong pyramid member bends the attitude ~100″s


@njit(cache=True)
def _angle(u, v):
    return np.arccos(min(1.0, max(-1.0, u[0] * v[0] + u[1] * v[1] + u[2] * v[2])))


@njit(cache=True)
def _sin_vertex(v, a, b):
    """sin of the spherical angle at vertex ``v`` between the arcs to ``a`` and ``b``."""
    ta = a - (a @ v) * v
    tb = b - (b @ v) * v
    na = np.sqrt(ta @ ta)
    nb = np.sqrt(tb @ tb)
    if na == 0.0 or nb == 0.0:
        return 0.0
    c = (ta @ tb) / (na * nb)
    return np.sqrt(max(0.0, 1.0 - c * c))


@njit(cache=True)
def _triple(a, b, c):
    return a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) + a[2] * (b[0] * c[1] - b[1] * c[0])


@njit(cache=True)
def _triad(b1, b2, r1, r2):
    """Body → ICRS rotation (3, 3) taking ``b1`` onto ``r1`` and the plane of (b1, b2) onto (r1, r2)."""
    out = np.empty((3, 3))
    tb = np.cross(b1, b2)
    tb /= np.sqrt(tb @ tb)
    tr = np.cross(r1, r2)
    tr /= np.sqrt(tr @ tr)
    ub = np.cross(b1, tb)
    ur = np.cross(r1, tr)
    for a in range(3):
        for c in range(3):
            out[a, c] = r1[a] * b1[c] + tr[a] * tb[c] + ur[a] * ub[c]
    return out


@njit(cache=True)
def _mag_ok(smag, vmag, mwin, s, w):
    """Spot ``s`` may be catalog star ``w``: no magnitudes given (``smag`` empty, or NaN for
    ``s``), or |V_w − m_s| ≤ ``mwin``."""
    if smag.shape[0] == 0:
        return True
    m = smag[s]
    return not (abs(vmag[w] - m) > mwin)     # NaN: no gate


_MTAB_LO, _MTAB_STEP, _MTAB_N = -3.0, 0.01, 2001     # magnitude grid of the share tables (V −3 … 17)


def mag_share_table(v: np.ndarray, mwin: float) -> np.ndarray:
    """Per cell [m, m + 0.01) of the magnitude grid: the share of the stars (magnitudes ``v``)
    within ``mwin`` of some m in the cell (an upper bound of :func:`_mag_fraction`'s share,
    at least one star's). Empty when ``mwin`` is 0 (magnitudes not used)."""
    if mwin <= 0.0:
        return np.ones(1)
    sv = np.sort(np.asarray(v, dtype=np.float64))
    edge = _MTAB_LO + _MTAB_STEP * np.arange(_MTAB_N)
    lo = np.searchsorted(sv, edge - mwin, side="left")
    hi = np.searchsorted(sv, edge + _MTAB_STEP + mwin, side="right")
    return np.maximum(hi - lo, 1) / max(len(sv), 1)


@njit(cache=True)
def _mag_fraction(table, m):
    """The chance that a random star passes :func:`_mag_ok` for a spot of measured V ``m``
    (``table`` from :func:`mag_share_table`; 1 for NaN)."""
    if not (m == m) or table.shape[0] < _MTAB_N:
        return 1.0
    k = int(np.floor((m - _MTAB_LO) / _MTAB_STEP))
    return table[min(max(k, 0), _MTAB_N - 1)]


@njit(cache=True)
def _fit_share(b, vec, i, j, k, x, y, z, br, q4, match, eps, label_tol, n_sigma):
    """The share of false matches that fit at least as well as this one (Fisher's combination).

    A false pyramid inside the tolerances has each triangle side's error |θ_obs − θ_cat|/ε
    uniform on (0, 1) (catalog separations are locally uniform), and each further label's
    (r/label_tol)², r its offset from the direction the pyramid's attitude ``q4`` predicts,
    uniform on (0, 1) too (a random star in the tolerance disc). For k such independent
    uniforms the chance that their product is at most the observed t is
    t·Σ_{j<k} (−ln t)^j / j!. The confirming star is not credited (its share is taken as 1).
    An error smaller than the noise says nothing more (a true match's is that small by chance,
    and so is a structured near-match's, a mirror image's stars near its axis): each factor
    is floored at its 1σ value, 1/n_sigma for a side (ε = n_sigma·σ_side) and
    1/(1.25·n_sigma)² for a label (label_tol = 1.25·n_sigma·σ)."""
    side_min = 1.0 / n_sigma
    lab_min = 1.0 / (1.25 * n_sigma) ** 2
    t = 1.0
    kk = 0
    for a, c, ca, cc in ((i, j, x, y), (i, k, x, z), (j, k, y, z)):
        t *= min(1.0, max(abs(_angle(b[a], b[c]) - _angle(vec[ca], vec[cc])) / eps, side_min))
        kk += 1
    m = quat_to_dcm(q4)
    for s in range(b.shape[0]):
        w = match[s]
        if w < 0 or s == i or s == j or s == k or s == br:
            continue
        v = vec[w]
        p = np.empty(3)
        for e in range(3):
            p[e] = m[e, 0] * v[0] + m[e, 1] * v[1] + m[e, 2] * v[2]      # predicted body direction
        r = _angle(b[s], p)
        t *= min(1.0, max((r / label_tol) ** 2, lab_min))
        kk += 1
    lt = -math.log(t)
    term = 1.0
    total = 1.0
    for jj in range(1, kk):
        term *= lt / jj
        total += term
    return min(1.0, t * total)


@njit(cache=True)
def _confirm(b, nb, i, j, k, x, y, z, vec, is_nav, vstart, vstars, vvec, vh, vg, eps, max_sep, smag, vmag, mwin):
    """First observed star r < ``nb``, r ∉ {i,j,k}, with a unique catalog star w fitting all three angles
    (and r's measured magnitude: :func:`_mag_ok`).

    The candidate attitude (triad on the triangle's longest side) predicts r's ICRS direction;
    ``w`` is searched in a cone around it (voxel grid) wide enough for the triad's error, and
    must have all three angles to x, y, z within ε and the same handedness."""
    # triad base: the longest side of the observed triangle
    tij = _angle(b[i], b[j])
    tik = _angle(b[i], b[k])
    tjk = _angle(b[j], b[k])
    if tij >= tik and tij >= tjk:
        m = _triad(b[i], b[j], vec[x], vec[y])
        base = tij
    elif tik >= tjk:
        m = _triad(b[i], b[k], vec[x], vec[z])
        base = tik
    else:
        m = _triad(b[j], b[k], vec[y], vec[z])
        base = tjk
    vx, vy, vz = vec[x], vec[y], vec[z]
    p = np.empty(3)
    for r in range(nb):
        if r == i or r == j or r == k:
            continue
        tri = _angle(b[r], b[i])
        if tri > max_sep - eps or tri < 2.0 * eps:
            continue
        trj = _angle(b[r], b[j])
        trk = _angle(b[r], b[k])
        for a in range(3):
            p[a] = m[a, 0] * b[r, 0] + m[a, 1] * b[r, 1] + m[a, 2] * b[r, 2]
        # the triad's error grows with the distance from its base star over the base length
        radius = eps * (3.0 + 2.0 * max(tri, trj) / base)
        # angle windows as cosine windows: |θ − t| ≤ ε  ⇔  cos(t+ε) ≤ cos θ ≤ cos(t−ε)
        ci_lo, ci_hi = np.cos(tri + eps), np.cos(max(tri - eps, 0.0))
        cj_lo, cj_hi = np.cos(trj + eps), np.cos(max(trj - eps, 0.0))
        ck_lo, ck_hi = np.cos(trk + eps), np.cos(max(trk - eps, 0.0))
        hand = np.sign(_triple(b[i], b[j], b[r]))
        found = -1
        nfound = 0
        # voxel cells around the prediction (cone_query inline, without its allocation)
        chord = 2.0 * np.sin(radius / 2.0)
        cosr = np.cos(radius)
        lo0, hi0, lo1, hi1, lo2, hi2 = voxel_span(p, chord, vh, vg)
        for c0 in range(lo0, hi0 + 1):
            for c1 in range(lo1, hi1 + 1):
                cell = (c0 * vg + c1) * vg
                for t in range(vstart[cell + lo2], vstart[cell + hi2 + 1]):
                    vw = vvec[t]
                    if vw[0] * p[0] + vw[1] * p[1] + vw[2] * p[2] < cosr:
                        continue
                    w = vstars[t]
                    if w == x or w == y or w == z or not is_nav[w] or not _mag_ok(smag, vmag, mwin, r, w):
                        continue
                    d = vw[0] * vx[0] + vw[1] * vx[1] + vw[2] * vx[2]
                    if d < ci_lo or d > ci_hi:
                        continue
                    d = vw[0] * vy[0] + vw[1] * vy[1] + vw[2] * vy[2]
                    if d < cj_lo or d > cj_hi:
                        continue
                    d = vw[0] * vz[0] + vw[1] * vz[1] + vw[2] * vz[2]
                    if d < ck_lo or d > ck_hi:
                        continue
                    if np.sign(_triple(vx, vy, vw)) == hand:
                        found = w
                        nfound += 1
        if nfound == 1:
            return r, found
    return -1, -1


@njit(cache=True)
def _triangle_candidates(b, i, j, k, vec, pt, pa, pb, kv, km, kq, eps, mark, nxt, oth, cand, smag, vmag, mwin):
    """Catalog triangles (x, y, z) matching observed (i, j, k): all three sides within ε,
    the same handedness and each star's magnitude (:func:`_mag_ok`). Writes up to
    ``_MAX_CAND`` rows of ``cand``; returns their count (more than ``_MAX_CAND``: too many to
    be useful) and the work arrays ``nxt``/``oth`` (grown when needed). ``mark`` int32 (N,) zeros, left zeroed.

    The side with the fewest pairs in its window (k-vector) is scanned, in both orders (P, Q);
    the shorter of the other two sides' ranges is threaded into per-star linked lists (heads
    in ``mark``, 1-based), and each scanned pair walks the list of its end on that side and
    tests the third side by its cosine window: one pass over two of the ranges."""
    tij = _angle(b[i], b[j])
    tik = _angle(b[i], b[k])
    tjk = _angle(b[j], b[k])
    s1, e1 = query(pt, kv, km, kq, tij - eps, tij + eps)
    s2, e2 = query(pt, kv, km, kq, tik - eps, tik + eps)
    s3, e3 = query(pt, kv, km, kq, tjk - eps, tjk + eps)
    if e1 == s1 or e2 == s2 or e3 == s3:
        return 0, nxt, oth
    # roles: P–Q the scanned side, R the third spot; cP, cQ, cR their columns in ``cand``
    if e1 - s1 <= e2 - s2 and e1 - s1 <= e3 - s3:
        P, Q, R, cP, cQ, cR = i, j, k, 0, 1, 2
        sS, eS, sA, eA, sB, eB, tPR, tQR = s1, e1, s2, e2, s3, e3, tik, tjk
    elif e2 - s2 <= e3 - s3:
        P, Q, R, cP, cQ, cR = i, k, j, 0, 2, 1
        sS, eS, sA, eA, sB, eB, tPR, tQR = s2, e2, s1, e1, s3, e3, tij, tjk
    else:
        P, Q, R, cP, cQ, cR = j, k, i, 1, 2, 0
        sS, eS, sA, eA, sB, eB, tPR, tQR = s3, e3, s1, e1, s2, e2, tij, tik
    # thread the shorter range: from P's star (P–R pairs) or from Q's (Q–R pairs)
    from_p = (eA - sA) <= (eB - sB)
    if from_p:
        s, e = sA, eA
        c_lo, c_hi = np.cos(tQR + eps), np.cos(max(tQR - eps, 0.0))
    else:
        s, e = sB, eB
        c_lo, c_hi = np.cos(tPR + eps), np.cos(max(tPR - eps, 0.0))
    m = e - s
    if nxt.shape[0] < 2 * m:
        nxt = np.empty(4 * m, dtype=np.int32)
        oth = np.empty(4 * m, dtype=np.int32)
    for p in range(s, e):
        t = 2 * (p - s)
        a = pa[p]
        c = pb[p]
        nxt[t] = mark[a] - 1
        oth[t] = c
        mark[a] = t + 1
        nxt[t + 1] = mark[c] - 1
        oth[t + 1] = a
        mark[c] = t + 2
    hand = np.sign(_triple(b[P], b[Q], b[R]))
    nc = 0
    for p in range(sS, eS):
        for o in range(2):
            x = pa[p] if o == 0 else pb[p]
            y = pb[p] if o == 0 else pa[p]
            h = x if from_p else y
            u = y if from_p else x   # the vertex whose side to z is tested by angle
            t = mark[h] - 1
            if t < 0 or not (_mag_ok(smag, vmag, mwin, P, x) and _mag_ok(smag, vmag, mwin, Q, y)):
                continue
            vu = vec[u]
            while t >= 0:
                z = oth[t]
                t = nxt[t]
                if z == u:
                    continue
                vzz = vec[z]
                d = vu[0] * vzz[0] + vu[1] * vzz[1] + vu[2] * vzz[2]
                if d < c_lo or d > c_hi:
                    continue
                if np.sign(_triple(vec[x], vec[y], vzz)) != hand or not _mag_ok(smag, vmag, mwin, R, z):
                    continue
                if nc < _MAX_CAND:
                    cand[nc, cP] = x
                    cand[nc, cQ] = y
                    cand[nc, cR] = z
                nc += 1
    for p in range(s, e):
        mark[pa[p]] = 0
        mark[pb[p]] = 0
    return nc, nxt, oth


@njit(cache=True)
def _search(b, vec, vmag, is_nav, pt, pa, pb, kv, km, kq, vstart, vstars, vvec, vh, vg, eps, label_tol, max_sep,
            fov_radius, p_false_max, max_triangles, mark, nnav, nloc, nmin, lab_nloc, max_spots, budgets, tried,
            status, smag, mwin, fn, flab, n_sigma):
    """Pyramid search over one navigation-star tier (pair table ``pt/pa/pb`` with its k-vector,
    ``is_nav``/``nnav`` its stars, ``nloc`` their local density as an all-sky count and ``nmin``
    its 5th percentile (early rejection only); only the brightest ``max_spots`` spots form pyramids);
    ``tried``/``status`` carry over from earlier tiers. Measured magnitudes ``smag`` (empty: none)
    gate every candidate star within ``mwin``; ``fn``/``flab`` (n,): the share of this tier's
    navigation stars / of all indexed stars a spot's magnitude admits (1 without magnitudes),
    each star's factor in the false-match count.
    Returns ``(match (n,), q (4,), p_false, status, triangles_tried)``."""
    n = b.shape[0]
    nstar = vec.shape[0]
    match = -np.ones(n, dtype=np.int64)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    cand = np.empty((_MAX_CAND, 3), dtype=np.int64)
    last_q = np.zeros(4)
    same_q = np.cos(5.0 * label_tol)  # two attitudes within 10 label tolerances: the same solution
    lab_min = nstar * label_tol * label_tol / 4.0 * nmin / nnav  # least chance of a random label
    flab_min = 1.0
    for s in range(n):
        flab_min = min(flab_min, flab[s])
    nxt = np.empty(256, dtype=np.int32)
    oth = np.empty(256, dtype=np.int32)
    prev = 0
    for lev in range(budgets.shape[0] + 1):
        nb = min(n, max_spots) if lev == budgets.shape[0] else min(n, budgets[lev], max_spots)
        if nb <= prev:
            continue
        fmin = 1.0       # the most selective magnitude among the spots that may confirm
        for s in range(nb):
            fmin = min(fmin, fn[s])
        for dj in range(1, nb - 1):
            for dk in range(1, nb - dj):
                for i in range(0, nb - dj - dk):
                    j = i + dj
                    k = j + dk
                    if k < prev:
                        continue  # tried at a smaller budget
                    if tried >= max_triangles:
                        return match, q, np.inf, status, tried
                    tij = _angle(b[i], b[j])
                    tik = _angle(b[i], b[k])
                    tjk = _angle(b[j], b[k])
                    if (tij > max_sep - eps or tik > max_sep - eps or tjk > max_sep - eps
                            or tij < 2.0 * eps or tik < 2.0 * eps or tjk < 2.0 * eps):
                        continue
                    sin_k = max(_sin_vertex(b[k], b[i], b[j]), 0.05)
                    # E₃ with the local density ρ (an all-sky count) for the stars around x
                    g3 = nnav * eps ** 3 * np.sin(tij) / (np.pi * sin_k) * fn[i] * fn[j] * fn[k]
                    # early rejection: even in a sparse sky (5th percentile), with the best-placed confirming star
                    # and every other spot labelled, this triangle's pyramid could not pass the bound
                    if n == 3:
                        best = g3 * nmin * nmin * (tried + 1)
                    else:
                        lm = lab_min * flab_min
                        best = (g3 * nmin ** 3 * eps * eps / np.pi * fmin * (nb - 3) * (lm ** (n - 4) if lm < 1.0
                                                                                          else 1.0) * (tried + 1))
                    if best > p_false_max:
                        continue
                    tried += 1
                    nc, nxt, oth = _triangle_candidates(b, i, j, k, vec, pt, pa, pb, kv, km, kq, eps, mark, nxt,
                                                        oth, cand, smag, vmag, mwin)
                    if nc == 0 or nc > _MAX_CAND:
                        continue
                    if n == 3:
                        rho = max(nloc[cand[0, 0]], nloc[cand[0, 1]], nloc[cand[0, 2]])
                        e3v = g3 * rho * rho
                        if nc == 1 and e3v * tried <= p_false_max:
                            match[0] = cand[0, 0]
                            match[1] = cand[0, 1]
                            match[2] = cand[0, 2]
                            q, match, nok, _ = verify_matches(b, vec, match, label_tol)
                            if nok == 3:
                                return match, q, e3v * tried, ST_OK, tried
                            match[:] = -1
                            return match, q, np.inf, ST_REJECTED, tried
                        status = ST_REJECTED if nc == 1 else status
                        continue
                    nconf = 0
                    best = -1
                    br = -1
                    bw = -1
                    for c in range(nc):
                        r, w = _confirm(b, nb, i, j, k, cand[c, 0], cand[c, 1], cand[c, 2], vec, is_nav, vstart,
                                        vstars, vvec, vh, vg, eps, max_sep, smag, vmag, mwin)
                        if r >= 0:
                            nconf += 1
                            best = c
                            br = r
                            bw = w
                    if nconf != 1:
                        continue
                    sin_r = max(_sin_vertex(b[br], b[i], b[j]), 0.05)
                    x = cand[best, 0]
                    y = cand[best, 1]
                    z = cand[best, 2]
                    rho = max(nloc[x], nloc[y], nloc[z], nloc[bw])
                    # any of the nb − 3 other spots could have confirmed a false candidate
                    pf = g3 * rho ** 3 * eps * eps / (np.pi * sin_r) * fn[br] * (nb - 3) * tried
                    lab = lab_nloc[x] * label_tol * label_tol / 4.0  # chance of a random label near x
                    # attitude from the pyramid, then label every spot
                    bb = np.empty((4, 3))
                    rr = np.empty((4, 3))
                    bb[0] = b[i]
                    bb[1] = b[j]
                    bb[2] = b[k]
                    bb[3] = b[br]
                    rr[0] = vec[x]
                    rr[1] = vec[y]
                    rr[2] = vec[z]
                    rr[3] = vec[bw]
                    q4, _ = quest(bb, rr, np.ones(4))
                    match[:] = -1
                    match[i] = x
                    match[j] = y
                    match[k] = z
                    match[br] = bw
                    label_rest(b, q4, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, match, smag, mwin)
                    q, out, nok, _ = verify_matches(b, vec, match, label_tol)
                    if out[i] != x or out[j] != y or out[k] != z or out[br] != bw:
                        status = ST_REJECTED
                        match[:] = -1
                        continue
                    # unambiguous both ways again at the refined attitude (the labels were given at
                    # the pyramid's own): a spot with two indexed stars in reach, or a star with two
                    # spots in reach, keeps no label — a close pair's members swap under the noise
                    q, out, nok = drop_unclear(b, q, out, nok, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius,
                                               label_tol)
                    # every further label: a random spot near a star of the right magnitude
                    for s in range(n):
                        if out[s] >= 0 and s != i and s != j and s != k and s != br:
                            pf *= lab * flab[s]
                    # of the false pyramids inside the tolerances, only those that fit as well
                    # as this one count
                    pf *= _fit_share(b, vec, i, j, k, x, y, z, br, q4, out, eps, label_tol, n_sigma)
                    if pf > p_false_max:
                        status = ST_REJECTED
                        match[:] = -1
                        # every spot labelled, or a second pyramid at the same attitude labelling
                        # half the spots or more, and still the bound is not met: the field has too few stars for
                        # the confidence asked (speed only: stopping never outputs anything)
                        if nok == n or (2 * nok >= n and abs(q @ last_q) >= same_q):
                            return match, q, np.inf, ST_SPARSE, tried
                        if 2 * nok >= n:
                            last_q = q
                        continue
                    if 4 * nok < 3 * n:
                        # a quarter of the spots or more unnamed: look again from scratch around this attitude
                        q, out = relabel_wide(b, q, out, nok, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius,
                                              label_tol, smag, mwin)
                    return out, q, pf, ST_OK, tried
        prev = nb
    return match, q, np.inf, status, tried


@njit(cache=True)
def pyramid_core(b, vec, vmag, tiers, lab_nloc, vstart, vstars, vvec, vh, vg, eps, label_tol, max_sep, fov_radius,
                 p_false_max, max_triangles, mark, budgets, smag, mwin, lab_sorted_v, n_sigma):
    """Numba core. ``b`` (n,3) body unit vectors, brightest first; ``mark`` int32 (N,) zeros (work, left zeroed).

    ``tiers``: tuple of navigation-star tiers, searched in order, each
    ``(is_nav, pair_theta, pair_a, pair_b, kv, nloc, (kv_m, kv_q, n_nav, max_spots, nloc_p5,
    max_tier_triangles), nav_share)`` over the same star numbering (a thinned tier of the brightest
    stars per field, on the brightest few spots, first — in a field of no more than ``max_spots``
    spots for ``max_tier_triangles`` triangles at most; then all stars on all spots).
    Adaptive spot budget: triangles and confirming stars come from the brightest
    ``budgets[0]`` spots first; when no pyramid is accepted there, from the brightest
    ``budgets[1]`` (only triangles with a new spot), and so on, then from all. Labelling and
    the false-match count use every spot. The false-match count takes the star density
    around the candidate: ``nloc`` (per star) is the tier's navigation stars within the pair
    radius scaled to an all-sky count (N where the sky is average; ``n_nav`` anchors,
    ``nloc`` for the stars found near them), ``lab_nloc`` the same for every indexed star
    (the labels); ``max_triangles``
    bounds the triangles tried over all tiers. The accepted ``p_false`` is the pyramid's
    expected false-match count times the number of triangles tried so far (a union bound
    over the search), and must be ≤ ``p_false_max``.
    Magnitudes: ``smag`` (n,) measured V (NaN unknown) or empty (positions only); a catalog
    star may stand for a spot only within ``mwin`` (mag) of its measured V, and each star's
    term of the false-match count is multiplied by the share of stars that window admits
    (``tier[7]``: :func:`mag_share_table` of the tier's navigation stars; ``lab_sorted_v``: of
    every indexed star).
    Returns ``(match (n,), q (4,), p_false, status, triangles_tried)``.
    """
    n = b.shape[0]
    if n < 3:
        return -np.ones(n, dtype=np.int64), np.array([0.0, 0.0, 0.0, 1.0]), np.inf, ST_TOO_FEW, 0
    tried = 0
    status = ST_NO_MATCH
    use_mag = smag.shape[0] == n
    gate = smag[:n] if use_mag else smag[:0]       # the magnitudes the search gates on (empty: none)
    flab = np.ones(n)
    fn = np.ones(n)
    if use_mag:
        for s in range(n):
            flab[s] = _mag_fraction(lab_sorted_v, smag[s])
    for tier in tiers:
        is_nav, pt, pa, pb, kv, nloc, kmq, nav_sorted_v = tier
        if use_mag:
            for s in range(n):
                fn[s] = _mag_fraction(nav_sorted_v, smag[s])
        # this tier's triangles end here: a field of no more spots than the tier takes has them
        # all among its candidates, so a thinned tier that finds nothing in its first few
        # triangles lacks the field's stars (the thinning kept a denser neighbourhood's)
        cap = max_triangles
        if n <= kmq[3]:
            cap = min(max_triangles, tried + max(int(kmq[5]), n * (n - 1) * (n - 2) // 12))
        match, q, pf, status, tried = _search(b, vec, vmag, is_nav, pt, pa, pb, kv, kmq[0], kmq[1], vstart, vstars,
                                              vvec, vh, vg, eps, label_tol, max_sep, fov_radius, p_false_max,
                                              cap, mark, kmq[2], nloc, kmq[4], lab_nloc, int(kmq[3]),
                                              budgets, tried, status, gate, mwin, fn, flab, n_sigma)
        if status == ST_OK or status == ST_SPARSE or tried >= max_triangles:
            return match, q, pf, status, tried
    return match, q, np.inf, status, tried


@njit(cache=True)
def label_rest(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, tol, match, smag, mwin):
    """Label unmatched observed stars with catalog stars predicted within ``tol`` (in place).

    A label is given only when it is unambiguous both ways: exactly one catalog star within
    ``tol`` of the observed star, and no other observed star within ``tol`` of that one; with
    measured magnitudes ``smag`` (empty: none) that star must also be within ``mwin`` of the
    spot's V (:func:`_mag_ok`).
    Then every label, the caller's included, is dropped when two observed stars lie within
    ``tol`` of its catalog star, and moves to the observed star nearest its catalog star
    (or is dropped when that one is named already).
    """
    a = quat_to_dcm(q)
    bore = a[2].copy()  # boresight in ICRS = A^T e_z
    near = cone_query(vvec, vstars, vstart, vh, vg, bore, fov_radius + tol, vec.shape[0])
    m = near.shape[0]
    n = b.shape[0]
    cos_tol = np.cos(tol)
    obs_icrs = body_to_icrs(a, b)
    count_obs = np.zeros(m, dtype=np.int64)
    used = np.zeros(m, dtype=np.bool_)
    for t in range(m):
        s = near[t]
        for i in range(n):
            if match[i] == s:
                used[t] = True
            v = obs_icrs[i]
            if v[0] * vec[s, 0] + v[1] * vec[s, 1] + v[2] * vec[s, 2] >= cos_tol:
                count_obs[t] += 1
    for i in range(n):
        if match[i] >= 0:
            continue
        v = obs_icrs[i]
        hits = 0
        bt = -1
        for t in range(m):
            s = near[t]
            if v[0] * vec[s, 0] + v[1] * vec[s, 1] + v[2] * vec[s, 2] >= cos_tol:
                hits += 1
                bt = t
        if hits == 1 and count_obs[bt] == 1 and not used[bt] and _mag_ok(smag, vmag, mwin, i, near[bt]):
            match[i] = near[bt]
            used[bt] = True
    # every label (the caller's too) belongs to the spot nearest its star: a spurious spot
    # close to a star must not keep the star's name while the star's own spot goes unnamed
    for i in range(n):
        s = match[i]
        if s < 0:
            continue
        best = i
        bd = obs_icrs[i, 0] * vec[s, 0] + obs_icrs[i, 1] * vec[s, 1] + obs_icrs[i, 2] * vec[s, 2]
        within = 0
        for j in range(n):
            d = obs_icrs[j, 0] * vec[s, 0] + obs_icrs[j, 1] * vec[s, 1] + obs_icrs[j, 2] * vec[s, 2]
            if d >= cos_tol:
                within += 1
            if d > bd:
                bd = d
                best = j
        if within >= 2:
            match[i] = -1  # two spots at the star: either could be it
        elif best != i:
            match[i] = -1
            if match[best] < 0 and bd >= cos_tol:
                match[best] = s


@njit(cache=True)
def drop_unclear(b, q, match, nok, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol):
    """Labels unambiguous both ways at attitude ``q``: a spot with two indexed stars in reach
    (:func:`~gyrostar.starid.verify.drop_ambiguous`) or a star with two spots in reach
    (:func:`~gyrostar.starid.verify.drop_shared`) keeps none; the attitude solved again when
    any went. Returns ``(q, match, nok)``."""
    if drop_ambiguous(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, match) \
            + drop_shared(b, q, vec, label_tol, match) > 0:
        q, match, nok, _ = verify_matches(b, vec, match, label_tol)
    return q, match, nok


@njit(cache=True)
def relabel_wide(b, q, match, nok, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, smag, mwin):
    """The accepted attitude's labels made again from scratch (in the neighbourhood the bound
    accepted): unambiguous labels within ``RELABEL_WIDE`` × ``label_tol`` of it (four at
    least), the attitude they give, then labels within ``label_tol`` of that one (verified,
    unambiguous both ways). They replace ``match`` when they name more stars. A pyramid with one wrong member — a
    neighbour of the right star, when the spot's magnitude was off and shut the right star
    out — fits its tolerances but bends the attitude by a few hundred arcseconds, so most
    spots go unnamed and one may be misnamed; the wider first pass finds the rest of the
    field and the attitude they all agree on. Returns ``(q, match)``."""
    n = b.shape[0]
    wide = -np.ones(n, dtype=np.int64)
    label_rest(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, RELABEL_WIDE * label_tol, wide, smag, mwin)
    n_wide = 0
    for i in range(n):
        if wide[i] >= 0:
            n_wide += 1
    if n_wide < 4:
        return q, match
    q1, wide, n1, _ = verify_matches(b, vec, wide, RELABEL_WIDE * label_tol)
    if n1 < 4:
        return q, match
    fresh = -np.ones(n, dtype=np.int64)
    label_rest(b, q1, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, fresh, smag, mwin)
    q2, fresh, n2, _ = verify_matches(b, vec, fresh, label_tol)
    if n2 > nok:
        q2, fresh, n2 = drop_unclear(b, q2, fresh, n2, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol)
    if n2 > nok:
        return q2, fresh
    return q, match


@njit(cache=True)
def post_checks(q, b, match, n_ok, cam, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, absent,
                fvec, fstart, fh, fg):
    """The checks after the per-star check, on an accepted solution: absent stars
    (``absent`` = [absent_max, margin mag, near rad, edge px, index limit V]; empty: off,
    :func:`gyrostar.starid.absent.absent_stars`), then labels next to a faint star the index
    leaves out (the faint stars' voxel grid ``fvec, fstart, fh, fg``; no stars: off,
    :func:`gyrostar.starid.faint.drop_near_faint`), dropped in place and the attitude solved
    again. Returns ``(status, q, n_ok)``."""
    if absent.shape[0] > 0:
        if absent_stars(q, b, match, cam, vec, vmag, vvec, vstars, vstart, vh, vg, fov_radius, absent[4], absent[1],
                        absent[2], absent[3]) > absent[0]:
            return ST_ABSENT, q, n_ok
    if fvec.shape[0] > 0 and drop_near_faint(q, b, match, fvec, fstart, fh, fg, label_tol) > 0:
        n_ok = 0
        for i in range(match.shape[0]):
            if match[i] >= 0:
                n_ok += 1
        if n_ok < 3:
            return ST_STAR_CHECK, q, 0
        q = solve(b, vec, match)
    return ST_OK, q, n_ok


@njit(cache=True)
def pyramid_identify_uv(uv, cam, tiers, lab_nloc, vec, vmag, ids, vstart, vstars, vvec, vh, vg, eps, label_tol, max_sep,
                        fov_radius, p_false_max, max_triangles, mark, budgets, mag, check, mwin, lab_sorted_v,
                        n_sigma, absent, fvec, fstart, fh, fg):
    """One compiled call: centroids ``uv`` (n, 2) px → body vectors → :func:`pyramid_core` →
    the per-star check :func:`gyrostar.starid.star_check.check_stars` (scalars ``check`` from
    ``StarCheck.settings()``; empty: no check here). ``mag`` (n,) measured V or empty; the search
    uses it when ``mwin`` > 0 (:func:`pyramid_core`); then :func:`post_checks`.
    Returns ``(match, catalog ids, q, status, p_false, n_ok, triangles tried)``; status
    ``ST_BAD`` for a non-finite centroid."""
    n = uv.shape[0]
    for i in range(n):
        if not (np.isfinite(uv[i, 0]) and np.isfinite(uv[i, 1])):
            none = -np.ones(n, dtype=np.int64)
            return none, none.copy(), np.array([0.0, 0.0, 0.0, 1.0]), ST_BAD, np.inf, 0, 0
    b = unproject_many(cam, uv)
    smag = mag[:n] if (mwin > 0.0 and mag.shape[0] == n) else mag[:0]
    match, q, pf, st, tried = pyramid_core(b, vec, vmag, tiers, lab_nloc, vstart, vstars, vvec, vh, vg, eps,
                                           label_tol, max_sep, fov_radius, p_false_max, max_triangles, mark,
                                           budgets, smag, mwin, lab_sorted_v, n_sigma)
    n_ok = 0
    for i in range(n):
        if match[i] >= 0:
            n_ok += 1
    if st == ST_OK and check.shape[0] > 0:
        m = mag if mag.shape[0] == n else np.full(n, np.nan)
        qc, n_ok = check_stars(b, m, vec, vmag, match, check[0], check[1], check[2], check[3], check[4],
                               int(check[5]), int(check[6]))
        if n_ok == 0:
            st = ST_STAR_CHECK
        else:
            q = qc
    if st == ST_OK:
        st, q, n_ok = post_checks(q, b, match, n_ok, cam, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius,
                                  label_tol, absent, fvec, fstart, fh, fg)
    if st != ST_OK:
        match[:] = -1
    out_ids = -np.ones(n, dtype=np.int64)
    for i in range(n):
        if match[i] >= 0:
            out_ids[i] = ids[match[i]]
    return match, out_ids, q, st, pf, n_ok, tried


def local_density(index: StarIndex) -> np.ndarray:
    """Per star: the navigation stars within the pair radius around it, scaled to an all-sky
    count (the N a uniform sky of that density would have; at least one star per cap)."""
    frac = (1.0 - math.cos(index.max_sep)) / 2.0
    return np.maximum(np.diff(index.nb_start), 1).astype(np.float64) / frac


@dataclasses.dataclass
class Pyramid:
    """Pyramid identifier over a :class:`StarIndex` and a camera (``gyrostar.camera``).

    ``sigma_px``: centroid noise (px, 1σ) the tolerances are built from:
    ε = n_sigma·√2·σ (pair angles), label_tol = n_sigma·1.25·σ (labelling/residuals).
    ``budgets``: the adaptive spot budget — pyramids are searched among the brightest
    ``budgets[0]`` centroids, then (when none is accepted) among the brightest
    ``budgets[1]``, and so on, then among all; every centroid is labelled and counted in
    the false-match bound whatever the budget. ``max_triangles`` bounds the search.
    ``fast_index``: optional thinned index over the same stars (``load_index(..., per_field=k)``:
    the brightest k navigation stars per field), searched first — its pair table is a few
    per cent of the full one and its smaller N makes its pyramids more certain — on the
    brightest ``fast_spots`` centroids; the full index follows when it finds nothing. In a
    field of n ≤ ``fast_spots`` spots the thinned index gets max(``fast_triangles``, C(n,3)/2)
    triangles: there its solves take 1 at the median and ≤ 6 at the 99th percentile (qian2015),
    and a sparse field next to a denser one, whose stars the thinning left out, would
    otherwise try every triangle there before the full index names it at the first.
    ``check``: the per-star verification stage (any object with ``apply(b, mag, ref, vmag,
    match) -> (q, match, n_ok)``); default a :class:`StarCheck` at ``sigma_px`` and the
    index's navigation limit (the sensor's), three stars minimum.
    ``sigma_mag``: 1σ of measured minus catalog V (mag, sensor and catalog together); when > 0
    and the caller gives magnitudes, a catalog star stands for a spot only within
    ``n_sigma·sigma_mag`` of its measured V, in the search, the confirming star and the labels,
    and every star's term of the false-match count is multiplied by the share of stars that
    window admits. 0: positions only (magnitudes then reach the per-star check alone).
    ``absent_max``: how many surely-seen catalog stars the solved attitude may put on the
    sensor with no spot near them (:mod:`gyrostar.starid.absent`; -1: no check).
    ``faint``: a :class:`gyrostar.starid.faint.FaintStars` of the same catalog (None: labels
    are not checked against the stars the index leaves out).
    """

    index: StarIndex
    camera: object
    sigma_px: float = 0.5
    n_sigma: float = 3.0
    p_false_max: float = 1e-6
    budgets: tuple = (8, 12, 16, 24)
    fast_index: object = None
    fast_spots: int = 10
    fast_triangles: int = 10
    max_triangles: int = 400
    check: object = None
    sigma_mag: float = 0.0
    absent_max: int = 0
    faint: object = None

    def __post_init__(self) -> None:
        if not (self.sigma_px > 0 and self.n_sigma > 0 and self.max_triangles >= 1 and self.fast_triangles >= 1
                and self.sigma_mag >= 0 and self.absent_max >= -1):
            raise ConfigError("pyramid needs sigma_px > 0, n_sigma > 0, max_triangles ≥ 1, fast_triangles ≥ 1, "
                              "sigma_mag ≥ 0 and absent_max ≥ -1")
        self.mwin = self.n_sigma * self.sigma_mag
        if not (len(self.budgets) >= 1 and all(int(k) >= 3 for k in self.budgets)
                and list(self.budgets) == sorted(self.budgets)):
            raise ConfigError(f"pyramid spot budgets must be ascending and ≥ 3, got {self.budgets!r}")
        self._budgets = np.asarray(self.budgets, dtype=np.int64)
        self._default_check = self.check is None
        self._set_camera()
        self._mark = np.zeros(len(self.index), dtype=np.int32)
        tiers = [self.index] if self.fast_index is None else [self.fast_index, self.index]
        if self.fast_index is not None and not (len(self.fast_index) == len(self.index)
                                                and np.array_equal(self.fast_index.ids, self.index.ids)):
            raise ConfigError("pyramid fast_index must index the same stars as index (same catalog and limit)")
        caps = [(float(self.fast_spots), float(self.fast_triangles))] * (len(tiers) - 1) + \
            [(1e9, float(self.max_triangles))]
        dens = [local_density(t) for t in tiers]
        self._tiers = tuple((t.is_nav, t.pair_theta, t.pair_a, t.pair_b, t.kv, d,
                             (float(t.kv_m), float(t.kv_q), float(np.count_nonzero(t.is_nav)), cap[0],
                              float(np.percentile(d[t.is_nav], 5)), cap[1]),
                             mag_share_table(t.vmag[t.is_nav], self.mwin))
                            for t, cap, d in zip(tiers, caps, dens))
        self._lab_sorted_v = mag_share_table(self.index.vmag, self.mwin)
        # every indexed star (labels): the full tier's navigation density scaled to all stars
        self._lab_nloc = dens[-1] * (len(self.index) / np.count_nonzero(self.index.is_nav))
        f = self.faint
        self._faint_grid = (np.empty((0, 3)), np.zeros(2, np.int64), 1.0, 1) if f is None else (
            f.vox_vec, f.vox_start, float(f.vox_h), int(f.vox_g))
        self._no_mag = np.empty(0)

    def _set_camera(self) -> None:
        """The camera's share of the set-up: tolerances, field radius, default per-star check."""
        self._params = self.camera.as_array()
        sig = self.sigma_px / self.camera.focal_length_px
        self.eps = self.n_sigma * math.sqrt(2.0) * sig + 2e-6
        self.label_tol = self.n_sigma * 1.25 * sig + 2e-6
        w, h = self.camera.width_px, self.camera.height_px
        self.fov_radius = math.atan(0.5 * math.hypot(w, h) / self.camera.focal_length_px)
        if 2.0 * self.fov_radius > self.index.max_sep + 1e-9:
            raise ConfigError(f"index pairs reach {math.degrees(self.index.max_sep):.2f}° but the camera "
                              f"diagonal is {math.degrees(2 * self.fov_radius):.2f}°")
        if self._default_check:
            self.check = StarCheck(self.sigma_px, self.camera.focal_length_px, mag_limit=self.index.nav_limit,
                                   min_stars=3)
        # a StarCheck runs inside the compiled call; another stage runs after it
        self._fused = self.check.settings() if isinstance(self.check, StarCheck) else np.empty(0)
        near = self.label_tol + BLEND_PX / self.camera.focal_length_px
        self._absent_cfg = np.empty(0) if self.absent_max < 0 else np.array(
            [float(self.absent_max), MARGIN_MAG, near, EDGE_PX, self.index.nav_limit])

    def with_camera(self, camera) -> Pyramid:
        """The same identifier (index, tiers, tables shared) for another camera whose diagonal
        the index's pairs still span — cheap: only the camera's tolerances are recomputed."""
        other = copy.copy(self)
        other.camera = camera
        other._mark = np.zeros(len(self.index), dtype=np.int32)
        other._set_camera()
        return other

    def identify_vectors(self, b: np.ndarray, mag=None) -> StarIdResult:
        """Identify body unit vectors (n, 3), brightest first; ``mag`` (n,) measured V or None."""
        ix = self.index
        b = np.ascontiguousarray(b, dtype=np.float64)
        smag = self._magnitudes(mag, b.shape[0])
        full, q, pf, st, tried = pyramid_core(
            b, ix.vectors, ix.vmag, self._tiers, self._lab_nloc, ix.vox_start, ix.vox_stars, ix.vox_vec, ix.vox_h,
            ix.vox_g, self.eps, self.label_tol, ix.max_sep, self.fov_radius, self.p_false_max, self.max_triangles,
            self._mark, self._budgets, smag if self.mwin > 0 else self._no_mag, self.mwin, self._lab_sorted_v,
            self.n_sigma)
        n_ok = 0
        if st == ST_OK:
            q, full, n_ok = self.check.apply(b, mag, ix.vectors, ix.vmag, full)
            if n_ok == 0:
                st = ST_STAR_CHECK
            else:
                full = np.array(full, dtype=np.int64)
                st, q, n_ok = post_checks(np.asarray(q, np.float64), b, full, n_ok, self._params, ix.vectors, ix.vmag,
                                          ix.vox_start, ix.vox_stars, ix.vox_vec, ix.vox_h, ix.vox_g, self.fov_radius,
                                          self.label_tol, self._absent_cfg, *self._faint_grid)
        return StarIdResult.make(ix, full, q, st == ST_OK, self._status(st, n_ok, pf), pf, "pyramid", tried)

    def identify(self, uv: np.ndarray, mag=None) -> StarIdResult:
        """Identify centroids ``uv`` (n, 2) [col, row] px, brightest first; ``mag`` (n,)
        their calibrated measured V (None: position-only per-star check). One compiled call
        when the check is a :class:`StarCheck`."""
        if self._fused.shape[0] == 0:
            return self.identify_vectors(to_body_vectors(self._params, uv), mag)
        pts = uv
        if not (isinstance(pts, np.ndarray) and pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 2
                and pts.flags.c_contiguous):
            pts = np.asarray(uv, dtype=np.float64)
            pts = np.ascontiguousarray(pts.reshape(-1, 2) if pts.size else np.empty((0, 2)))
        m = self._magnitudes(mag, pts.shape[0])
        ix = self.index
        match, ids, q, st, pf, n_ok, tried = pyramid_identify_uv(
            pts, self._params, self._tiers, self._lab_nloc, ix.vectors, ix.vmag, ix.ids, ix.vox_start, ix.vox_stars,
            ix.vox_vec, ix.vox_h, ix.vox_g, self.eps, self.label_tol, ix.max_sep, self.fov_radius, self.p_false_max,
            self.max_triangles, self._mark, self._budgets, m, self._fused, self.mwin, self._lab_sorted_v,
            self.n_sigma, self._absent_cfg, *self._faint_grid)
        if st == ST_BAD:
            raise ConfigError(STATUS_TEXT[ST_BAD])
        return StarIdResult(match, ids, q, st == ST_OK, self._status(st, n_ok, pf), float(pf), "pyramid", int(tried))

    def _magnitudes(self, mag, n: int) -> np.ndarray:
        """``mag`` as a float64 (n,) array (empty for None)."""
        if mag is None:
            return self._no_mag
        m = np.ascontiguousarray(mag, dtype=np.float64).reshape(-1)
        if m.shape[0] != n:
            raise ConfigError(f"{m.shape[0]} magnitudes for {n} centroids")
        return m

    @staticmethod
    def _status(st, n_ok, pf) -> str:
        if st == ST_OK and n_ok <= 4:
            # a sparse field, accepted because the bound allowed it at p_false_max
            return f"ok: sparse field, {n_ok} stars (p_false {pf:.1e})"
        return STATUS_TEXT[int(st)]
