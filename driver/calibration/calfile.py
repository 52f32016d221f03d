"""The calibration TOML the driver loads: schema (``gyrostar.config`` dataclasses), writer, loader.

One file holds one table per calibration; each ``gyrostar calibrate NAME`` replaces its
own table and keeps the others, so a field campaign builds up one file::

    [gyro_static]   bias (rad/s), ARW (rad/√s), bias instability (rad/s), RRW (rad/s/√s)
    [gyro_scale]    ω_true = correction · (ω_meas − bias); scale factor errors (ppm)
    [dark]          dark-current FITS path, read noise (DN), hot pixels [[column, row], …]
    [camera]        focal length, principal point (px), Brown–Conrady k1 k2 k3 p1 p2
    [alignment]     q_gyro_to_camera [x, y, z, w] (maps gyro-frame vectors to the camera
                    frame), time_offset_s (add to gyro timestamps to get camera time)

Written with ``tomli-w``; read back with :func:`gyrostar.config.load`, which rejects
unknown or ill-typed keys and values outside physical bounds (a [camera] whose diagonal field
of view leaves :data:`FOV_DEG` or whose principal point is off the sensor, a time offset
beyond :data:`TIME_OFFSET_MAX_S`, a quaternion whose norm is off 1 by more than
:data:`QUAT_NORM_TOL` (it is normalised when applied), a bias beyond :data:`BIAS_MAX_RPS`).
"""

from __future__ import annotations

import datetime as _dt
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .. import config
from ..errors import ConfigError

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

FOV_DEG = (0.5, 58.0)       # diagonal field of view (deg) a [camera] may imply; the star index holds pairs < 60°
CORNER_DISTORTION = 0.2     # |radial distortion| (fraction of the radius) allowed at the sensor corner
PP_SIGMA_MAX_PX = 100.0     # a principal point known only to 100 px is no calibration
TIME_OFFSET_MAX_S = 1.0     # |[alignment] time_offset_s| (s): more is a wrong clock, not a gyro-camera delay
QUAT_NORM_TOL = 1e-3        # |‖q‖ − 1| accepted (hand-typed quaternions), normalised when applied
BIAS_MAX_RPS = math.radians(10.0)   # |gyro bias| (rad/s): a MEMS zero-rate offset is ~1 °/s


def _check_bias(key: str, bias: Vec3) -> None:
    if max(abs(v) for v in bias) > BIAS_MAX_RPS:
        raise ValueError(f"{key} must be within ±{BIAS_MAX_RPS:.3f} rad/s (10 °/s) per axis, got {list(bias)}")


@dataclass
class GyroStaticCal:
    """Static gyro log: per-axis bias and IEEE 952 noise terms (SI units, gyro axes)."""

    bias_rps: Vec3
    arw_rad_per_sqrt_s: Vec3
    bias_instability_rps: Vec3
    rrw_rps_per_sqrt_s: Vec3
    quantization_rad: Vec3 = (0.0, 0.0, 0.0)
    duration_s: float = 0.0
    temperature_c: float | None = None
    bias_temp_coeff_rps_per_c: Vec3 | None = None

    def validate(self) -> None:
        _check_bias("gyro_static.bias_rps", self.bias_rps)


@dataclass
class GyroScaleCal:
    """Scale factor and misalignment: ``ω_true = correction @ (ω_meas − bias_rps)``.

    ``sensitivity`` is the inverse of ``correction`` (``ω_meas = sensitivity @ ω_true + b``);
    its diagonal minus one, in ppm, is ``scale_factor_ppm``."""

    correction: Mat3
    sensitivity: Mat3
    bias_rps: Vec3
    scale_factor_ppm: Vec3
    method: str = "rate-table"

    def validate(self) -> None:
        for key in ("correction", "sensitivity"):
            if any(abs(v) > 2.0 for row in getattr(self, key) for v in row):
                raise ValueError(f"gyro_scale.{key}: entries above 2 in size are not a gyro calibration")
        _check_bias("gyro_scale.bias_rps", self.bias_rps)


@dataclass
class DarkCal:
    """Dark frames: map file (FITS, DN/s per pixel), read noise, hot pixels (column, row)."""

    fits: str
    read_noise_dn: float
    dark_current_median_dn_per_s: float
    offset_median_dn: float
    hot_pixels: list[tuple[int, int]] = field(default_factory=list)
    temperature_c: float | None = None


@dataclass
class CameraCal:
    """Intrinsics in pixels; Brown–Conrady on normalised coordinates (x = X/Z, y = Y/Z)."""

    focal_length_px: float
    principal_point_px: tuple[float, float]
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    image_size_px: tuple[int, int] = (1024, 1024)
    residual_rms_px: float = 0.0
    pixel_pitch_um: float = 15.0       # only turns the focal length into metres (the loop works in px)
    principal_point_sigma_px: tuple[float, float] = (0.0, 0.0)   # the fit's 1σ of each (0: not known)

    def validate(self) -> None:
        w, h = self.image_size_px
        f = self.focal_length_px
        if w < 1 or h < 1:
            raise ValueError(f"camera.image_size_px must be positive, got {list(self.image_size_px)}")
        if not f > 0:
            raise ValueError(f"camera.focal_length_px must be > 0, got {f!r}")
        half_diag = 0.5 * math.hypot(w, h)
        fov = 2.0 * math.degrees(math.atan(half_diag / f))
        if not FOV_DEG[0] <= fov <= FOV_DEG[1]:
            f_lo, f_hi = (half_diag / math.tan(math.radians(a / 2.0)) for a in FOV_DEG[::-1])
            raise ValueError(f"camera.focal_length_px = {f:g} gives a {fov:.3g}° diagonal field of view on "
                             f"{w}×{h} px; allowed {FOV_DEG[0]}–{FOV_DEG[1]}° ({f_lo:.0f}–{f_hi:.0f} px)")
        cx, cy = self.principal_point_px
        if not (0.0 <= cx <= w - 1 and 0.0 <= cy <= h - 1):
            raise ValueError(f"camera.principal_point_px ({cx:g}, {cy:g}) is off the {w}×{h} px sensor "
                             f"(column 0–{w - 1}, row 0–{h - 1})")
        r2 = (half_diag / f) ** 2
        radial = self.k1 * r2 + self.k2 * r2 ** 2 + self.k3 * r2 ** 3
        if not abs(radial) <= CORNER_DISTORTION:
            raise ValueError(f"camera.k1, k2, k3 distort the sensor corner by {radial:.3g} of its radius "
                             f"(allowed ±{CORNER_DISTORTION:g})")
        if not 0.0 < self.pixel_pitch_um <= 1000.0:
            raise ValueError(f"camera.pixel_pitch_um must be in (0, 1000] µm, got {self.pixel_pitch_um!r}")
        if not all(math.isfinite(v) and 0.0 <= v <= PP_SIGMA_MAX_PX for v in self.principal_point_sigma_px):
            raise ValueError(f"camera.principal_point_sigma_px must be two values in [0, {PP_SIGMA_MAX_PX:g}] px, got "
                             f"{list(self.principal_point_sigma_px)}")


@dataclass
class AlignmentCal:
    """Gyro → camera rotation ([x, y, z, w], vector part first) and clock offset (s)."""

    q_gyro_to_camera: tuple[float, float, float, float]
    time_offset_s: float
    residual_rms_arcsec: float = 0.0

    def validate(self) -> None:
        n = math.sqrt(sum(v * v for v in self.q_gyro_to_camera))
        if not abs(n - 1.0) <= QUAT_NORM_TOL:
            raise ValueError(f"alignment.q_gyro_to_camera must be a unit quaternion [x, y, z, w] (norm within "
                             f"{QUAT_NORM_TOL:g} of 1), got norm {n:.9g}")
        if not abs(self.time_offset_s) <= TIME_OFFSET_MAX_S:
            raise ValueError(f"alignment.time_offset_s must be within ±{TIME_OFFSET_MAX_S:g} s, "
                             f"got {self.time_offset_s!r}")


@dataclass
class Meta:
    """Provenance: when each table was last written and from what."""

    updated: dict[str, str] = field(default_factory=dict)
    source: dict[str, str] = field(default_factory=dict)


@dataclass
class Calibration:
    """Root of the calibration TOML; every table is optional."""

    meta: Meta = field(default_factory=Meta)
    gyro_static: GyroStaticCal | None = None
    gyro_scale: GyroScaleCal | None = None
    dark: DarkCal | None = None
    camera: CameraCal | None = None
    alignment: AlignmentCal | None = None


SECTIONS = {"gyro_static": GyroStaticCal, "gyro_scale": GyroScaleCal, "dark": DarkCal,
            "camera": CameraCal, "alignment": AlignmentCal}


def load(path: str | Path) -> Calibration:
    """Read and validate a calibration TOML (``ConfigError`` on any bad key, type or value)."""
    what = "calibration file"
    return config.loads(config.read_text(path, what), Calibration, source=str(path), what=what)


def write_section(path: str | Path, section: str, value, source: str) -> Calibration:
    """Replace table ``section`` of the calibration file at ``path`` (created if absent),
    keeping the others. The merged result is validated before the file is replaced, and
    the file is written to a temporary name first, so a failure loses nothing; an existing
    file that is not a calibration TOML (binary, other TOML) is refused and left as it is."""
    import tomli_w

    if section not in SECTIONS or not isinstance(value, SECTIONS[section]):
        raise ConfigError(f"unknown calibration section {section!r} or wrong value type")
    path = Path(path)
    raw: dict = {}
    if path.exists():
        raw = _existing(path)
    raw[section] = config.to_dict(value)
    meta = raw.setdefault("meta", {})
    meta.setdefault("updated", {})[section] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    meta.setdefault("source", {})[section] = source
    cal = config.from_dict(raw, Calibration, source=str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(tomli_w.dumps(raw).encode())
    tmp.replace(path)
    return cal


def check_target(path: str | Path) -> None:
    """``ConfigError`` when ``path`` exists and is not a calibration file (or is a folder):
    what :func:`write_section` refuses, checked before the work that would write it."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{path} is a folder: give the calibration file's path")
    if path.exists():
        _existing(path)


def _existing(path: Path) -> dict:
    """The tables of the calibration file at ``path``: ``ConfigError`` when it is not one."""
    refuse = f"{path} exists and is not a calibration file; left as it is (choose another --out)"
    data = config.read_bytes(path, "existing file")
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{refuse}: it is not UTF-8 text TOML") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{refuse}: it is not valid TOML ({exc})") from None
    foreign = sorted(set(raw) - {"meta", *SECTIONS})
    if foreign:
        raise ConfigError(f"{refuse}: it has key '{foreign[0]}' (a calibration file has "
                          f"{', '.join(['meta', *SECTIONS])})")
    return raw


def camera_model(cal: Calibration, nominal):
    """The :class:`gyrostar.camera.CameraModel` with the calibrated intrinsics of ``cal``
    (``nominal`` itself when ``cal`` has no [camera] table). The pixel pitch is kept, so
    ``focal_length_m = focal_length_px · pitch``."""
    import dataclasses

    c = cal.camera
    if c is None:
        return nominal
    if tuple(c.image_size_px) != (nominal.width_px, nominal.height_px):
        raise ConfigError(f"camera calibration is for {c.image_size_px} px, the camera is "
                          f"{nominal.width_px}×{nominal.height_px}")
    return dataclasses.replace(nominal, focal_length_m=c.focal_length_px * nominal.pixel_pitch_m,
                               cx_px=c.principal_point_px[0], cy_px=c.principal_point_px[1],
                               k1=c.k1, k2=c.k2, k3=c.k3, p1=c.p1, p2=c.p2)


def gyro_to_camera(cal: Calibration):
    """``(M, b, δt)`` such that ``ω_camera = M (ω_meas − b)`` at camera time ``t_gyro + δt``:
    ``M = R_alignment · correction`` (identity parts when a table is absent), ``b`` the
    [gyro_scale] bias, else the [gyro_static] bias, else zero (rad/s, gyro axes)."""
    import numpy as np

    from ..attitude import quat_to_dcm

    m = np.eye(3)
    b = np.zeros(3)
    if cal.gyro_static is not None:
        b = np.asarray(cal.gyro_static.bias_rps, float)
    if cal.gyro_scale is not None:
        m = np.asarray(cal.gyro_scale.correction, float)
        b = np.asarray(cal.gyro_scale.bias_rps, float)
    dt = 0.0
    if cal.alignment is not None:
        q = np.asarray(cal.alignment.q_gyro_to_camera, float)
        m = quat_to_dcm(q / np.linalg.norm(q)) @ m
        dt = cal.alignment.time_offset_s
    return m, b, dt


def hot_pixel_mask(cal: Calibration, width: int, height: int):
    """Boolean (height, width) mask, True at the [dark] hot pixels (for centroiding to skip)."""
    import numpy as np

    mask = np.zeros((height, width), bool)
    if cal.dark is not None and cal.dark.hot_pixels:
        hp = np.asarray(cal.dark.hot_pixels, np.int64)
        if hp.min() < 0 or hp[:, 0].max() >= width or hp[:, 1].max() >= height:
            raise ConfigError(f"hot pixels fall outside a {width}×{height} sensor")
        mask[hp[:, 1], hp[:, 0]] = True
    return mask
