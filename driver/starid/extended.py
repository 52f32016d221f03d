"""Extended grid tracking identification (paper 001) and the extended-image triangle baseline.

While tracking, the attitude predicted from the last identification and the gyro,
``q_pred`` (ICRS → body), gives the boresight of the coming image:

* image A — the catalog stars (V ≤ ``mag_max``) that fall in the extended field
  θ_E × θ_E around the predicted boresight, as predicted body vectors; its real part is
  what projects onto the sensor;
* image B — the observed centroids (body vectors);
* image C = B ∪ (A minus its real part): the observed field surrounded by the predicted
  extension ring.

Reference stars (the brightest ``max_ref`` of B) get grid patterns built on C; every
real-part star of A gets its pattern built on A; patterns are lists of occupied cell
numbers (:func:`gyrostar.starid.grid.grid_pattern`), compared by shared cells. A reference
takes the candidate with the most shared cells when that is ≥ ξ and strictly more than any
other; a candidate claimed by two references is given to neither. The matches must then
pass QUEST residual verification (with a leave-one-out residual test at 1.5× the tolerance
for 4–6 matches; a solution from ≤ 3 matches first labels the other centroids, and two
matches are accepted only from images of at most three centroids), no matched star may have a
second indexed star within
the residual tolerance (:func:`gyrostar.starid.verify.drop_ambiguous`; the index may go
deeper than ``mag_max`` for this), and the attitude must lie within ``gate`` (rad) of the
prediction, or the frame is rejected (the tracker falls back to lost-in-space). Last, the
per-star check (:class:`gyrostar.starid.star_check.StarCheck`, swappable) judges every
label on its own (position, and magnitude when given), unlabels failures and re-solves.

``method="triangle"``: the comparison method of paper 001 (extended image + triangles):
each star's triangle with its two nearest stars (beyond ``2·tri_eps``) in C (reference)
or A (candidate); a match needs all three sides within ``tri_eps`` and to be unique.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from ..attitude import quat_error_angles, quat_to_dcm
from ..camera import project_point, unproject_many
from ..errors import ConfigError
from .grid import GridParams, cells_from, nth_neighbour, tangent_coords_into
from .index import cone_query, n_brighter
from .pyramid import label_rest
from .result import StarIdResult
from .star_check import StarCheck, check_stars
from .verify import drop_ambiguous, loo_reject, verify_matches

M_GRID, M_TRIANGLE = 0, 1
LOO_MAX = 6  # leave-one-out test from 4 up to this many matches
LOO_TOL = 1.5  # its tolerance, in residual tolerances (the others' attitude adds its own error)


@njit(cache=True)
def _angle(u, v):
    return np.arccos(min(1.0, max(-1.0, u[0] * v[0] + u[1] * v[1] + u[2] * v[2])))


@njit(cache=True)
def _triangle(vecs, ref, min_sep):
    """Sides (θ_r1, θ_r2, θ_12) of ``ref`` with its two nearest stars beyond ``min_sep``,
    plus the neighbour index; sides are NaN when fewer than two."""
    d1 = np.inf
    d2 = np.inf
    i1 = -1
    i2 = -1
    for s in range(vecs.shape[0]):
        if s == ref:
            continue
        d = _angle(vecs[ref], vecs[s])
        if d < min_sep:
            continue
        if d < d1:
            d2 = d1
            i2 = i1
            d1 = d
            i1 = s
        elif d < d2:
            d2 = d
            i2 = s
    out = np.full(3, np.nan)
    if i2 < 0:
        return out, i1
    out[0] = d1
    out[1] = d2
    out[2] = _angle(vecs[i1], vecs[i2])
    return out, i1


@njit(cache=True)
def build_images(b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg, mag_max, half_ext, mag_deep):
    """Images A and C. Returns ``(a_vecs, a_cat, a_real, c_vecs, c_cat)``: A's predicted
    body vectors, catalog indexes and real-part flags; C's body vectors and catalog index
    of each row (-1 for the observed rows, which come first). The ring holds stars to
    ``mag_max``; A's real part goes to ``mag_deep`` (stars the sensor may report when
    magnitude noise lifts them over its limit)."""
    a = quat_to_dcm(q_pred)
    bore = a[2].copy()
    radius = np.arctan(half_ext * np.sqrt(2.0)) + 1e-3
    near = cone_query(vvec, vstars, vstart, vh, vg, bore, radius, n_brighter(vmag, max(mag_max, mag_deep)))
    m = near.shape[0]
    a_vecs = np.empty((m, 3))
    a_cat = np.empty(m, dtype=np.int64)
    a_real = np.empty(m, dtype=np.bool_)
    k = 0
    n_ring = 0
    p = np.empty(3)
    for t in range(m):
        v = vec[near[t]]
        for r in range(3):
            p[r] = a[r, 0] * v[0] + a[r, 1] * v[1] + a[r, 2] * v[2]
        if p[2] <= 0.0 or abs(p[0] / p[2]) > half_ext or abs(p[1] / p[2]) > half_ext:
            continue
        _, _, ok = project_point(cam, p)
        if not ok and vmag[near[t]] > mag_max:
            continue
        a_vecs[k] = p
        a_cat[k] = near[t]
        a_real[k] = ok
        if not ok:
            n_ring += 1
        k += 1
    n = b.shape[0]
    c_vecs = np.empty((n + n_ring, 3))
    c_cat = -np.ones(n + n_ring, dtype=np.int64)
    c_vecs[:n] = b
    j = n
    for t in range(k):
        if not a_real[t]:
            c_vecs[j] = a_vecs[t]
            c_cat[j] = a_cat[t]
            j += 1
    return a_vecs[:k], a_cat[:k], a_real[:k], c_vecs, c_cat


@njit(cache=True)
def extended_core(b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg, mag_max, half_ext, br, pr, g, cell, xi,
                  max_ref, method, tri_eps, n_orient, mag_deep):
    """Match the brightest ``max_ref`` observed stars. Returns ``(match, nb_c, c_cat, cand_cat,
    pat_nb)``: catalog index per observed star (-1 none); C-row of each reference's
    neighbour (-1 none); C's catalog map (-1 for observed rows); catalog index of each
    candidate (A's real part); catalog index of the neighbour each candidate pattern is
    oriented on, (n_cand, n_orient) (-1 none).

    ``n_orient``: each candidate's pattern is built oriented on each of its ``n_orient``
    nearest stars outside ``br`` and the best-sharing orientation counts, so a neighbour
    that is missing from, or extra in, the observed image (magnitude noise at the sensor
    limit) does not lose the match."""
    n = b.shape[0]
    a_vecs, a_cat, a_real, c_vecs, c_cat = build_images(b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg,
                                                        mag_max, half_ext, mag_deep)
    na = a_vecs.shape[0]
    nc = c_vecs.shape[0]
    match = -np.ones(n, dtype=np.int64)
    nb_c = -np.ones(n, dtype=np.int64)
    ncand = 0
    for t in range(na):
        if a_real[t]:
            ncand += 1
    cand = np.empty(ncand, dtype=np.int64)
    cand_cat = np.empty(ncand, dtype=np.int64)
    j = 0
    for t in range(na):
        if a_real[t]:
            cand[j] = t
            cand_cat[j] = a_cat[t]
            j += 1
    no = n_orient if method == M_GRID else 1
    pat_nb = -np.ones((ncand, no), dtype=np.int64)
    nr = min(n, max_ref)
    if method == M_GRID:
        npat = ncand * n_orient
        cells = np.empty((npat, na + 1), dtype=np.int64)
        ncell = np.zeros(npat, dtype=np.int64)
        done = np.zeros(npat, dtype=np.bool_)
        xs = np.empty((ncand, na))
        ys = np.empty((ncand, na))
        idx = np.empty((ncand, na), dtype=np.int64)
        dots = np.empty((ncand, na))
        kk = np.zeros(ncand, dtype=np.int64)
        nbpos = -np.ones((ncand, n_orient), dtype=np.int64)
        for c in range(ncand):
            kk[c] = tangent_coords_into(a_vecs, cand[c], br, pr, xs[c], ys[c], idx[c], dots[c])
            for o in range(n_orient):
                nb = nth_neighbour(dots[c], kk[c], o)
                if nb < 0:
                    break
                nbpos[c, o] = nb
                pat_nb[c, o] = a_cat[idx[c, nb]]
            if nbpos[c, 0] >= 0:
                ncell[c * n_orient] = cells_from(xs[c], ys[c], kk[c], nbpos[c, 0], g, cell, cells[c * n_orient])
            done[c * n_orient] = True
        buf = np.empty(nc + 1, dtype=np.int64)
        occupied = np.zeros(g * g, dtype=np.bool_)
        cx = np.empty(nc)
        cy = np.empty(nc)
        cidx = np.empty(nc, dtype=np.int64)
        cdots = np.empty(nc)
        for r in range(nr):
            kr = tangent_coords_into(c_vecs, r, br, pr, cx, cy, cidx, cdots)
            nbp = nth_neighbour(cdots, kr, 0)
            if nbp < 0:
                continue
            nb_c[r] = cidx[nbp]
            k = cells_from(cx, cy, kr, nbp, g, cell, buf)
            if k < xi:
                continue
            for t in range(k):
                occupied[buf[t]] = True
            # pass 1: every candidate in its first orientation; a clear winner is taken.
            # pass 2 (otherwise): all orientations, the extra patterns built on first use.
            for npass in range(2):
                no = 1 if npass == 0 else n_orient
                best = -1
                bv = 0
                second = 0
                for c in range(ncand):
                    cv = 0
                    cu = -1
                    for o in range(no):
                        u = c * n_orient + o
                        if not done[u]:
                            if nbpos[c, o] >= 0:
                                ncell[u] = cells_from(xs[c], ys[c], kk[c], nbpos[c, o], g, cell, cells[u])
                            done[u] = True
                        v = 0
                        for t in range(ncell[u]):
                            if occupied[cells[u, t]]:
                                v += 1
                        if v > cv:
                            cv = v
                            cu = u
                    if cv > bv:
                        second = bv
                        bv = cv
                        best = cu
                    elif cv > second:
                        second = cv
                if npass == 0 and bv >= xi and bv >= second + 2:
                    break
            for t in range(k):
                occupied[buf[t]] = False
            if bv >= xi and bv > second:
                match[r] = a_cat[cand[best // n_orient]]
    else:
        tri = np.empty((ncand, 3))
        for u in range(ncand):
            tri[u], nb = _triangle(a_vecs, cand[u], 2.0 * tri_eps)
            if nb >= 0:
                pat_nb[u, 0] = a_cat[nb]
        for r in range(nr):
            tr, nb = _triangle(c_vecs, r, 2.0 * tri_eps)
            nb_c[r] = nb
            if np.isnan(tr[2]):
                continue
            hits = 0
            best = -1
            for u in range(ncand):
                if (abs(tri[u, 0] - tr[0]) <= tri_eps and abs(tri[u, 1] - tr[1]) <= tri_eps
                        and abs(tri[u, 2] - tr[2]) <= tri_eps):
                    hits += 1
                    best = u
            if hits == 1:
                match[r] = a_cat[cand[best]]
    # a catalog star claimed twice is given to neither
    for r in range(nr):
        for s in range(r + 1, nr):
            if match[r] >= 0 and match[r] == match[s]:
                match[r] = -1
                match[s] = -1
    return match, nb_c, c_cat, cand_cat, pat_nb


ST_OK, ST_FEW, ST_GATE, ST_BAD, ST_BAD_Q, ST_STAR_CHECK = 0, 1, 2, 3, 4, 5
STATUS_TEXT = {ST_OK: "ok", ST_FEW: "fewer than 2 verified matches",
               ST_GATE: "attitude disagrees with the prediction", ST_BAD: "non-finite centroid",
               ST_BAD_Q: "q_pred is not a unit quaternion",
               ST_STAR_CHECK: "too few stars pass the per-star check"}


@njit(cache=True)
def extended_identify_uv(uv, q_pred, cam, settings, vec, vmag, ids, vstart, vstars, vvec, vh, vg, mag, check):
    """:func:`extended_identify` from centroids ``uv`` (n, 2) px in one compiled call, then
    the per-star check :func:`gyrostar.starid.star_check.check_stars` with the scalars
    ``check`` (:meth:`StarCheck.settings`; empty: no check) and measured V ``mag`` (n,)
    (empty: unknown).

    ``settings`` packs the identifier's scalars (see :class:`ExtendedIdentifier`). Returns
    ``(match, match_ids, q, status, nb_c, c_cat, cand_cat, pat_nb)``; status ``ST_BAD``
    when a centroid is not finite, ``ST_BAD_Q`` when ``q_pred`` is not a unit quaternion."""
    n_orient = int(settings[10])
    e = np.empty(0, dtype=np.int64)
    none = -np.ones(uv.shape[0], dtype=np.int64)
    qq = 0.0
    for i in range(4):
        qq += q_pred[i] * q_pred[i]
    if not (abs(qq - 1.0) <= 1e-6):
        return none, none.copy(), np.array([0.0, 0.0, 0.0, 1.0]), ST_BAD_Q, e, e, e, np.empty((0, 1), dtype=np.int64)
    for i in range(uv.shape[0]):
        if not (np.isfinite(uv[i, 0]) and np.isfinite(uv[i, 1])):
            return none, none.copy(), np.array([0.0, 0.0, 0.0, 1.0]), ST_BAD, e, e, e, np.empty((0, 1), dtype=np.int64)
    b = unproject_many(cam, uv)
    match, q, st, nb_c, c_cat, cand_cat, pat_nb = extended_identify(
        b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg, settings[0], settings[1], settings[2], settings[3],
        int(settings[4]), settings[5], int(settings[6]), int(settings[7]), int(settings[8]), settings[9], n_orient,
        settings[11], settings[12], settings[13], settings[14])
    if st == ST_OK and check.shape[0] > 0:
        m = mag if mag.shape[0] == uv.shape[0] else np.full(uv.shape[0], np.nan)
        qc, nok = check_stars(b, m, vec, vmag, match, check[0], check[1], check[2], check[3], check[4],
                              int(check[5]), int(check[6]))
        if nok == 0:
            st = ST_STAR_CHECK
        else:
            q = qc
    out_ids = -np.ones(uv.shape[0], dtype=np.int64)
    for i in range(uv.shape[0]):
        if match[i] >= 0:
            out_ids[i] = ids[match[i]]
    return match, out_ids, q, st, nb_c, c_cat, cand_cat, pat_nb


@njit(cache=True)
def extended_identify(b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg, mag_max, half_ext, br, pr, g, cell, xi,
                      max_ref, method, tri_eps, n_orient, tol, fov_radius, gate, mag_deep):
    """:func:`extended_core` + verification, in one call. Returns ``(match, q, status, nb_c,
    c_cat, cand_cat, pat_nb)`` (``match`` all -1 unless status is ``ST_OK``)."""
    raw, nb_c, c_cat, cand_cat, pat_nb = extended_core(b, q_pred, cam, vec, vmag, vstart, vstars, vvec, vh, vg, mag_max,
                                                       half_ext, br, pr, g, cell, xi, max_ref, method,
                                                       tri_eps, n_orient, mag_deep)
    q, match, nok, _ = verify_matches(b, vec, raw, tol)
    if nok <= 3:
        # a weak solution: its attitude must label other centroids (unambiguous both ways)
        label_rest(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, tol, match, np.empty(0), 0.0)
        q, match, nok, _ = verify_matches(b, vec, match, tol)
    while 4 <= nok <= LOO_MAX and loo_reject(b, vec, match, LOO_TOL * tol):
        q, match, nok, _ = verify_matches(b, vec, match, tol)
    if nok >= 2 and drop_ambiguous(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, tol, match) > 0:
        q, match, nok, _ = verify_matches(b, vec, match, tol)
    if nok < 2 or (nok == 2 and b.shape[0] >= 4):
        # two matches out of a rich field: the rest should have been labelled, so no
        match[:] = -1
        return match, q, ST_FEW, nb_c, c_cat, cand_cat, pat_nb
    err = quat_error_angles(q, q_pred)
    if np.sqrt(err[0] * err[0] + err[1] * err[1]) > gate:
        match[:] = -1
        return match, q, ST_GATE, nb_c, c_cat, cand_cat, pat_nb
    return match, q, ST_OK, nb_c, c_cat, cand_cat, pat_nb


@dataclasses.dataclass
class ExtendedIdentifier:
    """Tracking identification on the extended image (grid or triangle comparison).

    ``sigma_px``: expected total centroid error (px, 1σ; sensor + prediction) for the
    residual tolerance ``n_sigma·1.25·σ`` and the triangle tolerance ``n_sigma·√2·σ``.
    ``ext_deg``: θ_E (paper: 8°). ``mag_max``: faintest catalog star put into image A.
    ``gate_px``: largest accepted distance (px at the boresight) between the verified
    attitude and the prediction. ``n_orient``: orientations tried per candidate pattern
    (1 = the plain grid rule). ``deep_mag``: A's real part also holds catalog stars this
    much fainter than ``mag_max`` (candidates and pattern stars the sensor may report).
    ``check``: the per-star verification stage (``apply(b, mag, ref, vmag, match) -> (q,
    match, n_ok)``); default a :class:`StarCheck` at ``sigma_px`` and ``mag_max``, two
    stars minimum (the tracker asks for more). Parameters are read once, at construction.
    """

    index: object
    camera: object
    params: GridParams = dataclasses.field(default_factory=GridParams)
    method: str = "grid"
    ext_deg: float = 8.0
    mag_max: float = 7.5
    sigma_px: float = 1.0
    n_sigma: float = 4.0
    max_ref: int = 8
    gate_px: float = 20.0
    n_orient: int = 3
    deep_mag: float = 0.3
    check: object = None

    def __post_init__(self) -> None:
        if self.method not in ("grid", "triangle"):
            raise ConfigError(f"extended method must be 'grid' or 'triangle', got {self.method!r}")
        if not (0.0 < self.ext_deg < 60.0):
            raise ConfigError(f"extended field must be in (0, 60)°, got {self.ext_deg}")
        self._cam = self.camera.as_array()
        ifov = 1.0 / self.camera.focal_length_px
        self.tol = self.n_sigma * 1.25 * self.sigma_px * ifov + 2e-6
        self.tri_eps = self.n_sigma * math.sqrt(2.0) * self.sigma_px * ifov + 2e-6
        self.gate = self.gate_px * ifov
        self.half_ext = math.tan(math.radians(self.ext_deg) / 2.0)
        w, h = self.camera.width_px, self.camera.height_px
        self.fov_radius = math.atan(0.5 * math.hypot(w, h) / self.camera.focal_length_px)
        self._code = M_GRID if self.method == "grid" else M_TRIANGLE
        self._method = "extended-" + self.method
        p = self.params
        self._settings = np.array([self.mag_max, self.half_ext, p.br, p.pr, p.g, p.cell, p.xi, self.max_ref,
                                   self._code, self.tri_eps, self.n_orient, self.tol, self.fov_radius, self.gate,
                                   self.mag_max + self.deep_mag], dtype=np.float64)
        self.last = None  # raw outputs of the last call (neighbour statistics)
        if self.check is None:
            self.check = StarCheck(self.sigma_px, self.camera.focal_length_px, mag_limit=self.mag_max, min_stars=2)
        # a StarCheck runs inside the compiled call; another stage runs after it
        self._fused = self.check.settings() if isinstance(self.check, StarCheck) else np.empty(0)
        self._no_mag = np.empty(0)

    def identify_vectors(self, b: np.ndarray, q_pred: np.ndarray, mag=None) -> StarIdResult:
        """Identify body unit vectors (n, 3), brightest first, given the predicted attitude;
        ``mag`` (n,) their calibrated measured V or None."""
        ix, p = self.index, self.params
        b = np.ascontiguousarray(b, dtype=np.float64)
        out = extended_identify(b, self._q(q_pred), self._cam, ix.vectors,
                                ix.vmag, ix.vox_start, ix.vox_stars, ix.vox_vec, ix.vox_h, ix.vox_g, self.mag_max,
                                self.half_ext, p.br, p.pr, p.g, p.cell, p.xi, self.max_ref, self._code, self.tri_eps,
                                self.n_orient, self.tol, self.fov_radius, self.gate, self.mag_max + self.deep_mag)
        match, q, st = out[0], out[1], int(out[2])
        self.last = (match,) + out[3:]
        if st == ST_OK:
            q, match, st = self._check(b, mag, match)
        return StarIdResult.make(ix, match, q, st == ST_OK, STATUS_TEXT[st], math.nan, self._method)

    def _check(self, b, mag, match):
        q, match, n_ok = self.check.apply(b, mag, self.index.vectors, self.index.vmag, match)
        return q, match, (ST_OK if n_ok > 0 else ST_STAR_CHECK)

    def identify(self, uv: np.ndarray, q_pred: np.ndarray, mag=None) -> StarIdResult:
        """Identify centroids ``uv`` (n, 2) [col, row] px, brightest first (one compiled call
        and the per-star check); ``mag`` (n,) their calibrated measured V or None."""
        ix = self.index
        pts = uv
        if not (isinstance(pts, np.ndarray) and pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 2
                and pts.flags.c_contiguous):
            pts = np.asarray(uv, dtype=np.float64)
            pts = np.ascontiguousarray(pts.reshape(-1, 2) if pts.size else np.empty((0, 2)))
        q = q_pred if (isinstance(q_pred, np.ndarray) and q_pred.dtype == np.float64 and q_pred.shape == (4,)) \
            else self._q(q_pred)
        m = self._no_mag
        if mag is not None:
            m = np.ascontiguousarray(mag, dtype=np.float64).reshape(-1)
            if m.shape[0] != pts.shape[0]:
                raise ConfigError(f"{m.shape[0]} magnitudes for {pts.shape[0]} centroids")
        out = extended_identify_uv(pts, q, self._cam, self._settings, ix.vectors, ix.vmag, ix.ids, ix.vox_start,
                                   ix.vox_stars, ix.vox_vec, ix.vox_h, ix.vox_g, m, self._fused)
        st = out[3]
        if st == ST_BAD or st == ST_BAD_Q:
            raise ConfigError(STATUS_TEXT[st])
        self.last = (out[0],) + out[4:]
        if st == ST_OK and self._fused.shape[0] == 0:
            q, match, st = self._check(unproject_many(self._cam, pts), mag, out[0])
            return StarIdResult.make(ix, match, q, st == ST_OK, STATUS_TEXT[st], math.nan, self._method)
        return StarIdResult(out[0], out[1], out[2], st == ST_OK, STATUS_TEXT[st], math.nan, self._method)

    @staticmethod
    def _q(q_pred) -> np.ndarray:
        q = np.ascontiguousarray(q_pred, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(q @ q - 1.0) > 1e-6:
            raise ConfigError("q_pred must be a finite unit quaternion [x, y, z, w]")
        return q
