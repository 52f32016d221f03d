"""Dark-frame calibration: dark-current map, offset map (bias + DSNU), read noise, hot pixels.

Inputs are stacks of dark frames (DN) taken at several exposure times ``t_e`` (s). Per
pixel the stack means follow ``mean(t) = offset + rate · t``; the dark current ``rate``
(DN/s) and ``offset`` (DN) come from a per-pixel least-squares line over the exposures.
Hot pixels are those whose dark current exceeds the median by more than ``k`` robust
standard deviations (1.4826·MAD) and is above ``hot_factor`` × the median (so the tail of
an ordinary dark-signal non-uniformity is not called hot). Read noise is the temporal
noise at zero exposure: the mean over the other pixels of the temporal variance at each
exposure (from frame-to-frame differences, which cancel any fixed pattern; a mean, since
the median of a few-frame χ² variance is biased low) is fitted as ``σ²(t) = σ_r² + c·t``
and ``σ_r`` is its intercept (DN, still including the ADC's 1/12 DN² quantisation).

Products go to a FITS file (astropy): primary HDU = dark-current map (DN/s), ``OFFSET``
image (DN), ``TNOISE`` image (temporal σ at the shortest exposure, DN), ``HOTPIX``
table (COLUMN, ROW, RATE); headers carry the exposures, frame counts and the figures.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError


@dataclass
class DarkStack:
    """Frames of one exposure time: ``mean`` (DN, H×W), ``tvar`` per-pixel temporal
    variance (DN², from frame differences), ``n`` frames, ``exposure`` s."""

    exposure: float
    mean: np.ndarray
    tvar: np.ndarray
    n: int


@dataclass
class DarkResult:
    rate: np.ndarray          # DN/s per pixel
    offset: np.ndarray        # DN per pixel (bias + DSNU)
    tnoise: np.ndarray        # DN, temporal σ at the shortest exposure
    read_noise: float         # DN
    hot: np.ndarray           # (K, 2) int: column, row
    hot_threshold: float      # DN/s
    exposures: np.ndarray     # s
    frames: np.ndarray        # frames per exposure

    @property
    def rate_median(self) -> float:
        return float(np.median(self.rate))


def stack(frames: np.ndarray, exposure: float) -> DarkStack:
    """Reduce ``frames`` (n ≥ 2, H, W) of one exposure to its mean and temporal variance."""
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim != 3 or f.shape[0] < 2:
        raise ConfigError(f"need at least 2 dark frames per exposure as (n, H, W); got {f.shape}")
    if not exposure >= 0:
        raise ConfigError(f"exposure time must be non-negative, got {exposure}")
    d = np.diff(f, axis=0)  # differences cancel the fixed pattern; var(diff) = 2 σ²
    return DarkStack(float(exposure), f.mean(axis=0), (d**2).mean(axis=0) / 2.0, int(f.shape[0]))


def solve(stacks: list[DarkStack], k_sigma: float = 8.0, hot_factor: float = 5.0) -> DarkResult:
    """Dark-current and offset maps, read noise and hot pixels from ≥ 2 exposure times."""
    stacks = sorted(stacks, key=lambda s: s.exposure)
    t = np.array([s.exposure for s in stacks])
    if len(np.unique(t)) < 2:
        raise ConfigError("dark calibration needs frames at two or more different exposure times")
    shapes = {s.mean.shape for s in stacks}
    if len(shapes) != 1:
        raise ConfigError(f"dark frames differ in size: {sorted(shapes)}")
    w = np.array([s.n for s in stacks], float)  # weight each exposure's mean by its frame count
    tm = (w * t).sum() / w.sum()
    means = np.stack([s.mean for s in stacks])
    ym = np.tensordot(w, means, axes=1) / w.sum()
    sxx = (w * (t - tm) ** 2).sum()
    rate = np.tensordot(w * (t - tm), means - ym, axes=1) / sxx
    offset = ym - rate * tm
    med = np.median(rate)
    mad = 1.4826 * np.median(np.abs(rate - med))
    threshold = float(max(med + k_sigma * mad, hot_factor * med))
    normal = rate <= threshold
    mean_var = np.array([s.tvar[normal].mean() for s in stacks])
    a = np.column_stack([np.ones_like(t), t])
    coef, *_ = np.linalg.lstsq(a * w[:, None] ** 0.5, mean_var * w**0.5, rcond=None)
    read_noise = float(np.sqrt(max(coef[0], 0.0)))
    rows, cols = np.nonzero(rate > threshold)
    order = np.argsort(-rate[rows, cols])
    hot = np.column_stack([cols[order], rows[order]]).astype(np.int64)
    return DarkResult(rate, offset, np.sqrt(stacks[0].tvar), read_noise, hot, threshold, t,
                      np.array([s.n for s in stacks]))


def write_fits(path: Path, res: DarkResult, temperature_c: float | None = None) -> Path:
    """Save the products as FITS (see module docstring)."""
    from astropy.io import fits

    prim = fits.PrimaryHDU(res.rate.astype(np.float32))
    h = prim.header
    h["BUNIT"] = ("DN/s", "dark current")
    h["NEXPOS"] = (len(res.exposures), "number of exposure times")
    for i, (te, n) in enumerate(zip(res.exposures, res.frames)):
        h[f"EXPT{i}"] = (float(te), f"exposure {i} [s]")
        h[f"NFRM{i}"] = (int(n), f"frames at exposure {i}")
    h["RDNOISE"] = (res.read_noise, "read noise [DN]")
    h["DCMEDIAN"] = (res.rate_median, "median dark current [DN/s]")
    h["HOTTHR"] = (res.hot_threshold, "hot-pixel threshold [DN/s]")
    h["NHOT"] = (len(res.hot), "hot pixels")
    if temperature_c is not None:
        h["CCD-TEMP"] = (float(temperature_c), "sensor temperature [C]")
    h["ORIGIN"] = "gyrostar calibrate dark"
    off = fits.ImageHDU(res.offset.astype(np.float32), name="OFFSET")
    off.header["BUNIT"] = "DN"
    tn = fits.ImageHDU(res.tnoise.astype(np.float32), name="TNOISE")
    tn.header["BUNIT"] = "DN"
    tn.header["EXPTIME"] = (float(res.exposures[0]), "[s]")
    cols = fits.ColDefs([
        fits.Column(name="COLUMN", format="J", array=res.hot[:, 0]),
        fits.Column(name="ROW", format="J", array=res.hot[:, 1]),
        fits.Column(name="RATE", format="E", unit="DN/s", array=res.rate[res.hot[:, 1], res.hot[:, 0]]),
    ])
    hot = fits.BinTableHDU.from_columns(cols, name="HOTPIX")
    path = Path(path)
    fits.HDUList([prim, off, tn, hot]).writeto(path, overwrite=True)
    return path


def read_hot_pixels(path: Path) -> np.ndarray:
    """Hot-pixel list (K, 2) [column, row] from a dark FITS written by :func:`write_fits`."""
    from astropy.io import fits

    from ..files import check_regular

    check_regular(path, "dark FITS")
    try:
        with fits.open(path) as hdul:
            tab = hdul["HOTPIX"].data
            return np.column_stack([tab["COLUMN"], tab["ROW"]]).astype(np.int64)
    except (OSError, KeyError) as exc:
        raise ConfigError(f"{path} is not a gyrostar dark FITS with a HOTPIX table: {exc}") from exc


def load_frames(path: Path) -> list[DarkStack]:
    """Dark stacks from a folder of FITS frames (``EXPTIME`` header, s; grouped by it) or
    an ``.npz`` with ``frames`` (M, H, W) and ``exposure`` (M,) s."""
    path = Path(path)
    groups: dict[float, list[np.ndarray]] = {}
    if path.is_dir():
        from astropy.io import fits

        files = sorted(path.glob("*.fits")) + sorted(path.glob("*.fit"))
        if not files:
            raise ConfigError(f"no FITS frames in {path}")
        import warnings

        from ..files import check_regular

        for f in files:
            check_regular(f, f"INPUT {path}: frame")     # a FIFO named *.fits: refused, never opened
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")     # a corrupt file is reported below, in one line
                    with fits.open(f) as hdul:
                        head, data = hdul[0].header, hdul[0].data
                        if "EXPTIME" not in head:
                            raise ConfigError(f"INPUT {path}: {f.name} has no EXPTIME header")
                        if data is None or np.asarray(data).ndim != 2:
                            raise ConfigError(f"INPUT {path}: {f.name} holds no 2-D image in its primary HDU")
                        groups.setdefault(float(head["EXPTIME"]), []).append(np.array(data))
            except ConfigError:
                raise
            except (OSError, ValueError, TypeError, IndexError) as exc:
                raise ConfigError(f"INPUT {path}: {f.name} is not a readable FITS file ({exc})"[:300]) from exc
    elif path.suffix == ".npz":
        from .report import read_npz

        z = read_npz(path, ("frames", "exposure"))
        frames, exp = z["frames"], z["exposure"]
        if frames.ndim != 3:
            raise ConfigError(f"INPUT {path}: 'frames' must be (M, H, W), got shape {frames.shape}")
        if len(frames) != len(exp):
            raise ConfigError(f"{path}: {len(frames)} frames but {len(exp)} exposure times")
        for f, e in zip(frames, exp):
            groups.setdefault(float(e), []).append(f)
    else:
        raise ConfigError(f"dark input must be a folder of FITS frames or an .npz, got {path}")
    return [stack(np.stack(v), e) for e, v in sorted(groups.items())]
