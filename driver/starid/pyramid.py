"""Pyramid lost-in-space identification (Mortari, Samaan, Bruccoleri & Junkins 2004).

Input: centroids (px) of one image, brightest first, and the camera model; output the
navigation star of each centroid (or -1) and the attitude, accepted only when the
analytic expected number of false matches is below ``p_false_max`` and the QUEST
residuals of every identified star are within ``label_tol``.

1. Triangles (i, j, k) of the observed stars in Mortari's smart order (index gaps
   dj, dk grow slowly, so a spurious star spoils few consecutive triangles).
2. Each side θ looks up the catalog pairs within θ ± ε with the k-vector; candidate
   catalog triangles (x, y, z) need all three sides and the same handedness
   (mirror test: sign of b_i·(b_j×b_k) = sign of r_x·(r_y×r_z)).
3. A fourth observed star r confirms a candidate when exactly one catalog star w has
   all three angles to x, y, z within ε; a triangle is accepted when exactly one of its
   candidates is confirmed.
4. QUEST on the pyramid, then every other centroid is labelled with the nearest catalog
   star within ``label_tol`` of its predicted direction; QUEST again over all and the
   residual test of :mod:`gyrostar.starid.verify`.
5. The per-star check (:class:`gyrostar.starid.star_check.StarCheck`, swappable): each
   label's own χ² (position, and magnitude when given) after QUEST; failures are
   unlabelled, the attitude re-solved over the rest, and fewer than three reject.

Expected false matches for a uniform sky of N navigation stars and tolerance ε (rad):
a triangle with side θ_ij and angle φ_k at vertex k:  E₃ = N³ ε³ sin θ_ij / (π sin φ_k)
(N choices of x, N ε sin θ_ij stars in the band around x, N ε²/(π sin φ_k) stars in the
intersection of the two other bands on the mirror-correct side); the confirming star
multiplies by N ε²/(π sin φ_r); every further labelled star by N δ²/4 (δ = label_tol, a
random star inside the cone; N there counts every indexed star, not only navigation
stars). ``p_false`` reported is that product.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..core.quest import quest
from ..errors import ConfigError
from .index import StarIndex, cone_query
from .kvector import query
from .result import StarIdResult, to_body_vectors
from .star_check import StarCheck
from .verify import verify_matches

ST_OK, ST_TOO_FEW, ST_NO_MATCH, ST_REJECTED, ST_STAR_CHECK = 0, 1, 2, 3, 4
STATUS_TEXT = {ST_OK: "ok", ST_TOO_FEW: "fewer than 3 stars", ST_NO_MATCH: "no unique pyramid",
               ST_REJECTED: "rejected by verification", ST_STAR_CHECK: "fewer than 3 stars pass the per-star check"}
_MAX_CAND = 256


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
def _confirm(b, i, j, k, x, y, z, vec, nbs, nbi, eps, max_sep):
    """First observed star r ∉ {i,j,k} with a unique catalog star w fitting all three angles.

    ``w`` is searched among the catalog neighbours of ``x`` (the neighbour table)."""
    n = b.shape[0]
    for r in range(n):
        if r == i or r == j or r == k:
            continue
        tri = _angle(b[r], b[i])
        trj = _angle(b[r], b[j])
        trk = _angle(b[r], b[k])
        if tri > max_sep - eps or tri < 2.0 * eps:
            continue
        found = -1
        nfound = 0
        # angle windows as cosine windows: |θ − t| ≤ ε  ⇔  cos(t+ε) ≤ cos θ ≤ cos(t−ε)
        ci_lo, ci_hi = np.cos(tri + eps), np.cos(max(tri - eps, 0.0))
        cj_lo, cj_hi = np.cos(trj + eps), np.cos(max(trj - eps, 0.0))
        ck_lo, ck_hi = np.cos(trk + eps), np.cos(max(trk - eps, 0.0))
        vx, vy, vz = vec[x], vec[y], vec[z]
        hand = np.sign(_triple(b[i], b[j], b[r]))
        for p in range(nbs[x], nbs[x + 1]):
            w = nbi[p]
            if w == y or w == z:
                continue
            vw = vec[w]
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
def pyramid_core(b, vec, vmag, pt, pa, pb, kv, km, kq, nbs, nbi, vstart, vstars, vvec, vh, vg, eps, label_tol, max_sep,
                 fov_radius, p_false_max, max_triangles, mark, nnav):
    """Numba core. ``b`` (n,3) body unit vectors, brightest first; ``mark`` int64 (2N,) zeros (work, left zeroed).

    ``nnav``: number of navigation stars (the N of the triangle/pyramid probabilities).
    Returns ``(match (n,), q (4,), p_false, status, triangles_tried)``.
    """
    n = b.shape[0]
    nstar = vec.shape[0]
    match = -np.ones(n, dtype=np.int64)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    if n < 3:
        return match, q, np.inf, ST_TOO_FEW, 0
    cand = np.empty((_MAX_CAND, 3), dtype=np.int64)
    mark2 = mark[nstar:]
    nxt = np.empty(64, dtype=np.int64)
    oth = np.empty(64, dtype=np.int64)
    nxt2 = np.empty(64, dtype=np.int64)
    oth2 = np.empty(64, dtype=np.int64)
    tried = 0
    status = ST_NO_MATCH
    for dj in range(1, n - 1):
        for dk in range(1, n - dj):
            for i in range(0, n - dj - dk):
                j = i + dj
                k = j + dk
                if tried >= max_triangles:
                    return match, q, np.inf, status, tried
                tij = _angle(b[i], b[j])
                tik = _angle(b[i], b[k])
                tjk = _angle(b[j], b[k])
                if (tij > max_sep - eps or tik > max_sep - eps or tjk > max_sep - eps
                        or tij < 2.0 * eps or tik < 2.0 * eps or tjk < 2.0 * eps):
                    continue
                tried += 1
                s1, e1 = query(pt, kv, km, kq, tij - eps, tij + eps)
                s2, e2 = query(pt, kv, km, kq, tik - eps, tik + eps)
                s3, e3 = query(pt, kv, km, kq, tjk - eps, tjk + eps)
                if e1 == s1 or e2 == s2 or e3 == s3:
                    continue
                # linked lists of the ik pairs per catalog star (head: mark, 1-based)
                nik = e2 - s2
                if nxt.shape[0] < 2 * nik:
                    nxt = np.empty(4 * nik, dtype=np.int64)
                    oth = np.empty(4 * nik, dtype=np.int64)
                for p in range(s2, e2):
                    e = 2 * (p - s2)
                    nxt[e] = mark[pa[p]] - 1
                    oth[e] = pb[p]
                    mark[pa[p]] = e + 1
                    nxt[e + 1] = mark[pb[p]] - 1
                    oth[e + 1] = pa[p]
                    mark[pb[p]] = e + 2
                njk = e3 - s3
                if nxt2.shape[0] < 2 * njk:
                    nxt2 = np.empty(4 * njk, dtype=np.int64)
                    oth2 = np.empty(4 * njk, dtype=np.int64)
                for p in range(s3, e3):
                    e = 2 * (p - s3)
                    nxt2[e] = mark2[pa[p]] - 1
                    oth2[e] = pb[p]
                    mark2[pa[p]] = e + 1
                    nxt2[e + 1] = mark2[pb[p]] - 1
                    oth2[e + 1] = pa[p]
                    mark2[pb[p]] = e + 2
                hand = np.sign(_triple(b[i], b[j], b[k]))
                nc = 0
                for p in range(s1, e1):
                    for o in range(2):
                        x = pa[p] if o == 0 else pb[p]
                        y = pb[p] if o == 0 else pa[p]
                        if mark2[y] == 0:
                            continue
                        e = mark[x] - 1
                        while e >= 0:
                            z = oth[e]
                            e = nxt[e]
                            if z == y:
                                continue
                            # is (y, z) a jk pair?
                            f = mark2[y] - 1
                            hit = False
                            while f >= 0:
                                if oth2[f] == z:
                                    hit = True
                                    break
                                f = nxt2[f]
                            if not hit:
                                continue
                            if np.sign(_triple(vec[x], vec[y], vec[z])) != hand:
                                continue
                            if nc < _MAX_CAND:
                                cand[nc, 0] = x
                                cand[nc, 1] = y
                                cand[nc, 2] = z
                            nc += 1
                for p in range(s2, e2):
                    mark[pa[p]] = 0
                    mark[pb[p]] = 0
                for p in range(s3, e3):
                    mark2[pa[p]] = 0
                    mark2[pb[p]] = 0
                if nc == 0 or nc > _MAX_CAND:
                    continue
                sin_k = max(_sin_vertex(b[k], b[i], b[j]), 0.05)
                e3v = (nnav * eps) ** 3 * np.sin(tij) / (np.pi * sin_k)
                if n == 3:
                    if nc == 1 and e3v <= p_false_max:
                        match[0] = cand[0, 0]
                        match[1] = cand[0, 1]
                        match[2] = cand[0, 2]
                        q, match, nok, _ = verify_matches(b, vec, match, label_tol)
                        if nok == 3:
                            return match, q, e3v, ST_OK, tried
                        match[:] = -1
                        return match, q, np.inf, ST_REJECTED, tried
                    continue
                nconf = 0
                best = -1
                br = -1
                bw = -1
                for c in range(nc):
                    r, w = _confirm(b, i, j, k, cand[c, 0], cand[c, 1], cand[c, 2], vec, nbs, nbi, eps, max_sep)
                    if r >= 0:
                        nconf += 1
                        best = c
                        br = r
                        bw = w
                if nconf != 1:
                    continue
                sin_r = max(_sin_vertex(b[br], b[i], b[j]), 0.05)
                pf = e3v * nnav * eps * eps / (np.pi * sin_r)
                x = cand[best, 0]
                y = cand[best, 1]
                z = cand[best, 2]
                # attitude from the pyramid, then label the rest
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
                label_rest(b, q4, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, label_tol, match)
                q, out, nok, _ = verify_matches(b, vec, match, label_tol)
                if out[i] != x or out[j] != y or out[k] != z or out[br] != bw:
                    status = ST_REJECTED
                    match[:] = -1
                    continue
                extra = nok - 4
                pf *= (nstar * label_tol * label_tol / 4.0) ** extra
                if pf > p_false_max:
                    status = ST_REJECTED
                    match[:] = -1
                    continue
                return out, q, pf, ST_OK, tried
    return match, q, np.inf, status, tried


@njit(cache=True)
def label_rest(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, tol, match):
    """Label unmatched observed stars with catalog stars predicted within ``tol`` (in place).

    A label is given only when it is unambiguous both ways: exactly one catalog star within
    ``tol`` of the observed star, and no other observed star within ``tol`` of that one.
    """
    a = quat_to_dcm(q)
    bore = a[2].copy()  # boresight in ICRS = A^T e_z
    near = cone_query(vvec, vstars, vstart, vh, vg, bore, fov_radius + tol, vec.shape[0])
    m = near.shape[0]
    n = b.shape[0]
    cos_tol = np.cos(tol)
    obs_icrs = np.empty((n, 3))
    for i in range(n):
        for j in range(3):
            obs_icrs[i, j] = a[0, j] * b[i, 0] + a[1, j] * b[i, 1] + a[2, j] * b[i, 2]
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
        if hits == 1 and count_obs[bt] == 1 and not used[bt]:
            match[i] = near[bt]
            used[bt] = True


@dataclasses.dataclass
class Pyramid:
    """Pyramid identifier over a :class:`StarIndex` and a camera (``gyrostar.camera``).

    ``sigma_px``: centroid noise (px, 1σ) the tolerances are built from:
    ε = n_sigma·√2·σ (pair angles), label_tol = n_sigma·1.25·σ (labelling/residuals).
    ``max_stars``: only the brightest this many centroids are used for the pyramid.
    ``check``: the per-star verification stage (any object with ``apply(b, mag, ref, vmag,
    match) -> (q, match, n_ok)``); default a :class:`StarCheck` at ``sigma_px`` and the
    index's limiting magnitude, three stars minimum.
    """

    index: StarIndex
    camera: object
    sigma_px: float = 0.5
    n_sigma: float = 3.0
    p_false_max: float = 1e-6
    max_stars: int = 8
    max_triangles: int = 400
    check: object = None

    def __post_init__(self) -> None:
        if not (self.sigma_px > 0 and self.n_sigma > 0 and self.max_stars >= 3):
            raise ConfigError("pyramid needs sigma_px > 0, n_sigma > 0 and max_stars ≥ 3")
        self._params = self.camera.as_array()
        sig = self.sigma_px / self.camera.focal_length_px
        self.eps = self.n_sigma * math.sqrt(2.0) * sig + 2e-6
        self.label_tol = self.n_sigma * 1.25 * sig + 2e-6
        w, h = self.camera.width_px, self.camera.height_px
        self.fov_radius = math.atan(0.5 * math.hypot(w, h) / self.camera.focal_length_px)
        if 2.0 * self.fov_radius > self.index.max_sep + 1e-9:
            raise ConfigError(f"index pairs reach {math.degrees(self.index.max_sep):.2f}° but the camera "
                              f"diagonal is {math.degrees(2 * self.fov_radius):.2f}°")
        self._mark = np.zeros(2 * len(self.index), dtype=np.int64)
        self._nnav = int(np.count_nonzero(self.index.is_nav))
        if self.check is None:
            self.check = StarCheck(self.sigma_px, self.camera.focal_length_px, mag_limit=self.index.mag_limit,
                                   min_stars=3)

    def identify_vectors(self, b: np.ndarray, mag=None) -> StarIdResult:
        """Identify body unit vectors (n, 3), brightest first; ``mag`` (n,) measured V or None."""
        ix = self.index
        nb = min(b.shape[0], self.max_stars)
        match, q, pf, st, tried = pyramid_core(
            np.ascontiguousarray(b[:nb]), ix.vectors, ix.vmag, ix.pair_theta, ix.pair_a, ix.pair_b, ix.kv,
            ix.kv_m, ix.kv_q, ix.nb_start, ix.nb_idx, ix.vox_start, ix.vox_stars, ix.vox_vec, ix.vox_h, ix.vox_g,
            self.eps, self.label_tol, ix.max_sep, self.fov_radius, self.p_false_max, self.max_triangles, self._mark,
            self._nnav)
        full = -np.ones(b.shape[0], dtype=np.int64)
        full[:nb] = match
        if st == ST_OK and b.shape[0] > nb:
            label_rest(np.ascontiguousarray(b), q, ix.vectors, ix.vmag, ix.vox_start, ix.vox_stars, ix.vox_vec,
                       ix.vox_h, ix.vox_g, self.fov_radius, self.label_tol, full)
            q, full, _, _ = verify_matches(np.ascontiguousarray(b), ix.vectors, full, self.label_tol)
        if st == ST_OK:
            q, full, n_ok = self.check.apply(b, mag, ix.vectors, ix.vmag, full)
            if n_ok == 0:
                st = ST_STAR_CHECK
        return StarIdResult.make(ix, full, q, st == ST_OK, STATUS_TEXT[int(st)], pf, "pyramid")

    def identify(self, uv: np.ndarray, mag=None) -> StarIdResult:
        """Identify centroids ``uv`` (n, 2) [col, row] px, brightest first; ``mag`` (n,)
        their calibrated measured V (None: position-only per-star check)."""
        return self.identify_vectors(to_body_vectors(self._params, uv), mag)
