"""Simulator presets: camera + optics + detector + photometry, read from TOML.

A preset is ``mocks/data/sim_<name>.toml`` (``xing2012``, ``qian2015``) or any TOML file
of the same schema, validated by :mod:`gyrostar.config`. Each file states, next to every
value, whether it comes from a paper or is an assumption and why. Units are in the names.

``SimPreset.detector_array()`` packs the detector for the numba kernels (index ``D_*``).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from gyrostar import config
from gyrostar.camera import CameraModel, camera_preset
from gyrostar.errors import ConfigError

DATA = Path(__file__).resolve().parent / "data"

(D_EXPOSURE, D_QE, D_READ, D_DARK, D_DSNU, D_PRNU, D_HOTF, D_HOTDARK, D_FULLWELL, D_GAIN, D_BIAS, D_ADCMAX,
 D_SKY_E) = range(13)
N_DET = 13


@dataclasses.dataclass(frozen=True)
class OpticsConfig:
    aperture_m: float
    transmittance: float
    psf_sigma_px: float

    def validate(self) -> None:
        if not self.aperture_m > 0:
            raise ValueError("optics.aperture_m must be > 0")
        if not 0 < self.transmittance <= 1:
            raise ValueError("optics.transmittance must be in (0, 1]")
        if not 0.1 <= self.psf_sigma_px <= 20:
            raise ValueError("optics.psf_sigma_px must be in [0.1, 20]")


@dataclasses.dataclass(frozen=True)
class DetectorConfig:
    exposure_s: float
    qe: float
    read_noise_e: float
    dark_current_e_s: float
    dsnu_frac: float
    prnu_frac: float
    hot_pixel_frac: float
    hot_pixel_dark_e_s: float
    full_well_e: float
    gain_e_per_adu: float
    bias_adu: float
    adc_bits: int

    def validate(self) -> None:
        if not 0 < self.exposure_s <= 100:
            raise ValueError("detector.exposure_s must be in (0, 100] s")
        if not 0 < self.qe <= 1:
            raise ValueError("detector.qe must be in (0, 1]")
        for name in ("read_noise_e", "dark_current_e_s", "dsnu_frac", "prnu_frac", "hot_pixel_dark_e_s", "bias_adu"):
            if getattr(self, name) < 0:
                raise ValueError(f"detector.{name} must be >= 0")
        if not 0 <= self.hot_pixel_frac < 1:
            raise ValueError("detector.hot_pixel_frac must be in [0, 1)")
        if not (self.full_well_e > 0 and self.gain_e_per_adu > 0):
            raise ValueError("detector.full_well_e and gain_e_per_adu must be > 0")
        if not 1 <= self.adc_bits <= 16:
            raise ValueError("detector.adc_bits must be in 1..16")


@dataclasses.dataclass(frozen=True)
class PhotometryConfig:
    zero_point_ph_s_m2: float = 1.0e10
    sky_mag_arcsec2: float = 22.0


@dataclasses.dataclass(frozen=True)
class SimPresetFile:
    """Schema of a preset TOML file."""

    camera: str
    optics: OpticsConfig
    detector: DetectorConfig
    photometry: PhotometryConfig = dataclasses.field(default_factory=PhotometryConfig)


@dataclasses.dataclass(frozen=True)
class SimPreset:
    """A resolved preset: the camera model plus optics, detector and photometry."""

    name: str
    camera: CameraModel
    optics: OpticsConfig
    detector: DetectorConfig
    photometry: PhotometryConfig

    @property
    def aperture_area_m2(self) -> float:
        return math.pi * (0.5 * self.optics.aperture_m) ** 2

    def electrons_per_s_at_v0(self) -> float:
        """Signal electrons per second from a V = 0 star: Φ0 · A · T · QE."""
        return (self.photometry.zero_point_ph_s_m2 * self.aperture_area_m2
                * self.optics.transmittance * self.detector.qe)

    def star_electrons(self, vmag: np.ndarray | float) -> np.ndarray | float:
        """Signal electrons collected in one exposure from stars of magnitude ``vmag``."""
        return self.electrons_per_s_at_v0() * self.detector.exposure_s * 10.0 ** (-0.4 * np.asarray(vmag))

    def sky_electrons_per_px(self) -> float:
        """Sky background electrons per pixel per exposure (surface brightness × pixel solid angle)."""
        px_arcsec = math.degrees(self.camera.ifov_rad) * 3600.0
        return float(self.star_electrons(self.photometry.sky_mag_arcsec2) * px_arcsec ** 2)

    def detector_array(self) -> np.ndarray:
        """float64 vector for the numba kernels (``D_*`` indexes)."""
        d = self.detector
        a = np.empty(N_DET)
        a[D_EXPOSURE], a[D_QE], a[D_READ], a[D_DARK] = d.exposure_s, d.qe, d.read_noise_e, d.dark_current_e_s
        a[D_DSNU], a[D_PRNU], a[D_HOTF], a[D_HOTDARK] = d.dsnu_frac, d.prnu_frac, d.hot_pixel_frac, d.hot_pixel_dark_e_s
        a[D_FULLWELL], a[D_GAIN], a[D_BIAS] = d.full_well_e, d.gain_e_per_adu, d.bias_adu
        a[D_ADCMAX] = float(2 ** d.adc_bits - 1)
        a[D_SKY_E] = self.sky_electrons_per_px()
        return a

    def with_exposure(self, exposure_s: float) -> SimPreset:
        """The same preset with another exposure time (s)."""
        det = dataclasses.replace(self.detector, exposure_s=float(exposure_s))
        try:
            det.validate()
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc
        return dataclasses.replace(self, detector=det)


PRESET_NAMES = tuple(sorted(p.stem[4:] for p in DATA.glob("sim_*.toml")))


def load_preset(name_or_path: str | Path) -> SimPreset:
    """A named preset (``xing2012``, ``qian2015``) or a preset TOML file."""
    path = Path(name_or_path)
    if not path.suffix == ".toml":
        path = DATA / f"sim_{name_or_path}.toml"
        if not path.exists():
            raise ConfigError(f"unknown simulator preset '{name_or_path}' (known: {', '.join(PRESET_NAMES)})")
    raw = config.load(path, SimPresetFile)
    return SimPreset(path.stem.removeprefix("sim_"), camera_preset(raw.camera), raw.optics, raw.detector,
                     raw.photometry)
