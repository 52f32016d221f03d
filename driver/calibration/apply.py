"""The calibration file a run uses: loaded once, identified by path and SHA-256, applied.

:func:`load_for_run` reads the TOML written by ``gyrostar calibrate`` (or the text kept in
a log's META, so a replay uses exactly what the run used). :class:`RunCalibration` gives
the loop its camera model (:meth:`camera`), its gyro in camera axes and camera time
(:meth:`gyro`, a :class:`gyrostar.gyro.calibrated.CalibratedGyro`) and the hot pixels
(:meth:`hot_pixels`, (column, row) pairs).

A real head has no simulator preset to fall back on: without a ``[camera]`` table the run
is refused with a :class:`ConfigError` naming the key (exit 2).
"""

from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import config
from ..errors import ConfigError
from . import calfile


@dataclass
class RunCalibration:
    """A calibration in use: ``cal`` (None: none given), where it came from, its hash."""

    cal: calfile.Calibration | None
    path: str = ""
    sha256: str = ""
    text: str = ""

    def describe(self) -> str:
        if self.cal is None:
            return "none (nominal camera, identity gyro mounting, no time offset)"
        tables = [s for s in calfile.SECTIONS if getattr(self.cal, s) is not None]
        return f"{self.path} (sha256 {self.sha256[:16]}): " + ", ".join(tables)

    def meta(self) -> dict:
        """What a log's META keeps of it (the whole text: replay must not depend on the file)."""
        return {"path": self.path, "sha256": self.sha256, "text": self.text}

    def camera(self, nominal, real_head: bool):
        """The loop's :class:`gyrostar.camera.CameraModel`: the calibrated intrinsics over
        ``nominal`` (a simulator preset), or from the calibration alone on a real head."""
        cam = self.cal.camera if self.cal is not None else None
        if real_head and cam is None:
            where = f"calibration file {self.path}" if self.path else "no calibration file (config key 'calibration')"
            raise ConfigError(f"a real head needs the camera model: key 'camera.focal_length_px' missing ({where}); "
                              "run gyrostar calibrate camera")
        if cam is None:
            return nominal
        if nominal is None:
            from ..camera import CameraModel

            pitch = cam.pixel_pitch_um * 1e-6
            w, h = cam.image_size_px
            nominal = CameraModel(cam.focal_length_px * pitch, pitch, int(w), int(h), 0.5 * (w - 1), 0.5 * (h - 1))
        return calfile.camera_model(self.cal, nominal)

    def gyro_map(self):
        """``(M, b, δt)`` of :func:`calfile.gyro_to_camera`, or None without gyro tables."""
        c = self.cal
        if c is None or (c.gyro_static is None and c.gyro_scale is None and c.alignment is None):
            return None
        return calfile.gyro_to_camera(c)

    def gyro(self, device):
        """``device`` seen through the calibration (itself when there is nothing to apply)."""
        gm = self.gyro_map()
        if gm is None:
            return device
        from ..gyro.calibrated import CalibratedGyro

        return CalibratedGyro(device, *gm)

    def hot_pixels(self) -> np.ndarray:
        """(n, 2) int64 [column, row] of the [dark] hot pixels (empty without them)."""
        if self.cal is None or self.cal.dark is None or not self.cal.dark.hot_pixels:
            return np.zeros((0, 2), np.int64)
        return np.asarray(self.cal.dark.hot_pixels, np.int64).reshape(-1, 2)


def load_for_run(path: str | Path | None) -> RunCalibration:
    """The calibration at ``path`` (``""``/None: none). ``ConfigError`` if missing or invalid."""
    if not path:
        return RunCalibration(None)
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"calibration file {p} is a folder: give the .toml file (config key 'calibration' or "
                          "--calibration)")
    if not p.exists():
        raise ConfigError(f"calibration file {p} does not exist (config key 'calibration' or --calibration)")
    data = config.read_bytes(p, "calibration file")
    return from_text(config.decode(data, p, "calibration file"), str(p), hashlib.sha256(data).hexdigest())


def from_text(text: str, path: str, sha256: str = "") -> RunCalibration:
    """A calibration from its TOML text (e.g. kept in a log's META)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"calibration file {path} is not valid TOML: {exc}") from exc
    cal = config.from_dict(raw, calfile.Calibration, source=path)
    return RunCalibration(cal, path, sha256 or hashlib.sha256(text.encode()).hexdigest(), text)


def from_meta(meta: dict | None) -> RunCalibration:
    """The calibration a logged run used (its META entry), or none."""
    if not meta or not meta.get("text"):
        return RunCalibration(None)
    return from_text(meta["text"], meta.get("path", "log META"), meta.get("sha256", ""))

