"""Scale-invariant four-star patterns for solving with no field-of-view hint (numba).

A pattern is four stars. Their unit vectors are projected gnomonically onto the tangent
plane at their mean direction; the six distances between them, sorted, divided by the
largest, give five edge ratios in (0, 1] that do not depend on the image scale or
rotation (the idea of tetra3, Pettersson/ESA, here with the tangent-plane distances so that
a pinhole image's pixel distances and the catalog's agree wherever the pattern lies).

Database (:class:`PatternDatabase`, cached under ``$GYROSTAR_CACHE/starid``): for each
scale ``s`` of a geometric lattice from the widest field down to the narrowest (step
``SCALE_STEP``), pattern stars are the catalog's locally brightest, thinned brightest first
to one per ``s/√STARS_PER_FIELD``; every four of them with all six separations within
``PATTERN_SPAN·s`` is a pattern. Patterns are stored once (their four catalog rows and five
ratios), keyed by the ratios quantised in bins of ``2·max_error`` in an open-addressing
hash table (numpy arrays).

Image side (:func:`match_patterns`): four-spot combinations of the brightest spots in
order of brightness (every combination among the first k before the (k+1)-th spot joins),
each turned into unit vectors with a few focal-length guesses across the range (the ratios
of wide patterns far off the axis depend weakly on the focal length), looked up in every
bin within ``max_error``; a catalog pattern whose ratios all lie within ``max_error`` is a
candidate: the focal length from its six angles, the attitude from its four stars (mirror
images rejected), then the other spots labelled with catalog stars, the attitude, focal
length and k1 refitted and labelled again within a few pixels. A candidate with enough
labelled stars, whose labels beyond its four would come by chance (Poisson, from the catalog
stars it puts on the sensor and the label tolerance) with probability at most ``CHANCE_MAX``,
is returned for verification (:mod:`gyrostar.starid.lost_in_space`).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..core.quest import quest
from ..errors import ConfigError
from ..paths import cache_dir
from .index import cone_query, voxel_grid
from .plate_fit import fit_plate, project_radial

PATTERN_VERSION = 1
SCALE_STEP = 1.4          # ratio of successive pattern scales
STARS_PER_FIELD = 25      # pattern stars per s×s field (sets the thinning separation)
PATTERN_SPAN = 0.75       # × s: the largest separation within a pattern
MAX_ERROR = 0.01          # edge-ratio tolerance of a lookup
CHANCE_MAX = 1e-6         # a proposal's labels beyond its four stars must be this unlikely by chance
_PRIME = np.int64(2654435761)


# ------------------------------------------------------------------ pattern geometry
@njit(cache=True)
def pattern_edges(v4):
    """Six tangent-plane distances (sorted ascending) of four unit vectors (4, 3), at their
    mean direction; also the pairs (6, 2) in the same order."""
    c = v4[0] + v4[1] + v4[2] + v4[3]
    c /= np.sqrt(c @ c)
    # tangent basis
    t = np.array([1.0, 0.0, 0.0]) if abs(c[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = t - (t @ c) * c
    e1 /= np.sqrt(e1 @ e1)
    e2 = np.cross(c, e1)
    p = np.empty((4, 2))
    for i in range(4):
        z = v4[i] @ c
        p[i, 0] = (v4[i] @ e1) / z
        p[i, 1] = (v4[i] @ e2) / z
    d = np.empty(6)
    pairs = np.empty((6, 2), dtype=np.int64)
    k = 0
    for i in range(4):
        for j in range(i + 1, 4):
            d[k] = math.hypot(p[i, 0] - p[j, 0], p[i, 1] - p[j, 1])
            pairs[k, 0] = i
            pairs[k, 1] = j
            k += 1
    order = np.argsort(d)
    return d[order], pairs[order]


@njit(cache=True)
def _key(qr, size):
    h = np.int64(0)
    for i in range(5):
        h = (h * np.int64(131) + np.int64(qr[i])) & np.int64(0x7FFFFFFFFFFF)
    return ((h * _PRIME) & np.int64(0x7FFFFFFFFFFF)) % size


# ------------------------------------------------------------------ database build
@njit(cache=True)
def _thin(vec, sep):
    """Indexes of ``vec`` (sorted brightest first) kept brightest first so that no two kept
    stars are within ``sep`` (rad)."""
    h = 2.0 * math.sin(sep / 2.0)
    g = int(math.ceil(2.0 / h)) + 1
    head = -np.ones(g * g * g, dtype=np.int64)
    nxt = -np.ones(vec.shape[0], dtype=np.int64)
    keep = np.empty(vec.shape[0], dtype=np.int64)
    n = 0
    cosr = math.cos(sep)
    for s in range(vec.shape[0]):
        ix = min(g - 1, int((vec[s, 0] + 1.0) / h))
        iy = min(g - 1, int((vec[s, 1] + 1.0) / h))
        iz = min(g - 1, int((vec[s, 2] + 1.0) / h))
        near = False
        for a in range(max(0, ix - 1), min(g, ix + 2)):
            for b in range(max(0, iy - 1), min(g, iy + 2)):
                for c in range(max(0, iz - 1), min(g, iz + 2)):
                    p = head[(a * g + b) * g + c]
                    while p >= 0:
                        if vec[p] @ vec[s] > cosr:
                            near = True
                            break
                        p = nxt[p]
                    if near:
                        break
                if near:
                    break
            if near:
                break
        if not near:
            cell = (ix * g + iy) * g + iz
            nxt[s] = head[cell]
            head[cell] = s
            keep[n] = s
            n += 1
    return keep[:n]


@njit(cache=True)
def _quads(vec, sel, span):
    """Every four of the stars ``sel`` (rows of ``vec``) with all separations ≤ ``span`` (rad):
    (m, 4) rows of ``vec``."""
    n = sel.shape[0]
    sv = vec[sel]
    cosr = math.cos(span)
    # neighbour lists (later stars only), by brute force over a sorted declination band
    z = sv[:, 2]
    order = np.argsort(z)
    zs = z[order]
    cap = 1024
    out = np.empty((cap, 4), dtype=np.int64)
    m = 0
    nb = np.empty(n, dtype=np.int64)
    for a in range(n):
        # candidates: |z_b − z_a| ≤ sin(span)-ish band
        lo = np.searchsorted(zs, sv[a, 2] - span * 1.01)
        hi = np.searchsorted(zs, sv[a, 2] + span * 1.01)
        k = 0
        for t in range(lo, hi):
            b = order[t]
            if b > a and sv[a] @ sv[b] >= cosr:
                nb[k] = b
                k += 1
        nbs = np.sort(nb[:k])
        for i in range(k):
            bi = nbs[i]
            for j in range(i + 1, k):
                bj = nbs[j]
                if sv[bi] @ sv[bj] < cosr:
                    continue
                for l in range(j + 1, k):
                    bl = nbs[l]
                    if sv[bi] @ sv[bl] < cosr or sv[bj] @ sv[bl] < cosr:
                        continue
                    if m == cap:
                        cap *= 2
                        bigger = np.empty((cap, 4), dtype=np.int64)
                        bigger[:m] = out[:m]
                        out = bigger
                    out[m, 0] = sel[a]
                    out[m, 1] = sel[bi]
                    out[m, 2] = sel[bj]
                    out[m, 3] = sel[bl]
                    m += 1
    return out[:m]


@njit(cache=True)
def _ratios_of(vec, quads):
    n = quads.shape[0]
    out = np.empty((n, 5), dtype=np.float32)
    v4 = np.empty((4, 3))
    for i in range(n):
        for k in range(4):
            v4[k] = vec[quads[i, k]]
        d, _ = pattern_edges(v4)
        for k in range(5):
            out[i, k] = d[k] / d[5]
    return out


@njit(cache=True)
def _hash_fill(ratios, bin_w, size):
    table = -np.ones(size, dtype=np.int32)
    qr = np.empty(5, dtype=np.int64)
    for i in range(ratios.shape[0]):
        for k in range(5):
            qr[k] = int(ratios[i, k] / bin_w)
        h = _key(qr, size)
        while table[h] >= 0:
            h = (h + 1) % size
        table[h] = i
    return table


class PatternDatabase:
    """Four-star patterns over a range of fields (see the module docstring).

    ``vectors`` (n, 3) and ``vmag`` (n,) and ``ids`` (n,): the catalog stars (sorted by V);
    ``quads`` (m, 4) int32 rows of them; ``ratios`` (m, 5) float32; ``table`` the hash table
    of pattern numbers (-1 empty); ``bin_w`` the ratio bin width; ``fov_range_deg``."""

    def __init__(self, vectors, vmag, ids, quads, ratios, table, bin_w, fov_range_deg, mag_limit):
        self.vectors = np.ascontiguousarray(vectors, dtype=np.float64)
        self.vmag = np.ascontiguousarray(vmag, dtype=np.float64)
        self.ids = np.ascontiguousarray(ids, dtype=np.int64)
        self.quads = np.ascontiguousarray(quads, dtype=np.int32)
        self.ratios = np.ascontiguousarray(ratios, dtype=np.float32)
        self.table = np.ascontiguousarray(table, dtype=np.int32)
        self.bin_w = float(bin_w)
        self.fov_range_deg = (float(fov_range_deg[0]), float(fov_range_deg[1]))
        self.mag_limit = float(mag_limit)
        self.vox_h = 0.02
        self.vox_g, self.vox_start, self.vox_stars = voxel_grid(self.vectors, self.vox_h)
        self.vox_vec = np.ascontiguousarray(self.vectors[self.vox_stars])

    def __len__(self) -> int:
        return int(self.quads.shape[0])


def scales_deg(fov_min: float, fov_max: float) -> list[float]:
    """Pattern scales (°): the widest field, divided by ``SCALE_STEP`` until below the
    narrowest field's height (a 4:3 sensor's short side)."""
    out = [fov_max]
    while out[-1] > 0.75 * fov_min:
        out.append(out[-1] / SCALE_STEP)
    return out


def build_pattern_database(catalog, fov_range_deg, max_error=MAX_ERROR, progress=None) -> PatternDatabase:
    """Patterns of ``catalog`` (a :class:`gyrostar.catalog.StarCatalog`, sorted by V) for
    fields across ``fov_range_deg`` (°); ``progress(text)`` is told of each scale."""
    vec = np.ascontiguousarray(catalog.vectors, dtype=np.float64)
    all_quads = []
    seen = set()
    for s in scales_deg(*fov_range_deg):
        sel = _thin(vec, math.radians(s) / math.sqrt(STARS_PER_FIELD))
        quads = _quads(vec, sel.astype(np.int64), math.radians(PATTERN_SPAN * s))
        quads = np.sort(quads, axis=1)
        # a pattern found at two scales is stored once
        codes = quads[:, 0] * (1 << 51) + quads[:, 1] * (1 << 34) + quads[:, 2] * (1 << 17) + quads[:, 3]
        new = np.array([c not in seen for c in codes.tolist()], dtype=bool)
        seen.update(codes[new].tolist())
        all_quads.append(quads[new])
        if progress is not None:
            progress(f"scale {s:.1f}°: {len(sel)} pattern stars, {int(new.sum())} patterns")
    quads = np.concatenate(all_quads) if all_quads else np.empty((0, 4), np.int64)
    ratios = _ratios_of(vec, quads)
    size = max(1024, 2 * len(quads) + 1)
    bin_w = 4.0 * max_error
    table = _hash_fill(ratios, bin_w, size)
    return PatternDatabase(vec, catalog.vmag, catalog.ids, quads, ratios, table, bin_w, fov_range_deg,
                           float(catalog.vmag[-1]) if len(catalog.vmag) else 0.0)


def pattern_db_path(catalog_name: str, mag_limit: float, fov_range_deg, max_error: float) -> os.PathLike:
    lo, hi = fov_range_deg
    return cache_dir("starid") / (f"patterns_{catalog_name}_m{mag_limit:.2f}_f{lo:.3f}-{hi:.3f}_e{max_error:.4f}"
                                  f"_s{SCALE_STEP:.2f}_n{STARS_PER_FIELD}_p{PATTERN_SPAN:.2f}_v{PATTERN_VERSION}.npz")


def load_pattern_database(catalog_name: str, mag_limit: float, fov_range_deg, max_error: float = MAX_ERROR,
                          epoch: float = 2025.0, quiet: bool = False) -> PatternDatabase:
    """The pattern database, built once and cached; building prints its progress on stderr."""
    from ..catalog import deepest_limit, load_catalog

    lo, hi = float(fov_range_deg[0]), float(fov_range_deg[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.5 <= lo <= hi <= 60.0):
        raise ConfigError(f"field-of-view range must satisfy 0.5 ≤ min ≤ max ≤ 60°, got {lo:g}, {hi:g}")
    path = pattern_db_path(catalog_name, mag_limit, (lo, hi), max_error)
    cat = load_catalog(catalog_name, deepest_limit(catalog_name, mag_limit), epoch)
    if path.exists():
        try:
            with np.load(path) as z:
                return PatternDatabase(cat.vectors, cat.vmag, cat.ids, z["quads"], z["ratios"], z["table"],
                                       float(z["bin_w"]), (lo, hi), float(z["mag_limit"]))
        except (OSError, KeyError, ValueError):
            path.unlink(missing_ok=True)

    def tell(text):
        if not quiet:
            print(f"building the pattern database ({lo:g}–{hi:g}°, {catalog_name} to V {mag_limit:g}): {text}",
                  file=sys.stderr, flush=True)

    db = build_pattern_database(cat, (lo, hi), max_error, tell)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    os.close(fd)
    np.savez(tmp, quads=db.quads, ratios=db.ratios, table=db.table, bin_w=db.bin_w, mag_limit=db.mag_limit)
    os.replace(tmp, path)
    tell(f"{len(db)} patterns, cached in {path}")
    return db


# ------------------------------------------------------------------ image side
@njit(cache=True)
def _pinhole_vecs(uv, idx, f, cx, cy):
    out = np.empty((idx.shape[0], 3))
    for k in range(idx.shape[0]):
        x = (uv[idx[k], 0] - cx) / f
        y = (uv[idx[k], 1] - cy) / f
        n = math.sqrt(x * x + y * y + 1.0)
        out[k, 0] = x / n
        out[k, 1] = y / n
        out[k, 2] = 1.0 / n
    return out


@njit(cache=True)
def _angles6(v4):
    out = np.empty(6)
    k = 0
    for i in range(4):
        for j in range(i + 1, 4):
            out[k] = math.acos(min(1.0, max(-1.0, v4[i] @ v4[j])))
            k += 1
    return out


@njit(cache=True)
def _best_permutation(d_img, p_img, d_cat, p_cat):
    """Star correspondence image → catalog pattern: the permutation of the four catalog stars
    whose sorted-edge pairs agree with the image's (both edge lists sorted). Returns perm
    (4,) with ``perm[image star] = catalog star`` or perm[0] = -1 when the edge order is
    inconsistent."""
    perm = -np.ones(4, dtype=np.int64)
    # each star's set of edge ranks identifies it (the ranks of its three edges)
    sig_i = np.zeros(4, dtype=np.int64)
    sig_c = np.zeros(4, dtype=np.int64)
    for k in range(6):
        sig_i[p_img[k, 0]] |= 1 << k
        sig_i[p_img[k, 1]] |= 1 << k
        sig_c[p_cat[k, 0]] |= 1 << k
        sig_c[p_cat[k, 1]] |= 1 << k
    for i in range(4):
        for c in range(4):
            if sig_i[i] == sig_c[c]:
                perm[i] = c
    for i in range(4):
        if perm[i] < 0:
            perm[0] = -1
            return perm
    return perm


@njit(cache=True)
def _label(uv, n_lab, a, f, k1, cx, cy, vec, cand, tol0, tol_slope, centre, match, dist):
    """Nearest projected catalog star (rows ``cand``) within tol0 + tol_slope·(distance to
    ``centre``) px of each of the first ``n_lab`` spots; each star labels one spot."""
    m = cand.shape[0]
    pu = np.empty(m)
    pv = np.empty(m)
    okp = np.zeros(m, dtype=np.bool_)
    for t in range(m):
        u, v, ok = project_radial(a, vec[cand[t]], f, k1, cx, cy)
        pu[t] = u
        pv[t] = v
        okp[t] = ok
    used = np.zeros(m, dtype=np.bool_)
    n = 0
    for s in range(n_lab):
        match[s] = -1
        tol = tol0 + tol_slope * math.hypot(uv[s, 0] - centre[0], uv[s, 1] - centre[1])
        best = tol * tol
        bt = -1
        for t in range(m):
            if not okp[t] or used[t]:
                continue
            d2 = (pu[t] - uv[s, 0]) ** 2 + (pv[t] - uv[s, 1]) ** 2
            if d2 < best:
                best = d2
                bt = t
        if bt >= 0:
            match[s] = cand[bt]
            used[bt] = True
            dist[s] = math.sqrt(best)
            n += 1
    return n


@njit(cache=True)
def _chance_labels(a, f, k1, cx, cy, width, height, vec, cand, n_spots, k, tol):
    """The chance that ``n_spots`` random spots get ``k`` or more labels within ``tol`` px
    from the catalog stars (rows ``cand``) the attitude puts on the sensor (Poisson)."""
    m = 0
    for t in range(cand.shape[0]):
        u, v, ok = project_radial(a, vec[cand[t]], f, k1, cx, cy)
        if ok and -0.5 <= u < width - 0.5 and -0.5 <= v < height - 0.5:
            m += 1
    lam = max(n_spots, 0) * m * math.pi * tol * tol / (width * height)
    if k <= 0:
        return 1.0
    term = math.exp(-lam)
    below = term
    for j in range(1, k):
        term *= lam / j
        below += term
    return max(0.0, 1.0 - below) if below < 0.999 else _tail(lam, k)


@njit(cache=True)
def _tail(lam, k):
    """P(X ≥ k) for X ~ Poisson(lam), summed upwards (accurate when it is small)."""
    term = math.exp(-lam)
    for j in range(1, k + 1):
        term *= lam / j
    total = 0.0
    j = k
    while term > 1e-300 and j < k + 200:
        total += term
        j += 1
        term *= lam / j
    return total


@njit(cache=True)
def _matched(uv, vec, match, n_lab):
    k = 0
    for s in range(n_lab):
        if match[s] >= 0:
            k += 1
    u = np.empty((k, 2))
    r = np.empty((k, 3))
    k = 0
    for s in range(n_lab):
        if match[s] >= 0:
            u[k] = uv[s]
            r[k] = vec[match[s]]
            k += 1
    return u, r


@njit(cache=True)
def match_patterns(uv, width, height, cx, cy, f_guesses, f_min, f_max, n_pattern, n_lab, quads, ratios, table,
                   bin_w, max_error, vec, n_cat, vox_vec, vox_stars, vox_start, vox_h, vox_g, tol_px, min_stars,
                   start, max_combos):
    """Search four-spot patterns of ``uv`` (n, 2) px (brightest first) from combination
    number ``start`` on (at most ``max_combos``) for a candidate that labels at least
    ``min_stars`` of the first ``n_lab`` spots within ``tol_px`` after a refit.

    Returns ``(next_start, q, f, k1, match (n_lab,), n_matched, combos_tried, lookups)``;
    ``next_start`` is -1 when the combinations are exhausted with nothing found (then
    n_matched is 0)."""
    n = uv.shape[0]
    npat = min(n, n_pattern)
    nl = min(n, n_lab)
    match = -np.ones(nl, dtype=np.int64)
    best_match = -np.ones(nl, dtype=np.int64)
    dist = np.zeros(nl)
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    idx = np.empty(4, dtype=np.int64)
    qr = np.empty(5, dtype=np.int64)
    lo_b = np.empty(5, dtype=np.int64)
    hi_b = np.empty(5, dtype=np.int64)
    size = table.shape[0]
    diag = math.hypot(width, height)
    combo = -1
    tried = 0
    lookups = 0
    v4c = np.empty((4, 3))
    for d in range(3, npat):
        for c in range(2, d):
            for b in range(1, c):
                for a in range(0, b):
                    combo += 1
                    if combo < start:
                        continue
                    if tried >= max_combos:
                        return combo, q0, 0.0, 0.0, best_match, 0, tried, lookups
                    tried += 1
                    idx[0], idx[1], idx[2], idx[3] = a, b, c, d
                    # too small or degenerate in the image: skip
                    dmax = 0.0
                    dmin = 1e30
                    for i in range(4):
                        for j in range(i + 1, 4):
                            dd = math.hypot(uv[idx[i], 0] - uv[idx[j], 0], uv[idx[i], 1] - uv[idx[j], 1])
                            dmax = max(dmax, dd)
                            dmin = min(dmin, dd)
                    if dmax < 0.1 * diag or dmin < 0.02 * dmax:
                        continue
                    for gi in range(f_guesses.shape[0]):
                        fg = f_guesses[gi]
                        v4 = _pinhole_vecs(uv, idx, fg, cx, cy)
                        d_img, p_img = pattern_edges(v4)
                        for k in range(5):
                            r = d_img[k] / d_img[5]
                            lo_b[k] = int(max(0.0, r - max_error) / bin_w)
                            hi_b[k] = int(min(1.0, r + max_error) / bin_w)
                        nbox = 1
                        for k in range(5):
                            nbox *= hi_b[k] - lo_b[k] + 1
                        for box in range(nbox):
                            rem = box
                            for k in range(5):
                                span = hi_b[k] - lo_b[k] + 1
                                qr[k] = lo_b[k] + rem % span
                                rem //= span
                            h = _key(qr, size)
                            while table[h] >= 0:
                                p = table[h]
                                h = (h + 1) % size
                                lookups += 1
                                ok = True
                                for k in range(5):
                                    if int(ratios[p, k] / bin_w) != qr[k]:
                                        ok = False
                                        break
                                if not ok:
                                    continue
                                for k in range(5):
                                    if abs(ratios[p, k] - d_img[k] / d_img[5]) > max_error:
                                        ok = False
                                        break
                                if not ok:
                                    continue
                                # candidate: correspondence, focal length, attitude
                                for k in range(4):
                                    v4c[k] = vec[quads[p, k]]
                                d_cat, p_cat = pattern_edges(v4c)
                                perm = _best_permutation(d_img, p_img, d_cat, p_cat)
                                if perm[0] < 0:
                                    continue
                                ref = np.empty((4, 3))
                                for k in range(4):
                                    ref[k] = v4c[perm[k]]
                                f = fg
                                th_c = _angles6(ref)
                                for _ in range(3):
                                    bv = _pinhole_vecs(uv, idx, f, cx, cy)
                                    th_i = _angles6(bv)
                                    f *= (th_i.sum() / th_c.sum())
                                if not (f_min <= f <= f_max):
                                    continue
                                bv = _pinhole_vecs(uv, idx, f, cx, cy)
                                # mirror image: handedness of the first three must agree
                                tb = bv[0] @ np.cross(bv[1], bv[2])
                                tr = ref[0] @ np.cross(ref[1], ref[2])
                                if tb * tr <= 0.0:
                                    continue
                                q, _ = quest(bv, ref, np.ones(4))
                                am = quat_to_dcm(q)
                                boresight = am[2]
                                rad = math.atan(0.5 * diag / f) * 1.05
                                cand = cone_query(vox_vec, vox_stars, vox_start, vox_h, vox_g, boresight, rad, n_cat)
                                centre = np.array([(uv[a, 0] + uv[b, 0] + uv[c, 0] + uv[d, 0]) / 4.0,
                                                   (uv[a, 1] + uv[b, 1] + uv[c, 1] + uv[d, 1]) / 4.0])
                                k1 = 0.0
                                nm = _label(uv, nl, am, f, k1, cx, cy, vec, cand, 2.0 * tol_px, 0.006, centre,
                                            match, dist)
                                if nm < min(min_stars, 6):
                                    continue
                                for it in range(2):
                                    mu, mr = _matched(uv, vec, match, nl)
                                    fk = mu.shape[0] >= 10
                                    q, f, k1, _, _, _ = fit_plate(mu, mr, q, f, k1, cx, cy, fk, False, 8)
                                    if not (f_min <= f <= f_max) or abs(k1) > 0.5:
                                        nm = 0
                                        break
                                    am = quat_to_dcm(q)
                                    nm = _label(uv, nl, am, f, k1, cx, cy, vec, cand, tol_px * (2 - it), 0.0,
                                                centre, match, dist)
                                    if nm < min_stars:
                                        break
                                if nm >= min_stars and _chance_labels(am, f, k1, cx, cy, width, height, vec, cand,
                                                                      nl - 4, nm - 4, tol_px) <= CHANCE_MAX:
                                    return combo + 1, q, f, k1, match, nm, tried, lookups
    return -1, q0, 0.0, 0.0, best_match, 0, tried, lookups
