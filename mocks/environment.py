"""The orbit environment on the sensor: Sun, Earth and Moon light, radiation and temperature.

:class:`Environment` is built from a scenario's ``[orbit]``, ``[stray_light]``, ``[moon]``,
``[radiation]`` and ``[thermal]`` tables (:mod:`gyrostar.hil.config`; every part off by
default) and handed to :class:`gyrostar.mocks.sky.Sky`. For each exposure starting at
scenario time ``t_s`` (s) it gives an :class:`ExposureEnv` that the renderers apply after the
stars and before the detector chain, in the same order for a whole frame and for any span
readout (so window pixels stay bit-identical to the frame's):

* **Stray light** (``[stray_light]``): per pixel, Σ K_src · PST(θ) over the Sun, the Moon and
  the sunlit Earth, θ the angle from the pixel's line of sight to the source (to the nearest
  point of the Earth's disk), K_src the electrons a pixel collects per unit PST from the
  source's irradiance at the aperture. PST(θ) (:func:`pst`): a lit first lens inside the
  baffle's exclusion angle (``pst_edge``·(θ_field/θ)², Harvey slope −2), the vanes' double
  scatter beyond it (``pst_exclusion``·(θ_excl/θ)^slope), joined by a logistic step in log PST
  of width ``transition_deg``. Evaluated on a 16-px grid and interpolated bilinearly (a smooth
  field; the grid is a function of the pixel only, so frame and spans agree). No Sun stray
  light in the Earth's shadow.
* **The Earth** (``[orbit]``): a pixel whose line of sight meets the Earth sees its sunlit
  surface (albedo · solar irradiance · cos z / π, z the Sun's zenith angle at the limb point
  nearest the boresight: saturating) or, on the night side, nothing; stars behind the Earth
  are hidden.
* **The Moon** (``[moon]``): a disk of angular radius asin(R_moon / d) at its topocentric
  direction, lit where the sphere faces the Sun (sub-sampled 3×3 per pixel), of uniform surface
  brightness whose total is the Moon's V magnitude at its phase angle α (Allen's Astrophysical
  Quantities: V = −12.73 + 0.026 |α| + 4·10⁻⁹ α⁴, α in deg, at 384,400 km): ~10⁷ e⁻ a pixel at
  full Moon, saturating; stars behind it are hidden.
* **Radiation** (``[radiation]``): Poisson hits per frame (flux × sensor area × exposure),
  the flux of the South Atlantic Anomaly box when the sub-satellite point is inside it; each
  hit enters at a uniform point, direction uniform in azimuth with cos θ = √U (an isotropic
  flux through a plane), deposits charge_e_per_um · depth/cos θ · (1 + w·x) electrons
  (x Moyal, the Landau approximation: x = −ln z², z normal) spread along a track of
  depth·tan θ / pitch px. Counter-based per frame: the hits of sensor frame k are a function of
  (seed, k, flux) alone. Hot pixels appear at a Poisson rate (``hot_pixels_per_hour``) and stay.
* **Temperature** (``[thermal]``): dark current × 2^((T − T_ref)/doubling) (the extra added as
  signal divided by the pixel's PRNU gain, so λ = … + factor · dark exactly) and the focal
  length × (1 + ppm·(T − T_ref)·10⁻⁶).

Everything is evaluated at mid-exposure (attitude and time); the Moon's disk is not smeared by
the body rate within an exposure.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from gyrostar.attitude import quat_to_dcm
from gyrostar.camera import P_CX, P_CY, P_F
from numba import njit

from . import pixel_noise, render
from .orbit import AU_KM, R_EARTH_KM, R_MOON_KM, CircularOrbit

V_SUN = -26.74                 # apparent V magnitude of the Sun at 1 AU
MOON_MEAN_KM = 384400.0
GRID_PX = 16                   # stray-light grid step, px
MAX_TRACK_PX = 50.0            # longest particle track (grazing hits), px
RADIATION_STREAM = 0x52414449  # "RADI": the hits' own counter stream beside the pixel noise

# the per-exposure parameter vector of the kernels
(E_CX, E_CY, E_F, E_SX, E_SY, E_SZ, E_KSUN, E_MX, E_MY, E_MZ, E_KMOON, E_MRAD, E_NX, E_NY, E_NZ, E_RHO,
 E_KEARTH, E_LEARTH, E_DU, E_DV, E_DR, E_LX, E_LY, E_LZ, E_DISK, E_HALF, E_EXCL, E_PSTEDGE, E_PSTEXCL,
 E_SLOPE, E_WIDTH, E_DARK, E_STRAY, E_EARTH, E_MOON, E_COSRHO) = range(36)
N_E = 36


@njit(cache=True, nogil=True)
def pst(theta, p):
    """Point-source transmittance at ``theta`` rad from the boresight (see the module docstring)."""
    th = max(theta, 1e-5)
    lens = p[E_PSTEDGE] * (p[E_HALF] / th) ** 2
    baffle = p[E_PSTEXCL] * (p[E_EXCL] / th) ** p[E_SLOPE]
    x = (th - p[E_EXCL]) / p[E_WIDTH]
    if x > 40.0:
        return baffle
    if x < -40.0:
        return lens
    w = 1.0 / (1.0 + math.exp(x))
    return math.exp(w * math.log(lens) + (1.0 - w) * math.log(baffle))


@njit(cache=True, nogil=True, inline="always")
def _los(u, v, p):
    """Unit line of sight (camera frame) of pixel (u = column, v = row), pinhole."""
    x = (u - p[E_CX]) / p[E_F]
    y = (v - p[E_CY]) / p[E_F]
    n = math.sqrt(x * x + y * y + 1.0)
    return x / n, y / n, 1.0 / n


@njit(cache=True, nogil=True, inline="always")
def _angle(ax, ay, az, bx, by, bz):
    c = ax * bx + ay * by + az * bz
    return math.acos(min(1.0, max(-1.0, c)))


@njit(cache=True, nogil=True)
def stray_parts(u, v, p):
    """Stray-light electrons at pixel (u, v) from the Sun, the Moon and the Earth (exact, no grid)."""
    dx, dy, dz = _los(u, v, p)
    sun = moon = earth = 0.0
    if p[E_KSUN] > 0.0:
        sun = p[E_KSUN] * pst(_angle(dx, dy, dz, p[E_SX], p[E_SY], p[E_SZ]), p)
    if p[E_KMOON] > 0.0:
        moon = p[E_KMOON] * pst(max(_angle(dx, dy, dz, p[E_MX], p[E_MY], p[E_MZ]), p[E_MRAD]), p)
    if p[E_KEARTH] > 0.0:
        earth = p[E_KEARTH] * pst(max(_angle(dx, dy, dz, p[E_NX], p[E_NY], p[E_NZ]) - p[E_RHO], 1e-4), p)
    return sun, moon, earth


@njit(cache=True, nogil=True)
def stray_at(u, v, p):
    """Stray-light electrons at pixel (u, v): the sum of :func:`stray_parts`."""
    sun, moon, earth = stray_parts(u, v, p)
    return sun + moon + earth


@njit(cache=True, nogil=True)
def stray_grid(p, width, height):
    """Stray light (e⁻) at the grid nodes (every ``GRID_PX`` px from pixel 0), float64 (gh, gw)."""
    gw = (width - 1) // GRID_PX + 2
    gh = (height - 1) // GRID_PX + 2
    g = np.empty((gh, gw))
    for j in range(gh):
        for i in range(gw):
            g[j, i] = stray_at(float(i * GRID_PX), float(j * GRID_PX), p)
    return g


@njit(cache=True, nogil=True, inline="always")
def _grid_value(g, r, c):
    j, i = r // GRID_PX, c // GRID_PX
    fy = (r - j * GRID_PX) / GRID_PX
    fx = (c - i * GRID_PX) / GRID_PX
    return ((1.0 - fy) * ((1.0 - fx) * g[j, i] + fx * g[j, i + 1])
            + fy * ((1.0 - fx) * g[j + 1, i] + fx * g[j + 1, i + 1]))


@njit(cache=True, nogil=True, inline="always")
def _disk_fraction(u, v, p):
    """Lit fraction of pixel (u, v) covered by the Moon's disk (3×3 sub-samples)."""
    du, dv, rm = u - p[E_DU], v - p[E_DV], p[E_DR]
    if du * du + dv * dv > (rm + 1.0) * (rm + 1.0):
        return 0.0
    n = 0
    for a in range(3):
        for b in range(3):
            x = (du + (a - 1) / 3.0) / rm
            y = (dv + (b - 1) / 3.0) / rm
            r2 = x * x + y * y
            if r2 < 1.0 and x * p[E_LX] + y * p[E_LY] + math.sqrt(1.0 - r2) * p[E_LZ] > 0.0:
                n += 1
    return n / 9.0


@njit(cache=True, nogil=True, inline="always")
def pixel_light(r, c, g, p):
    """Electrons the environment adds to pixel (row r, column c) besides the dark-current change
    and the hits: interpolated stray light, the Earth in the field, the Moon's disk."""
    e = _grid_value(g, r, c) if p[E_STRAY] > 0.0 else 0.0
    u, v = float(c), float(r)
    if p[E_EARTH] > 0.0:
        dx, dy, dz = _los(u, v, p)
        if dx * p[E_NX] + dy * p[E_NY] + dz * p[E_NZ] > p[E_COSRHO]:
            e += p[E_LEARTH]
    if p[E_MOON] > 0.0 and p[E_DISK] > 0.0:
        e += p[E_DISK] * _disk_fraction(u, v, p)
    return e


@njit(cache=True, nogil=True)
def add_env_full(signal, gain, dark, g, p, deposits):
    """Add the environment to a whole frame's signal (H, W) in place (see :func:`add_env_spans`)."""
    h, w = signal.shape
    kd = p[E_DARK]
    for r in range(h):
        for c in range(w):
            e = pixel_light(r, c, g, p)
            if kd != 0.0:
                e += np.float64(dark[r, c]) * kd / np.float64(gain[r, c])
            signal[r, c] += e
    for k in range(deposits.shape[0]):
        r, c = int(deposits[k, 0]), int(deposits[k, 1])
        if 0 <= r < h and 0 <= c < w:
            signal[r, c] += deposits[k, 2]


@njit(cache=True, nogil=True)
def add_env_spans(signal, spans, maps, g, p, deposits):
    """Add the environment to span pixels ``signal`` (m,) in place: per pixel the light of
    :func:`pixel_light` plus the dark-current change, then the deposits (hits, hot pixels)
    ``[row, col, e⁻]`` in list order: the values :func:`add_env_full` adds to the same pixels."""
    kd = p[E_DARK]
    k = 0
    for i in range(spans.shape[0]):
        r = spans[i, 1]
        for c in range(spans[i, 2], spans[i, 3]):
            e = pixel_light(r, c, g, p)
            if kd != 0.0:
                e += np.float64(maps[r, c, 1]) * kd / np.float64(maps[r, c, 0])
            signal[k] += e
            k += 1
    for d in range(deposits.shape[0]):
        r, c = int(deposits[d, 0]), int(deposits[d, 1])
        base = 0
        for i in range(spans.shape[0]):
            n = spans[i, 3] - spans[i, 2]
            if spans[i, 1] == r and spans[i, 2] <= c < spans[i, 3]:
                signal[base + c - spans[i, 2]] += deposits[d, 2]
            base += n


@njit(cache=True)
def radiation_hits(seed, frame, lam, width, height, pitch_um, depth_um, q_per_um, landau_w):
    """The particle hits of sensor frame ``frame``: ``(hits (n, 6) [u0, v0, u1, v1, charge e⁻,
    points], deposits (m, 3) [row, col, e⁻])`` for a Poisson mean of ``lam`` hits."""
    key = pixel_noise.frame_key(seed, frame)
    u = pixel_noise.uniform(key, 0)
    # Poisson count by inversion (normal approximation beyond 60)
    if lam <= 0.0:
        n = 0
    elif lam < 60.0:
        p = math.exp(-lam)
        f = p
        n = 0
        while u > f and n < 1000:
            n += 1
            p *= lam / n
            f += p
    else:
        z, _ = pixel_noise.normal_pair(key, 1)
        n = max(0, int(math.floor(lam + math.sqrt(lam) * z + 0.5)))
    hits = np.empty((n, 6))
    npts = 0
    lens = np.empty(n, np.int64)
    for i in range(n):
        d = 8 + 8 * i
        u0 = pixel_noise.uniform(key, d) * width - 0.5
        v0 = pixel_noise.uniform(key, d + 1) * height - 0.5
        phi = 2.0 * math.pi * pixel_noise.uniform(key, d + 2)
        cos_t = math.sqrt(pixel_noise.uniform(key, d + 3))
        tan_t = math.sqrt(max(1.0 - cos_t * cos_t, 0.0)) / cos_t
        length = min(depth_um * tan_t / pitch_um, MAX_TRACK_PX)
        z, _ = pixel_noise.normal_pair(key, d + 4)
        x = min(max(-math.log(max(z * z, 1e-300)), -3.0), 25.0)         # Moyal: mode 0, Landau-like tail
        path_um = min(depth_um / cos_t, math.sqrt(depth_um * depth_um + (MAX_TRACK_PX * pitch_um) ** 2))
        q = max(q_per_um * path_um * (1.0 + landau_w * x), 0.0)
        m = max(1, int(math.ceil(2.0 * length)))
        hits[i, 0], hits[i, 1] = u0, v0
        hits[i, 2], hits[i, 3] = u0 + length * math.cos(phi), v0 + length * math.sin(phi)
        hits[i, 4], hits[i, 5] = q, m
        lens[i] = m
        npts += m
    deposits = np.empty((npts, 3))
    k = 0
    for i in range(n):
        m = lens[i]
        for j in range(m):
            f = (j + 0.5) / m
            deposits[k, 0] = math.floor(hits[i, 1] + f * (hits[i, 3] - hits[i, 1]) + 0.5)
            deposits[k, 1] = math.floor(hits[i, 0] + f * (hits[i, 2] - hits[i, 0]) + 0.5)
            deposits[k, 2] = hits[i, 4] / m
            k += 1
    return hits, deposits


@dataclasses.dataclass(frozen=True)
class ExposureEnv:
    """The environment of one exposure, ready for the kernels."""

    t_s: float                 # scenario time of the exposure start, s
    frame: int                 # sensor frame (the hits' counter)
    params: np.ndarray         # float64 (N_E,): see the E_* indexes
    grid: np.ndarray           # stray-light grid (e⁻), float64
    deposits: np.ndarray       # (m, 3) [row, col, e⁻]: this frame's hits, then the hot pixels
    hits: np.ndarray           # (n, 6) [u0, v0, u1, v1, charge e⁻, points] of this frame
    focal_scale: float         # true focal length / the preset's
    hidden_dirs: np.ndarray    # (k, 4) [x, y, z, cos r] ICRS cones whose stars are hidden (Earth, Moon)


class Environment:
    """The orbit environment of a run; see the module docstring.

    ``scen``: a :class:`gyrostar.hil.config.Scenario` (its hazard tables); ``seed``: the run's
    sensor seed (hits and hot pixels); ``horizon_s``: the run length (ephemeris table, hot pixels)."""

    def __init__(self, scen, seed: int, horizon_s: float = 600.0):
        self.orbit_cfg, self.stray, self.moon = scen.orbit, scen.stray_light, scen.moon
        self.rad, self.thermal = scen.radiation, scen.thermal
        self.seed = int(seed) & 0x7FFFFFFFFFFFFFFF
        self.horizon_s = float(horizon_s)
        self.orbit = CircularOrbit(self.orbit_cfg, horizon_s) if self.orbit_cfg.enabled else None
        self._hot = np.zeros((0, 4))           # [t_appear, row, col, dark e-/s]
        self._hot_until = 0.0
        self._hot_rng = np.random.default_rng([self.seed, RADIATION_STREAM, 1])

    @classmethod
    def from_scenario(cls, scen, seed: int, horizon_s: float | None = None):
        """The scenario's environment, or None when every part of it is off (the kind sky)."""
        if not getattr(scen, "hazards", None):
            return None
        return cls(scen, seed, scen.duration_s if horizon_s is None else horizon_s)

    # --- geometry ----------------------------------------------------------------------------
    def temperature_c(self, t: float) -> float:
        """Sensor temperature at scenario time ``t`` (s), °C."""
        th = self.thermal
        if not th.enabled:
            return float(th.reference_c)
        period = self.orbit.period_s if self.orbit is not None else 5677.0
        return float(th.temperature_c + th.swing_c * math.sin(2.0 * math.pi * t / period) + th.rate_c_per_s * t)

    def dark_factor(self, t: float) -> float:
        """Dark current at ``t`` over the preset's (2^(ΔT / doubling))."""
        th = self.thermal
        return 2.0 ** ((self.temperature_c(t) - th.reference_c) / th.dark_doubling_c) if th.enabled else 1.0

    def focal_scale(self, t: float) -> float:
        """True focal length at ``t`` over the preset's."""
        th = self.thermal
        return 1.0 + th.focal_ppm_per_c * 1e-6 * (self.temperature_c(t) - th.reference_c) if th.enabled else 1.0

    def geometry(self, t: float) -> dict | None:
        """ICRS directions at ``t``: ``sun``, ``moon`` (from the spacecraft), ``nadir``; distances
        (km) ``sun_km``, ``moon_km``; ``rho`` (Earth's angular radius, rad); ``eclipse``;
        ``lat_deg``, ``lon_deg``. None without an orbit."""
        o = self.orbit
        if o is None:
            return None
        r = o.position_km(t)
        sun = o.sun_km(t) - r
        moon = o.moon_km(t) - r
        d_sun, d_moon = float(np.linalg.norm(sun)), float(np.linalg.norm(moon))
        lat, lon = o.subpoint_deg(t)
        return {"sun": sun / d_sun, "sun_km": d_sun, "moon": moon / d_moon, "moon_km": d_moon,
                "sun_from_moon": (o.sun_km(t) - o.moon_km(t)) / np.linalg.norm(o.sun_km(t) - o.moon_km(t)),
                "nadir": -r / np.linalg.norm(r), "r_km": float(np.linalg.norm(r)), "rho": o.earth_radius_angle(),
                "eclipse": o.in_shadow(t), "lat_deg": lat, "lon_deg": lon}

    def in_saa(self, t: float) -> bool:
        """The sub-satellite point is inside the South Atlantic Anomaly box at ``t``."""
        if self.orbit is None:
            return False
        lat, lon = self.orbit.subpoint_deg(t)
        (a, b), (c, d) = self.rad.saa_lat_deg, self.rad.saa_lon_deg
        return a <= lat <= b and c <= lon <= d

    def hit_rate_per_frame(self, t: float, preset) -> float:
        """Poisson mean of particle hits on the whole sensor in one exposure at ``t``."""
        if not self.rad.enabled:
            return 0.0
        cam = preset.camera
        area_cm2 = cam.width_px * cam.height_px * (cam.pixel_pitch_m * 100.0) ** 2
        flux = self.rad.saa_flux_cm2_s if self.in_saa(t) else self.rad.flux_cm2_s
        return flux * area_cm2 * preset.detector.exposure_s

    def hits(self, frame: int, t: float, preset) -> tuple[np.ndarray, np.ndarray]:
        """``(hits, deposits)`` of sensor frame ``frame`` exposed from ``t`` (:func:`radiation_hits`)."""
        cam, r = preset.camera, self.rad
        return radiation_hits(self.seed ^ RADIATION_STREAM, int(frame), self.hit_rate_per_frame(t, preset),
                              cam.width_px, cam.height_px, cam.pixel_pitch_m * 1e6, r.depth_um, r.charge_e_per_um,
                              r.landau_width)

    def hot_pixels(self, t: float, preset) -> np.ndarray:
        """Hot pixels appeared by ``t``: (k, 4) [t_appear s, row, col, dark e⁻/s], in order of appearance."""
        rate = self.rad.hot_pixels_per_hour / 3600.0 if self.rad.enabled else 0.0
        if rate <= 0.0:
            return self._hot
        cam = preset.camera
        rows = []
        while self._hot_until <= t:
            t_next = self._hot_until + float(self._hot_rng.exponential(1.0 / rate))
            rows.append((t_next, float(self._hot_rng.integers(0, cam.height_px)),
                         float(self._hot_rng.integers(0, cam.width_px)),
                         self.rad.hot_pixel_dark_e_s * 10.0 ** (0.5 * float(self._hot_rng.standard_normal()))))
            self._hot_until = t_next
        if rows:
            self._hot = np.concatenate([self._hot, np.array(rows)])
        return self._hot[self._hot[:, 0] <= t]

    # --- one exposure ----------------------------------------------------------------------------
    def exposure(self, t_start: float, q_mid: np.ndarray, frame: int, preset, params: np.ndarray) -> ExposureEnv:
        """The environment of the exposure of ``preset`` starting at scenario time ``t_start``
        (s), attitude ``q_mid`` (ICRS→body) at its middle, sensor frame ``frame``; ``params``:
        the nominal camera array (its focal length is scaled here by the temperature)."""
        cam, det = preset.camera, preset.detector
        t = t_start + 0.5 * det.exposure_s
        scale = self.focal_scale(t)
        p = np.zeros(N_E)
        p[E_CX], p[E_CY], p[E_F] = params[P_CX], params[P_CY], params[P_F] * scale
        p[E_DARK] = self.dark_factor(t) - 1.0
        half = math.atan(math.hypot(cam.width_px, cam.height_px) / 2.0 / (params[P_F] * scale))
        s = self.stray
        p[E_HALF], p[E_EXCL] = half, math.radians(s.exclusion_deg)
        p[E_PSTEDGE], p[E_PSTEXCL], p[E_SLOPE], p[E_WIDTH] = s.pst_edge, s.pst_exclusion, s.slope, \
            math.radians(s.transition_deg)
        hidden = []
        geo = self.geometry(t)
        if geo is not None:
            a = quat_to_dcm(np.asarray(q_mid, float))
            # electrons a pixel collects per unit PST from an irradiance of 1 photon/s/m² at the aperture
            per_ph = cam.pixel_pitch_m ** 2 * det.qe * det.exposure_s
            zp = preset.photometry.zero_point_ph_s_m2
            e_sun = zp * 10.0 ** (-0.4 * V_SUN) * (AU_KM / geo["sun_km"]) ** 2      # photons/s/m²
            n_cam = a @ geo["nadir"]
            p[E_NX], p[E_NY], p[E_NZ], p[E_RHO] = n_cam[0], n_cam[1], n_cam[2], geo["rho"]
            p[E_COSRHO] = math.cos(geo["rho"])
            cosz = self._limb_cos_zenith(geo, a[2])
            # the Earth in the field (tested per pixel when its disk can reach the sensor): the
            # radiance albedo·E·cos z/π over a pixel's solid angle, through the aperture
            albedo = s.earth_albedo
            p[E_LEARTH] = (albedo * e_sun * max(cosz, 0.0) / math.pi * (cam.pixel_pitch_m / cam.focal_length_m) ** 2
                           * preset.aperture_area_m2 * preset.optics.transmittance * det.qe * det.exposure_s)
            limb = math.acos(max(-1.0, min(1.0, float(a[2] @ geo["nadir"])))) - geo["rho"]
            p[E_EARTH] = 1.0 if p[E_LEARTH] > 0.0 and limb < half + math.radians(0.5) else 0.0
            hidden.append((*geo["nadir"], math.cos(geo["rho"])))
            sun_cam, moon_cam = a @ geo["sun"], a @ geo["moon"]
            p[E_SX], p[E_SY], p[E_SZ] = sun_cam
            p[E_MX], p[E_MY], p[E_MZ] = moon_cam
            p[E_MRAD] = math.asin(R_MOON_KM / geo["moon_km"])
            v_moon, cos_alpha = self._moon_mag(geo, moon_cam, a)
            if s.enabled:
                p[E_STRAY] = 1.0
                p[E_KSUN] = 0.0 if geo["eclipse"] else e_sun * per_ph
                p[E_KMOON] = zp * 10.0 ** (-0.4 * v_moon) * per_ph
                p[E_KEARTH] = albedo * e_sun * max(cosz, 0.0) * (R_EARTH_KM / geo["r_km"]) ** 2 * per_ph
            if self.moon.enabled:
                p[E_MOON] = 1.0
                hidden.append((*geo["moon"], math.cos(p[E_MRAD])))
                if moon_cam[2] > 0.0:
                    uv = render.star_paths(np.asarray(params, float) * _focal_vec(len(params), scale),
                                           geo["moon"][None, :], np.asarray(q_mid, float)[None, :])[0, 0]
                    rm = p[E_F] * math.tan(p[E_MRAD])
                    lit_px2 = math.pi * rm * rm * 0.5 * (1.0 + cos_alpha)
                    on_sensor = (-rm - 2.0 < uv[0] < cam.width_px + rm + 1.0
                                 and -rm - 2.0 < uv[1] < cam.height_px + rm + 1.0)
                    if lit_px2 > 1e-6 and np.isfinite(uv).all() and on_sensor:
                        p[E_DU], p[E_DV], p[E_DR] = uv[0], uv[1], rm
                        p[E_DISK] = float(preset.star_electrons(v_moon)) / lit_px2
                        ex, ey, ez = _disk_axes(moon_cam)
                        sm = a @ geo["sun_from_moon"]
                        p[E_LX], p[E_LY], p[E_LZ] = sm @ ex, sm @ ey, sm @ ez
        grid = stray_grid(p, cam.width_px, cam.height_px) if p[E_STRAY] > 0.0 else np.zeros((1, 1))
        hits, deposits = self.hits(frame, t_start, preset) if self.rad.enabled else (np.zeros((0, 6)), np.zeros((0, 3)))
        hot = self.hot_pixels(t_start, preset) if self.rad.enabled else self._hot
        if len(hot):
            deposits = np.concatenate([deposits, np.column_stack([hot[:, 1], hot[:, 2], hot[:, 3] * det.exposure_s])])
        return ExposureEnv(float(t_start), int(frame), p, grid, np.ascontiguousarray(deposits), hits, scale,
                           np.array(hidden, float).reshape(-1, 4))

    @staticmethod
    def _limb_cos_zenith(geo: dict, bore: np.ndarray) -> float:
        """cos of the Sun's zenith angle at the point of the Earth's limb nearest ``bore`` (ICRS)."""
        n, rho = geo["nadir"], geo["rho"]
        e = bore - (bore @ n) * n
        ne = float(np.linalg.norm(e))
        if ne < 1e-12:                    # the boresight at nadir or zenith: any limb point will do
            e, ne = np.cross(n, [0.0, 0.0, 1.0]), 1.0
            ne = max(float(np.linalg.norm(e)), 1e-12)
        e = e / ne
        los = math.cos(rho) * n + math.sin(rho) * e
        r = -n * geo["r_km"]
        pt = r + los * math.sqrt(geo["r_km"] ** 2 - R_EARTH_KM ** 2)
        return float(pt @ geo["sun"] / np.linalg.norm(pt))

    @staticmethod
    def _moon_mag(geo: dict, moon_cam: np.ndarray, a: np.ndarray) -> tuple[float, float]:
        """(V magnitude of the Moon seen from the spacecraft, cos of its phase angle α)."""
        cos_alpha = float(-(geo["sun_from_moon"] @ geo["moon"]))
        alpha = math.degrees(math.acos(max(-1.0, min(1.0, cos_alpha))))
        v = -12.73 + 0.026 * alpha + 4e-9 * alpha ** 4 + 5.0 * math.log10(geo["moon_km"] / MOON_MEAN_KM)
        return v, cos_alpha

    # --- truth ---------------------------------------------------------------------------------
    def truth(self, t: float, q: np.ndarray, preset, params: np.ndarray) -> dict:
        """What the environment does at scenario time ``t`` with the attitude ``q`` (ICRS→body):
        angles from the boresight (deg) to the Sun, the Earth's limb (negative: the boresight is
        on the Earth) and the Moon; the Moon's pixel position and radius (px) when its centre is
        in front of the camera; the stray light (e⁻/px/exposure) at the principal point (and its parts from
        the Sun, the Moon and the Earth); eclipse,
        sub-satellite point, SAA, temperature, dark factor, focal scale, hit rate per frame."""
        out = {"t_s": float(t), "temperature_c": self.temperature_c(t), "dark_factor": self.dark_factor(t),
               "focal_scale": self.focal_scale(t), "hits_per_frame": self.hit_rate_per_frame(t, preset),
               "in_saa": self.in_saa(t)}
        geo = self.geometry(t)
        if geo is None:
            return out
        bore = quat_to_dcm(np.asarray(q, float))[2]
        ang = lambda v: math.degrees(math.acos(max(-1.0, min(1.0, float(v @ bore)))))   # noqa: E731
        env = self.exposure(t - 0.5 * preset.detector.exposure_s, q, 0, preset, params)
        p = env.params
        cx, cy = p[E_CX], p[E_CY]
        out.update({"sun_angle_deg": ang(geo["sun"]),
                    "earth_limb_angle_deg": ang(geo["nadir"]) - math.degrees(geo["rho"]),
                    "moon_angle_deg": ang(geo["moon"]), "moon_radius_deg": math.degrees(p[E_MRAD]),
                    "eclipse": bool(geo["eclipse"]), "lat_deg": geo["lat_deg"], "lon_deg": geo["lon_deg"],
                    "stray_e_px": float(stray_at(cx, cy, p)) if p[E_STRAY] > 0 else 0.0,
                    "stray_parts_e_px": dict(zip(("sun", "moon", "earth"), map(float, stray_parts(cx, cy, p)))),
                    "earth_in_field_e_px": float(p[E_LEARTH]),
                    "moon_uv": [float(p[E_DU]), float(p[E_DV])] if p[E_DISK] > 0 else None,
                    "moon_radius_px": float(p[E_DR]) if p[E_DISK] > 0 else None,
                    "moon_disk_e_px": float(p[E_DISK])})
        return out

    def describe(self) -> dict:
        """The hazard parameters switched on (for the run summary)."""
        out = {}
        for key, cfg in (("orbit", self.orbit_cfg), ("stray_light", self.stray), ("moon", self.moon),
                         ("radiation", self.rad), ("thermal", self.thermal)):
            if cfg.enabled:
                out[key] = {k: v for k, v in dataclasses.asdict(cfg).items() if k != "enabled"}
        if self.orbit is not None:
            out["orbit"]["period_s"] = self.orbit.period_s
            out["orbit"]["raan_deg"] = math.degrees(self.orbit.raan) % 360.0
        return out


def _focal_vec(n: int, scale: float) -> np.ndarray:
    """A camera-array multiplier that scales the focal length only."""
    v = np.ones(n)
    v[P_F] = scale
    return v


def _disk_axes(m: np.ndarray):
    """Axes (camera frame) of the Moon's disk: along +column and +row across the line of sight
    ``m``, and towards the observer (−m)."""
    x = np.array([1.0, 0.0, 0.0]) - m[0] * m
    x /= np.linalg.norm(x)
    y = np.array([0.0, 1.0, 0.0]) - m[1] * m
    y -= (y @ x) * x
    y /= np.linalg.norm(y)
    return x, y, -m


def visible_mask(vecs: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """bool (n,): the star vectors (n, 3, ICRS) outside every hidden cone [x, y, z, cos r]."""
    keep = np.ones(len(vecs), bool)
    for x, y, z, c in hidden:
        keep &= vecs @ np.array([x, y, z]) <= c
    return keep

