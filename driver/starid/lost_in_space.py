"""Lost-in-space plate solving: centroids of one image → attitude, field of view and lens,
with or without a known camera (the public solver API).

* :func:`build_pyramid` — the lost-in-space Pyramid identifier for a camera: index to the
  sensor's limit with pairs across the diagonal, the thinned first tier, the faint stars the
  index leaves out (the builder ``eval starid`` and the flatsat loop's acquisition use).
* :class:`LostInSpace` — ``LostInSpace.for_camera(camera)`` (known intrinsics) or
  ``LostInSpace.for_sensor(width_px, height_px, fov_range_deg=(5, 30))`` (unknown focal
  length); ``solve(xy, mag=None, fov_hint_deg=None)`` → :class:`PlateSolution`.

With no camera, a scale-invariant first stage (:mod:`gyrostar.starid.patterns`: four-star
edge-ratio patterns over the field range) proposes a focal length, k1 and attitude; the
existing Pyramid search, run with that camera, then decides (its verification, per-star and
absent-star checks and its false-match bound ``p_false``), and must agree with the proposal
(within ``AGREE_PX`` px at the sensor's corner). ``p_false`` reported is Pyramid's bound
times the number of proposals verified (a union bound). Last, the focal length and k1 are
fitted by least squares to Pyramid's matched stars (:mod:`gyrostar.starid.plate_fit`).

Conventions (those of :mod:`gyrostar.attitude` and :mod:`gyrostar.camera`): pixel
``xy = [col, row]``, pixel centres at integers; camera frame +x along increasing column,
+y along increasing row, +z the boresight; ``q_icrs_to_camera = [x, y, z, w]`` maps ICRS
vectors to the camera frame. ``ra_deg, dec_deg``: the boresight (+z). ``roll_deg`` (0–360°): the angle ψ of
:func:`gyrostar.attitude.quat_from_boresight` — at ψ = 0 image up (−y, towards row 0) points
to celestial north and +x (increasing column) to the west (the sky seen from inside: east to
the left of north); at ψ north lies on the image ψ from image up (−y) towards −x
(counter-clockwise on a displayed image, row 0 at the top).
``quat_from_boresight(ra, dec, roll)`` rebuilds ``q`` exactly.
``fov_deg``: horizontal, the angle between the directions seen at the sensor's left and
right edges on the principal point's row, from the radial model ``u = cx + f·xn·(1 + k1 r²)``
whose ``focal_length_px`` and ``k1`` are fitted per image (with a known camera: its own).
A pinhole-only solver (tetra3rs's ``solve_from_centroids``) absorbs k1 into its scale, which
then depends on where the image's stars lie.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..attitude import quat_to_dcm
from ..camera import CameraModel
from ..errors import ConfigError
from .plate_fit import fit_plate, fov_x_deg, pixel_residuals

FAST_PER_FIELD = 10       # navigation stars per field of Pyramid's first (thinned) tier
DEFAULT_FOV_RANGE = (5.0, 30.0)
SIGMA_PX_UNKNOWN = 1.0    # centroid + model σ (px) assumed for a camera solved from the sky
AGREE_PX = 5.0            # Pyramid's attitude must agree with the pattern proposal this well
MAX_PROPOSALS = 6         # proposals handed to Pyramid before "not solved"
PATTERN_SPOTS = 12        # brightest spots whose four-spot combinations are tried
LABEL_SPOTS = 40          # brightest spots labelled when a proposal is checked
RANGE_MARGIN = 1.03       # × the focal-length range searched (its ends included)
MIN_PROPOSAL_STARS = 7    # labelled stars a proposal needs before Pyramid sees it
PIXEL_PITCH_M = 1e-5      # nominal pitch of a camera known only in pixels (scales focal_length_m)


def auto_mag_limit(fov_deg: float) -> float:
    """Navigation-star limit (V) for a field of ``fov_deg`` (°, horizontal): ~7.5 at 11°,
    keeping the stars per field about constant (N(<V) grows ~×2.8 per mag), within
    [5.5, 8.0]."""
    return float(np.clip(7.5 - 4.4 * math.log10(max(fov_deg, 0.1) / 11.4), 5.5, 8.0))


def camera_diagonal_deg(camera) -> float:
    return 2.0 * math.degrees(math.atan(0.5 * math.hypot(camera.width_px, camera.height_px)
                                        / camera.focal_length_px))


def build_pyramid(camera, catalog: str = "hip2", mag_limit: float = 7.5, *, index=None, per_field: int = 0,
                  fast_per_field: int = FAST_PER_FIELD, label_depth_mag: float = 0.0, sigma_px: float = 0.5,
                  sigma_mag: float = 0.0, p_false_max: float = 1e-6, faint_catalog=None, max_sep_deg=None,
                  absent_max: int = 0):
    """The lost-in-space Pyramid for ``camera`` (:class:`gyrostar.camera.CameraModel`).

    ``index``: a :class:`gyrostar.starid.index.StarIndex` to use (None: ``catalog`` to
    ``mag_limit``, pairs to ``max_sep_deg`` (default the diagonal + 0.01°), ``per_field``
    navigation stars per field (0: all), stars ``label_depth_mag`` fainter label spots);
    ``fast_per_field``: the thinned first tier's stars per field (0: none; only with an
    unthinned index); ``faint_catalog``: the catalog whose stars the index leaves out are
    checked against labels (None: ``catalog`` to the index limit + label depth +
    ``gyrostar.starid.faint.DEPTH_MAG``). ``sigma_px``, ``sigma_mag``, ``p_false_max``,
    ``absent_max``: as :class:`gyrostar.starid.pyramid.Pyramid`."""
    from ..catalog import deepest_limit, load_catalog
    from .faint import DEPTH_MAG, faint_stars
    from .index import load_index
    from .pyramid import Pyramid

    sep = round(camera_diagonal_deg(camera) + 0.01, 3) if max_sep_deg is None else float(max_sep_deg)
    fast = None
    given = index is not None
    if not given:
        index = load_index(catalog, mag_limit, sep, per_field, label_depth_mag=label_depth_mag)
        if per_field == 0 and fast_per_field > 0:
            fast = load_index(catalog, mag_limit, sep, fast_per_field, label_depth_mag=label_depth_mag)
    if faint_catalog is None:
        base = index.mag_limit if given else mag_limit
        faint_catalog = load_catalog(index.catalog, deepest_limit(index.catalog, base + label_depth_mag + DEPTH_MAG))
    return Pyramid(index, camera, sigma_px=sigma_px, fast_index=fast, sigma_mag=sigma_mag,
                   faint=faint_stars(faint_catalog, index), p_false_max=p_false_max, absent_max=absent_max)


@dataclasses.dataclass(frozen=True)
class PlateSolution:
    """One image's solution (conventions in the module docstring).

    ``solved``: an attitude verified by Pyramid within ``p_false_max``; ``status``: "ok" or
    why not; ``match`` (n,): catalog id per spot or -1; ``residual_px`` (n, 2): observed
    minus predicted [col, row] px (NaN unmatched); ``residual_arcsec_rms``: RMS of the
    matched stars' residuals; ``p_false``: expected false matches of the search (union bound);
    ``solve_ms``: wall time of ``solve``."""

    solved: bool
    status: str
    q_icrs_to_camera: np.ndarray
    ra_deg: float
    dec_deg: float
    roll_deg: float
    fov_deg: float
    focal_length_px: float
    k1: float
    cx_px: float
    cy_px: float
    match: np.ndarray
    residual_px: np.ndarray
    residual_arcsec_rms: float
    stars_matched: int
    p_false: float
    solve_ms: float

    @staticmethod
    def not_solved(status: str, n: int, cx: float, cy: float, p_false: float, t0: float) -> PlateSolution:
        nan = float("nan")
        return PlateSolution(False, status, np.full(4, nan), nan, nan, nan, nan, nan, nan, cx, cy,
                             np.full(n, -1, dtype=np.int64), np.full((n, 2), nan), nan, 0, float(p_false),
                             (time.perf_counter() - t0) * 1e3)


def boresight_radec_roll(q) -> tuple[float, float, float]:
    """(ra, dec, roll) in degrees of attitude ``q`` (ICRS → camera): roll as
    :func:`gyrostar.attitude.quat_from_boresight`."""
    a = quat_to_dcm(np.asarray(q, dtype=np.float64))
    x, z = a[0], a[2]
    ra = math.atan2(z[1], z[0]) % (2.0 * math.pi)
    dec = math.asin(max(-1.0, min(1.0, z[2])))
    north = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    y0 = -north
    x0 = np.cross(y0, z)
    roll = math.atan2(float(x @ y0), float(x @ x0))
    return math.degrees(ra), math.degrees(dec), math.degrees(roll) % 360.0


class LostInSpace:
    """Plate solver over a catalog: a known camera, or a sensor whose focal length is sought
    in ``fov_range_deg`` (horizontal, °). Build with :meth:`for_camera` or :meth:`for_sensor`.

    ``absent_max`` (Pyramid's absent-star check) is off by default (-1): images from the
    ground lose stars behind trees, roofs and clouds, so a missing star is no evidence
    against a solution there; the false-match bound and the verification decide."""

    def __init__(self, width_px: int, height_px: int, *, camera=None, fov_range_deg=DEFAULT_FOV_RANGE,
                 mag_limit=None, catalog: str = "hip2", sigma_px: float | None = None, p_false_max: float = 1e-6,
                 absent_max: int = -1, quiet: bool = False):
        if int(width_px) != width_px or int(height_px) != height_px or width_px < 16 or height_px < 16:
            raise ConfigError(f"sensor size must be whole pixels ≥ 16, got {width_px!r} × {height_px!r}")
        lo, hi = (float(v) for v in fov_range_deg)
        if not (math.isfinite(lo) and math.isfinite(hi) and 1.0 <= lo <= hi <= 45.0):
            raise ConfigError(f"field-of-view range must satisfy 1 ≤ min ≤ max ≤ 45°, got {lo:g}, {hi:g}")
        if mag_limit is not None and not (math.isfinite(mag_limit) and 2.0 <= mag_limit <= 10.0):
            raise ConfigError(f"mag limit must be in [2, 10], got {mag_limit!r}")
        self.width_px, self.height_px = int(width_px), int(height_px)
        self.camera = camera
        self.fov_range_deg = (lo, hi)
        self.mag_limit = mag_limit
        self.catalog = catalog
        self.p_false_max = float(p_false_max)
        self.sigma_px = float(sigma_px if sigma_px is not None else (0.5 if camera is not None else SIGMA_PX_UNKNOWN))
        self.absent_max = int(absent_max)
        self.quiet = quiet
        self._pyramids: dict = {}
        self._patterns = None
        if camera is not None:
            self._pyramid_for(camera)       # built now: a solve then costs only the search

    # -------------------------------------------------------------- builders
    @classmethod
    def for_camera(cls, camera, mag_limit=None, catalog: str = "hip2", **kw) -> LostInSpace:
        """Solver for a camera of known intrinsics (:class:`gyrostar.camera.CameraModel`);
        ``mag_limit`` None: :func:`auto_mag_limit` of its field."""
        return cls(camera.width_px, camera.height_px, camera=camera, mag_limit=mag_limit, catalog=catalog, **kw)

    @classmethod
    def for_sensor(cls, width_px: int, height_px: int, fov_range_deg=DEFAULT_FOV_RANGE, mag_limit=None,
                   catalog: str = "hip2", **kw) -> LostInSpace:
        """Solver for a ``width_px`` × ``height_px`` sensor of unknown focal length, its
        horizontal field within ``fov_range_deg``; the pattern database is built (and cached)
        on the first solve, or by :meth:`prepare`."""
        return cls(width_px, height_px, fov_range_deg=fov_range_deg, mag_limit=mag_limit, catalog=catalog, **kw)

    def prepare(self) -> LostInSpace:
        """Load (or build, printing progress) the pattern database now."""
        if self.camera is None:
            self._pattern_db()
        return self

    # -------------------------------------------------------------- pieces
    def _pattern_db(self):
        from .patterns import load_pattern_database

        if self._patterns is None:
            lo, hi = self.fov_range_deg
            mag = self.mag_limit if self.mag_limit is not None else auto_mag_limit(lo)
            self._patterns = load_pattern_database(self.catalog, mag, (lo, hi), quiet=self.quiet)
        return self._patterns

    def _pyramid_for(self, camera):
        """A Pyramid for ``camera``; indexes are shared by cameras whose diagonal rounds up to
        the same 3 % step (so a refitted focal length reuses them)."""
        diag = camera_diagonal_deg(camera)
        sep = round(1.03 ** math.ceil(math.log(diag + 0.01) / math.log(1.03)), 3)
        mag = self.mag_limit if self.mag_limit is not None else round(auto_mag_limit(camera.fov_x_deg) * 4) / 4
        key = (sep, mag)
        if key not in self._pyramids:
            proto = build_pyramid(camera, self.catalog, mag, sigma_px=self.sigma_px, p_false_max=self.p_false_max,
                                  max_sep_deg=sep, absent_max=self.absent_max)
            self._pyramids[key] = proto
        proto = self._pyramids[key]
        return proto if proto.camera == camera else proto.with_camera(camera)

    def _camera(self, f, k1, cx, cy):
        return CameraModel(f * PIXEL_PITCH_M, PIXEL_PITCH_M, self.width_px, self.height_px, cx, cy, k1)

    # -------------------------------------------------------------- solve
    def solve(self, xy, mag=None, fov_hint_deg=None) -> PlateSolution:
        """Solve centroids ``xy`` (n, 2) [col, row] px, brightest first; ``mag`` (n,) their
        calibrated V or None; ``fov_hint_deg`` an optional horizontal field (°) that narrows
        the search to ±5 % of it (ignored with a known camera)."""
        t0 = time.perf_counter()
        pts = np.asarray(xy, dtype=np.float64)
        pts = np.ascontiguousarray(pts.reshape(-1, 2) if pts.size else np.empty((0, 2)))
        if not np.all(np.isfinite(pts)):
            raise ConfigError("centroids must be finite pixel coordinates")
        if mag is not None:
            mag = np.ascontiguousarray(mag, dtype=np.float64).reshape(-1)
            if mag.shape[0] != pts.shape[0]:
                raise ConfigError(f"{mag.shape[0]} magnitudes for {pts.shape[0]} centroids")
        if fov_hint_deg is not None and not (math.isfinite(fov_hint_deg) and 0.5 <= fov_hint_deg <= 60.0):
            raise ConfigError(f"field-of-view hint must be in [0.5, 60]°, got {fov_hint_deg!r}")
        n = pts.shape[0]
        if self.camera is not None:
            cam = self.camera
            return self._verified(pts, mag, cam, None, 1, t0)
        cx, cy = (self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0
        if n < 4:
            return PlateSolution.not_solved("fewer than 4 spots", n, cx, cy, math.nan, t0)
        return self._solve_patterns(pts, mag, fov_hint_deg, t0)

    def _f_range(self, fov_hint_deg):
        w = self.width_px
        lo, hi = self.fov_range_deg
        if fov_hint_deg is not None:
            lo, hi = fov_hint_deg / 1.05, fov_hint_deg * 1.05
        # a field at an end of the range is found: its focal length may come out a little beyond
        f_min = 0.5 * w / math.tan(math.radians(hi) / 2.0) / RANGE_MARGIN
        f_max = 0.5 * w / math.tan(math.radians(lo) / 2.0) * RANGE_MARGIN
        return f_min, f_max

    def _f_guesses(self, f_min, f_max) -> np.ndarray:
        """Focal lengths the image patterns are computed with: the edge ratios of a pattern at
        off-axis angle α change by ~tan²α·δf/f; steps keep that below a third of the
        tolerance, from the widest field down to where one guess covers the rest."""
        from .patterns import MAX_ERROR

        half_diag = 0.5 * math.hypot(self.width_px, self.height_px)
        out = []
        f = f_min
        while True:
            u2 = (half_diag / f) ** 2
            step = 1.0 + 2.0 * (MAX_ERROR / 2.0) / max(u2, 1e-9)
            fg = min(f * math.sqrt(step), f_max)
            out.append(fg)
            f = f * step
            if f >= f_max:
                break
        return np.array(out)

    def _solve_patterns(self, pts, mag, fov_hint_deg, t0) -> PlateSolution:
        from .patterns import MAX_ERROR, match_patterns

        db = self._pattern_db()
        n = pts.shape[0]
        cx, cy = (self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0
        f_min, f_max = self._f_range(fov_hint_deg)
        guesses = self._f_guesses(f_min, f_max)
        n_cat = len(db.vmag)
        start = 0
        proposals = 0
        last = "no four-star pattern of the brightest spots matches the catalog"
        while proposals < MAX_PROPOSALS:
            nxt, q, f, k1, match, nm, tried, _ = match_patterns(
                pts, self.width_px, self.height_px, cx, cy, guesses, f_min, f_max, PATTERN_SPOTS, LABEL_SPOTS,
                db.quads, db.ratios, db.table, db.bin_w, MAX_ERROR, db.vectors, n_cat, db.vox_vec, db.vox_stars,
                db.vox_start, db.vox_h, db.vox_g, 2.0 * self.sigma_px + 1.0, MIN_PROPOSAL_STARS, start, 100000)
            if nxt < 0 or nm == 0:
                break
            start = nxt
            proposals += 1
            cam = self._camera(f, k1, cx, cy)
            sol = self._verified(pts, mag, cam, q, proposals, t0)
            if sol.solved:
                return sol
            last = f"a pattern proposal was rejected: {sol.status}"
        return PlateSolution.not_solved(last, n, cx, cy, math.nan, t0)

    def _verified(self, pts, mag, cam, q_prop, proposals, t0) -> PlateSolution:
        """Pyramid on ``cam``; agreement with the proposal ``q_prop`` (None: none); the fit."""
        n = pts.shape[0]
        pyr = self._pyramid_for(cam)
        res = pyr.identify(pts, mag)
        p_false = float(res.p_false) * proposals
        if not res.ok:
            return PlateSolution.not_solved(res.status, n, cam.cx_px, cam.cy_px, p_false, t0)
        if p_false > self.p_false_max:
            return PlateSolution.not_solved(f"p_false {p_false:.1e} over {proposals} proposals exceeds "
                                            f"{self.p_false_max:.0e}", n, cam.cx_px, cam.cy_px, p_false, t0)
        q = np.asarray(res.q, dtype=np.float64)
        if q_prop is not None:
            # the rotation between them, in pixels across the field (× f: an upper bound)
            da = quat_to_dcm(q) @ quat_to_dcm(q_prop).T
            ang = math.acos(max(-1.0, min(1.0, (np.trace(da) - 1.0) / 2.0)))
            if ang * cam.focal_length_px > AGREE_PX:
                return PlateSolution.not_solved("Pyramid's attitude disagrees with the pattern proposal", n,
                                                cam.cx_px, cam.cy_px, p_false, t0)
        got = res.index >= 0
        ref = np.ascontiguousarray(pyr.index.vectors[res.index[got]])
        uvm = np.ascontiguousarray(pts[got])
        f, k1, cx, cy = cam.focal_length_px, cam.k1, cam.cx_px, cam.cy_px
        if self.camera is None and uvm.shape[0] >= 4:
            q, f, k1, cx, cy, _ = fit_plate(uvm, ref, q, f, k1, cx, cy, uvm.shape[0] >= 10, False, 20)
        fov = fov_x_deg(f, cam.width_px, cx, k1)
        resid = np.full((n, 2), np.nan)
        if self.camera is None:
            resid[got] = pixel_residuals(uvm, ref, q, f, k1, cx, cy)
        else:
            pred, _ = cam.project(ref @ quat_to_dcm(q).T)
            resid[got] = uvm - pred
        rms_px = float(np.sqrt(np.nanmean(np.sum(resid[got] ** 2, axis=1)))) if got.any() else math.nan
        ra, dec, roll = boresight_radec_roll(q)
        return PlateSolution(True, "ok", q, ra, dec, roll, fov, float(f), float(k1),
                             float(cx), float(cy), np.asarray(res.ids, dtype=np.int64), resid,
                             rms_px / f * 206264.806, int(got.sum()), p_false, (time.perf_counter() - t0) * 1e3)
