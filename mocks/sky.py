"""The simulated sky seen through a camera: the exposure API that emulators and evaluations call.

``Sky(catalog, preset, seed)`` binds a :class:`~gyrostar.catalog.StarCatalog`, a simulator
preset (:mod:`gyrostar.mocks.sim_preset`: camera, optics, detector) and a sensor seed
(fixed-pattern noise). One exposure is described by

* ``q_start`` — attitude (ICRS → body, [x, y, z, w]) at exposure start;
* ``omega`` — body rate over the exposure (rad/s, body axes): (3,) constant, or (m, 3)
  piecewise constant over m equal segments (e.g. the 400 Hz true rates), or
  ``quats`` — (m + 1, 4) attitudes at equal times from start to end instead (turned into
  the piecewise-constant rates that join them exactly);
* ``frame`` — frame counter (the noise of frame k is reproducible from (seed, k)).

Entry points:

* ``render_frame(q_start, omega, frame=0, noise=True) -> (image uint16 (H, W), truth)``
* ``render_windows(spans, q_start, omega, frame=0, noise=True) -> (pixels uint16 (m,), truth)``
  with ``spans`` int32 (n, 4) ``[window_id, row, col_start, col_stop)`` sorted by window
  then row; the pixels of every span concatenated in order, identical to
  ``image[row, col_start:col_stop]`` of ``render_frame`` at the same seed and frame.
* ``expose(q_start, omega) -> Exposure``: the geometry only (star paths and truth), which
  both renderers use, for callers that render several readouts of one exposure.

``environment`` (:class:`gyrostar.mocks.environment.Environment`, default None) adds the
orbit's hazards — stray light, the Earth and the Moon, particle hits, hot pixels, the
temperature's dark current and focal length — to the exposures given their scenario time
``t_s`` (s, exposure start; keyword of every entry point). Without an environment, or
without ``t_s``, the renderers run exactly as before.

``false_spots`` (k, 3) ``[col, row, vmag]`` adds stray-light glints: point sources fixed on
the sensor (they do not move with the attitude), rendered like stars and listed after the
stars in the truth with ids ``-1 … -k``.

``truth`` is a :class:`StarTruth`: per star near the field (catalog order, brightest
first) its exposure-averaged true centroid ``uv`` [col, row] (px), ``vmag``, catalog
``ids``, signal ``electrons``, and ``in_field`` (the averaged centroid lies on the sensor),
plus the attitude at start, mid and end of the exposure.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from gyrostar.attitude import quat_conj, quat_mult, quat_to_dcm
from gyrostar.camera import P_F
from gyrostar.catalog import StarCatalog
from gyrostar.core.windows import span_pixel_count
from gyrostar.errors import ConfigError
from numba import njit

from . import pixel_noise, render
from .sim_preset import SimPreset, load_preset
from .trajectory import piecewise_attitudes


@dataclasses.dataclass(frozen=True)
class StarTruth:
    """Truth for one exposure (arrays over the stars near the field, catalog order)."""

    ids: np.ndarray          # int64 (n,)
    vmag: np.ndarray         # float64 (n,)
    uv: np.ndarray           # float64 (n, 2): exposure-averaged true centroid [col, row] px
    in_field: np.ndarray     # bool (n,)
    electrons: np.ndarray    # float64 (n,): signal electrons collected in the exposure
    q_start: np.ndarray      # (4,) ICRS→body at exposure start
    q_mid: np.ndarray        # (4,) at mid-exposure
    q_end: np.ndarray        # (4,) at exposure end
    exposure_s: float


@dataclasses.dataclass(frozen=True)
class Exposure:
    """Geometry of one exposure: star paths at sub-step midpoints and pixel boxes."""

    paths: np.ndarray        # (n, n_sub, 2) [col, row] px
    boxes: np.ndarray        # int64 (n, 4) [r0, r1, c0, c1)
    truth: StarTruth
    env: object = None       # the exposure's ExposureEnv (gyrostar.mocks.environment), or None


def _as_rates(q_start, omega, quats, exposure_s) -> np.ndarray:
    if quats is not None:
        if omega is not None:
            raise ConfigError("give the exposure's omega or its quats, not both")
        qs = np.asarray(quats, dtype=np.float64)
        if qs.ndim != 2 or qs.shape[1] != 4 or qs.shape[0] < 2:
            raise ConfigError(f"quats must be (m+1, 4) with m >= 1, got {qs.shape}")
        if not np.allclose(qs[0], q_start) and not np.allclose(qs[0], -q_start):
            raise ConfigError("quats[0] must equal q_start")
        m = qs.shape[0] - 1
        dt = exposure_s / m
        rates = np.empty((m, 3))
        for i in range(m):
            dq = quat_mult(qs[i + 1], quat_conj(qs[i]))
            if dq[3] < 0:
                dq = -dq
            ang = 2.0 * math.atan2(np.linalg.norm(dq[:3]), dq[3])
            n = np.linalg.norm(dq[:3])
            rates[i] = dq[:3] / n * ang / dt if n > 0 else 0.0
        return rates
    om = np.zeros(3) if omega is None else np.asarray(omega, dtype=np.float64)
    return om


class Sky:
    """A catalog seen through a simulator preset; see the module docstring."""

    def __init__(self, catalog: StarCatalog, preset: SimPreset | str = "xing2012", seed: int = 0,
                 false_spots=None, environment=None):
        self.catalog = catalog
        self.preset = load_preset(preset) if isinstance(preset, str) else preset
        self.camera = self.preset.camera
        self.params = self.camera.as_array()
        self.det = self.preset.detector_array()
        self.seed = int(seed) & 0x7FFFFFFFFFFFFFFF
        self.electrons = np.asarray(self.preset.star_electrons(catalog.vmag), dtype=np.float64)
        self._fpn = None
        self._span_maps = None   # the four maps interleaved for the span digitiser, built on first use
        self._sig_pool: list[np.ndarray] = []
        self._cand = None  # (boresight, radius, catalog indexes) of the last wide selection
        f = self.camera.focal_length_px
        half_diag = math.hypot(self.camera.width_px, self.camera.height_px) / 2.0 + 20.0
        self._field_radius = math.atan(half_diag / f)
        # stray-light glints: point sources fixed on the sensor, [col, row, V magnitude] each
        spots = np.zeros((0, 3)) if false_spots is None else np.asarray(false_spots, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(spots).all():
            raise ConfigError("false_spots must be finite [col, row, vmag] triples")
        self.false_spots = spots
        self._spot_electrons = np.asarray(self.preset.star_electrons(spots[:, 2]), dtype=np.float64).reshape(-1)
        self.environment = environment

    def with_exposure(self, exposure_s: float) -> Sky:
        """The same sky (catalog, seed, glints, environment) through the preset at another exposure (s)."""
        return Sky(self.catalog, self.preset.with_exposure(exposure_s), seed=self.seed,
                   false_spots=self.false_spots if len(self.false_spots) else None, environment=self.environment)

    def _env_at(self, t_s, q_start, rates, frame):
        """``(ExposureEnv or None, camera params)`` of an exposure from scenario time ``t_s``:
        the environment evaluated at the mid-exposure attitude, and the camera array with its
        focal length at the exposure's temperature."""
        if self.environment is None or t_s is None:
            return None, self.params
        t_exp = self.preset.detector.exposure_s
        q_mid = piecewise_attitudes(q_start, rates, t_exp, np.array([0.5 * t_exp]))[0]
        env = self.environment.exposure(float(t_s), q_mid, int(frame), self.preset, self.params)
        if env.focal_scale == 1.0:
            return env, self.params
        params = self.params.copy()
        params[P_F] *= env.focal_scale
        return env, params

    def _env_electrons(self, env, electrons, vecs):
        """Star electrons with the stars behind the Earth or the Moon put out."""
        if env is None or not len(env.hidden_dirs):
            return electrons
        from .environment import visible_mask

        return np.where(visible_mask(vecs, env.hidden_dirs), electrons, 0.0)

    @property
    def fixed_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(PRNU gain, dark electrons per exposure), float32 (H, W): same for every frame."""
        if self._fpn is None:
            gain, dark = pixel_noise.fixed_pattern(self.seed, self.camera.height_px, self.camera.width_px, self.det)
            self._fpn = (gain, dark) + pixel_noise.background_maps(gain, dark, self.det)
        return self._fpn[0], self._fpn[1]

    def _noise_maps(self):
        self.fixed_pattern  # noqa: B018 - builds the maps on first use
        return self._fpn

    def expose(self, q_start, omega=None, quats=None, t_s=None, frame: int = 0) -> Exposure:
        """Star paths and truth for one exposure (no pixels); ``t_s``, ``frame``: the environment's."""
        q_start, rates2, n_sub, w_max = self._exposure_setup(q_start, omega, quats)
        env, params = self._env_at(t_s, q_start, rates2, frame)
        t_exp = self.preset.detector.exposure_s
        # one exact attitude grid: 4·n_sub intervals; sub-step midpoints are every 4th from 2
        n_grid = 4 * n_sub
        qs = piecewise_attitudes(q_start, rates2, t_exp, np.arange(n_grid + 1) * (t_exp / n_grid))
        q_mid, q_fin = qs[2 * n_sub].copy(), qs[-1].copy()
        # stars near the field: within the field radius + the rotation of the exposure
        bore = quat_to_dcm(q_mid)[2]
        reach = self._field_radius + w_max * t_exp
        sel = self.near(bore, reach)
        vecs = np.ascontiguousarray(self.catalog.vectors[sel])
        grid_paths = render.star_paths(params, vecs, qs)
        paths = np.ascontiguousarray(grid_paths[:, 2::4])
        boxes = render.star_boxes(paths, self.preset.optics.psf_sigma_px, self.camera.width_px,
                                  self.camera.height_px)
        uv = _simpson_mean(grid_paths)
        ids, vmag, electrons = self.catalog.ids[sel], self.catalog.vmag[sel], self.electrons[sel]
        electrons = self._env_electrons(env, electrons, vecs)
        k = len(self.false_spots)
        if k:
            paths, boxes, electrons = self._add_glints(paths, boxes, electrons)
            uv = np.concatenate([uv, self.false_spots[:, :2]])
            ids = np.concatenate([ids, -1 - np.arange(k, dtype=ids.dtype)])
            vmag = np.concatenate([vmag, self.false_spots[:, 2]])
        w, h = self.camera.width_px, self.camera.height_px
        in_field = (uv[:, 0] >= -0.5) & (uv[:, 0] < w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < h - 0.5)
        truth = StarTruth(ids, vmag, uv, in_field, electrons, q_start.copy(), q_mid, q_fin, t_exp)
        return Exposure(paths, boxes, truth, env)

    def _exposure_setup(self, q_start, omega, quats):
        """``(q_start, rates (m, 3), n_sub, w_max)`` of one exposure: the validated start
        attitude, its piecewise-constant rates (rad/s), the sub-step count that keeps
        ≤ ``render.MAX_STEP_PX`` between path samples and the largest rate (rad/s)."""
        q_start = np.asarray(q_start, dtype=np.float64)
        if q_start.shape != (4,) or not _is_unit_quat(q_start):
            raise ConfigError("q_start must be a unit quaternion [x, y, z, w]")
        t_exp = self.preset.detector.exposure_s
        rates = np.ascontiguousarray(np.atleast_2d(_as_rates(q_start, omega, quats, t_exp)), dtype=np.float64)
        n_sub, w_max = _substeps(rates, t_exp, self.camera.focal_length_px,
                                 math.hypot(self.camera.width_px, self.camera.height_px) / 2.0)
        return q_start, rates, n_sub, w_max

    def window_pixels(self, spans, q_start, omega=None, frame: int = 0, noise: bool = True, t_s=None) -> np.ndarray:
        """Span pixels (uint16 (m,) ADU in span order) of one exposure: the pixels of
        :meth:`render_windows`, to the bit, without its truth (the star paths are taken at
        the sub-steps only; the emulated heads' per-frame path)."""
        spans = render.check_spans(spans, self.camera.width_px, self.camera.height_px)
        q_start, rates, n_sub, w_max = self._exposure_setup(q_start, omega, None)
        env, params = self._env_at(t_s, q_start, rates, frame)
        t_exp = self.preset.detector.exposure_s
        qs, bore = _substep_attitudes(q_start, rates, t_exp, n_sub)
        reach = self._field_radius + w_max * t_exp
        sel, vecs = _within(*self._candidates(bore, reach), bore, math.cos(min(reach, math.pi)))
        paths, boxes = render.star_paths_boxes(params, vecs, qs, self.preset.optics.psf_sigma_px,
                                               self.camera.width_px, self.camera.height_px)
        electrons = self._env_electrons(env, self.electrons[sel], vecs)
        if len(self.false_spots):
            paths, boxes, electrons = self._add_glints(paths, boxes, electrons)
        return self._readout(paths, electrons, boxes, spans, frame, noise, env)

    def _add_glints(self, paths, boxes, electrons):
        """``(paths, boxes, electrons)`` with the stray-light glints after the stars: they do
        not move with the attitude (the same position at every sub-step)."""
        spot_paths = np.repeat(self.false_spots[:, None, :2], paths.shape[1], axis=1)
        return (np.ascontiguousarray(np.concatenate([paths, spot_paths])),
                np.concatenate([boxes, render.star_boxes(np.ascontiguousarray(spot_paths),
                                                         self.preset.optics.psf_sigma_px,
                                                         self.camera.width_px, self.camera.height_px)]),
                np.concatenate([electrons, self._spot_electrons]))

    def near(self, bore: np.ndarray, reach: float) -> np.ndarray:
        """Catalog indexes (ascending) within ``reach`` rad of ``bore``: the test of
        :meth:`window_pixels` (``_within``), so both renderers see the same stars."""
        return _within(*self._candidates(bore, reach), bore, math.cos(min(reach, math.pi)))[0]

    def _candidates(self, bore: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """``(catalog indexes (ascending), their vectors)`` of a cone 2° wider than ``reach``
        about a boresight near ``bore``: kept while later boresights stay inside it
        (tracking), so only they are tested, not the whole catalog."""
        cand = self._cand
        if cand is not None:
            c_bore, c_radius, c_idx, c_vec = cand
            off = math.acos(max(-1.0, min(1.0, float(c_bore @ bore))))
            if off + reach <= c_radius:
                return c_idx, c_vec
        radius = min(reach + math.radians(2.0), math.pi)
        c_idx = np.flatnonzero(self.catalog.vectors @ bore > math.cos(radius))
        c_vec = np.ascontiguousarray(self.catalog.vectors[c_idx])     # the candidates' vectors, kept
        self._cand = (bore.copy(), radius, c_idx, c_vec)
        return c_idx, c_vec

    def signal_frame(self, exp: Exposure) -> np.ndarray:
        """Mean photo-signal of the stars (e⁻) over the whole sensor, float64 (H, W)."""
        sig = np.zeros((self.camera.height_px, self.camera.width_px))
        render.add_stars_full(sig, exp.paths, exp.truth.electrons, exp.boxes, self.preset.optics.psf_sigma_px)
        return sig

    def render_frame(self, q_start, omega=None, frame: int = 0, noise: bool = True, quats=None, t_s=None):
        """Whole frame: (uint16 (H, W) ADU, StarTruth)."""
        exp = self.expose(q_start, omega, quats, t_s=t_s, frame=frame)
        env = exp.env
        gain, dark, lam_bg, exp_bg = self._noise_maps()
        # zero-filled (H, W) buffers reused between frames, cleared box by box after use;
        # a pool (list.pop/append are atomic) so threads sharing one Sky never share a buffer
        try:
            sig = self._sig_pool.pop()
        except IndexError:
            sig = np.zeros((self.camera.height_px, self.camera.width_px))
        try:
            render.add_stars_full(sig, exp.paths, exp.truth.electrons, exp.boxes, self.preset.optics.psf_sigma_px)
            if env is not None:
                from .environment import add_env_full

                add_env_full(sig, gain, dark, env.grid, env.params, env.deposits)
                lit = np.ones(self.camera.height_px, np.bool_)
            else:
                lit = render.lit_rows(exp.boxes, self.camera.height_px)
            img = pixel_noise.digitise_frame(sig, gain, dark, lam_bg, exp_bg, self.seed, int(frame), self.det,
                                             bool(noise), pixel_noise.normal_table(), lit)
        finally:
            if env is not None:
                sig[:] = 0.0
            else:
                render.clear_boxes(sig, exp.boxes)
            self._sig_pool.append(sig)
        return img, exp.truth

    def render_windows(self, spans, q_start, omega=None, frame: int = 0, noise: bool = True, quats=None, t_s=None):
        """Span pixels: (uint16 (m,) ADU in span order, StarTruth)."""
        spans = render.check_spans(spans, self.camera.width_px, self.camera.height_px)
        exp = self.expose(q_start, omega, quats, t_s=t_s, frame=frame)
        return self._readout(exp.paths, exp.truth.electrons, exp.boxes, spans, frame, noise, exp.env), exp.truth

    def readout_windows(self, exp: Exposure, spans: np.ndarray, frame: int = 0, noise: bool = True) -> np.ndarray:
        """Span pixels (uint16, span order) of an already computed exposure; ``spans`` are validated."""
        return self._readout(exp.paths, exp.truth.electrons, exp.boxes,
                             render.check_spans(spans, self.camera.width_px, self.camera.height_px), frame, noise,
                             exp.env)

    def _readout(self, paths, electrons, boxes, spans: np.ndarray, frame: int, noise: bool, env=None) -> np.ndarray:
        """ADU of the (validated) ``spans`` under stars on ``paths`` with ``electrons`` and ``boxes``
        (and the exposure's environment ``env``, if any)."""
        sig = np.zeros(span_pixel_count(spans))
        render.add_stars_spans(sig, spans, paths, electrons, boxes, self.preset.optics.psf_sigma_px)
        if self._span_maps is None:
            self._span_maps = pixel_noise.span_maps(*self._noise_maps())
        if env is not None:
            from .environment import add_env_spans

            add_env_spans(sig, spans, self._span_maps, env.grid, env.params, env.deposits)
        return pixel_noise.digitise_spans(sig, spans, self._span_maps, self.seed, int(frame), self.det,
                                          bool(noise), pixel_noise.normal_table())


@njit(cache=True)
def _is_unit_quat(q) -> bool:
    n2 = 0.0
    for i in range(4):
        if not math.isfinite(q[i]):
            return False
        n2 += q[i] * q[i]
    return abs(math.sqrt(n2) - 1.0) <= 1e-6


@njit(cache=True)
def _substeps(rates, t_exp, f, half):
    """``(n_sub, w_max)``: path samples of an exposure of ``t_exp`` s under ``rates`` (m, 3)
    rad/s — the image moves at most |ω|·(F + r²/F) px/s at radius r ≤ ``half`` px from the
    principal point (focal length F px) — and the largest rate (rad/s)."""
    w_max = 0.0
    for i in range(rates.shape[0]):
        w_max = max(w_max, math.sqrt(rates[i, 0] * rates[i, 0] + rates[i, 1] * rates[i, 1] + rates[i, 2] * rates[i, 2]))
    path_px = w_max * t_exp * (f + half * half / f)
    n_sub = int(min(render.MAX_SUBSTEPS, max(1, math.ceil(path_px / render.MAX_STEP_PX))))
    return n_sub, w_max


@njit(cache=True, nogil=True)
def _within(c_idx, c_vec, bore, cos_reach):
    """``(catalog indexes (ascending), unit vectors (k, 3))`` of the candidates ``c_idx`` with
    vectors ``c_vec`` closer than the angle of ``cos_reach`` to ``bore``."""
    keep = np.empty(c_idx.shape[0], np.bool_)
    k = 0
    for i in range(c_idx.shape[0]):
        keep[i] = c_vec[i, 0] * bore[0] + c_vec[i, 1] * bore[1] + c_vec[i, 2] * bore[2] > cos_reach
        if keep[i]:
            k += 1
    idx = np.empty(k, c_idx.dtype)
    vecs = np.empty((k, 3))
    j = 0
    for i in range(c_idx.shape[0]):
        if keep[i]:
            idx[j] = c_idx[i]
            vecs[j] = c_vec[i]
            j += 1
    return idx, vecs


@njit(cache=True, nogil=True)
def _substep_attitudes(q_start, rates, t_exp, n_sub):
    """``(attitudes (n_sub, 4) at the sub-step midpoints, boresight (3,) at mid-exposure)``:
    the points 2, 6, 10 … and 2·n_sub of :meth:`Sky.expose`'s grid of 4·n_sub intervals."""
    step = t_exp / (4 * n_sub)
    times = np.empty(n_sub + 1)
    for k in range(n_sub):
        times[k] = (4 * k + 2) * step
    times[n_sub] = (2 * n_sub) * step
    qs = piecewise_attitudes(q_start, rates, t_exp, times)
    return qs[:n_sub].copy(), quat_to_dcm(qs[n_sub])[2].copy()


def _simpson_mean(paths: np.ndarray) -> np.ndarray:
    """Time average (n, 2) of positions (n, 2k + 1, 2) sampled on an even grid (composite Simpson)."""
    k = paths.shape[1]
    wts = np.ones(k)
    wts[1:-1:2] = 4.0
    wts[2:-1:2] = 2.0
    wts /= wts.sum()
    return render.weighted_mean_paths(paths, wts)
