"""Image files → one luminance array per frame (float32, [row, column], pixel values as stored).

Formats, by file suffix:

* FITS (``.fits .fit .fts``, optionally ``.gz``; astropy): the first HDU with 2-D data (or a
  3-D cube of 3 colour planes, read as colour), BZERO/BSCALE applied. ``gyrostar sim frame``
  writes these (10-bit ADU in uint16).
* TIFF (``.tif .tiff``; tifffile): 8/16-bit integer or float, grey or RGB(A).
* PNG, JPEG, BMP (pillow): grey, 16-bit grey (``I;16``) or RGB(A).
* The head's full-frame dump: ``.npy`` (one 2-D array, as ``HeadClient.full_frame`` returns)
  or ``.npz`` holding ``frames`` (k, h, w) (what ``calibrate dark`` keeps) or ``image`` (h, w);
  each frame of ``frames`` is one image (``name#i``).

Colour → luminance with the Rec. 709 weights 0.2126 R + 0.7152 G + 0.0722 B (alpha dropped).
``saturation`` is the largest value the file's pixel type holds (2^bits − 1 for integers; for
uint16 data that never exceed 1023/4095/16383 — a 10/12/14-bit sensor in a 16-bit container —
that smaller full scale), or None for float data.

Every unreadable or malformed file raises :class:`~gyrostar.errors.ConfigError` naming it
(exit 2).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..errors import ConfigError

FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fits.gz", ".fit.gz", ".fts.gz")
TIFF_SUFFIXES = (".tif", ".tiff")
PILLOW_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
DUMP_SUFFIXES = (".npy", ".npz")
IMAGE_SUFFIXES = FITS_SUFFIXES + TIFF_SUFFIXES + PILLOW_SUFFIXES + DUMP_SUFFIXES
LUMA = np.array([0.2126, 0.7152, 0.0722])    # Rec. 709 luminance weights of R, G, B
MIN_SIDE_PX = 16                             # smaller images cannot hold a star field


@dataclasses.dataclass(frozen=True)
class Frame:
    """One image: ``name`` (file, or ``file#i`` for a stack), ``pixels`` (h, w) float32 luminance,
    ``saturation`` full-scale value (None: unknown), ``colour`` (read from colour planes)."""

    name: str
    pixels: np.ndarray
    saturation: float | None
    colour: bool = False

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])


def suffix_of(path: Path) -> str:
    name = path.name.lower()
    for s in IMAGE_SUFFIXES:
        if name.endswith(s):
            return s
    return path.suffix.lower()


def is_image(path: Path) -> bool:
    return suffix_of(path) in IMAGE_SUFFIXES


def expand_paths(paths) -> list[Path]:
    """Files named plus the image files inside named folders (sorted, not recursive).
    A missing path, or a folder with no image file, raises ConfigError."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and is_image(f))
            if not found:
                raise ConfigError(f"{p}: folder holds no image file ({', '.join(IMAGE_SUFFIXES)})")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise ConfigError(f"{p}: no such file or folder")
    return out


def read_frames(path) -> list[Frame]:
    """The frames of one image file (see the module docstring)."""
    path = Path(path)
    kind = suffix_of(path)
    if kind not in IMAGE_SUFFIXES:
        raise ConfigError(f"{path}: not an image file this reads ({', '.join(IMAGE_SUFFIXES)})")
    import logging
    import warnings

    tiff_log = logging.getLogger("tifffile")
    level = tiff_log.level
    try:
        tiff_log.setLevel(logging.CRITICAL)       # a corrupt file is our one line, not its warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arrays = _read_arrays(path, kind)
        for a in arrays:
            if np.asarray(a).ndim not in (2, 3) or np.asarray(a).size == 0:
                raise ValueError(f"no image data (array of shape {np.shape(a)})")
    except ConfigError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, RuntimeError, MemoryError) as exc:
        if isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError)):
            raise ConfigError(f"{path}: {exc.strerror or exc}") from None
        raise ConfigError(f"{path}: not a readable {kind[1:].upper()} image ({type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else 'corrupt data'})") from None
    finally:
        tiff_log.setLevel(level)
    frames = []
    for i, arr in enumerate(arrays):
        name = str(path) if len(arrays) == 1 else f"{path}#{i}"
        frames.append(to_frame(name, np.asarray(arr)))
    return frames


def _read_arrays(path: Path, kind: str) -> list[np.ndarray]:
    if kind in FITS_SUFFIXES:
        return [_read_fits(path)]
    if kind in TIFF_SUFFIXES:
        import tifffile

        return [tifffile.imread(path)]
    if kind in PILLOW_SUFFIXES:
        return [_read_pillow(path)]
    return _read_dump(path)


def to_frame(name: str, arr: np.ndarray) -> Frame:
    """Luminance frame from a 2-D grey or 3-D colour (h, w, 3|4) / (3, h, w) array."""
    colour = False
    if arr.ndim == 3 and arr.shape[0] in (3, 4) and arr.shape[2] not in (3, 4):
        arr = np.moveaxis(arr, 0, -1)
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        colour = True
        sat = _saturation(arr[..., :3])
        lum = np.tensordot(arr[..., :3].astype(np.float64), LUMA, axes=([2], [0]))
        pixels = lum.astype(np.float32)
    elif arr.ndim == 2:
        sat = _saturation(arr)
        pixels = arr.astype(np.float32)
    else:
        raise ConfigError(f"{name}: image of shape {arr.shape} is neither grey (h, w) nor colour (h, w, 3)")
    if min(pixels.shape) < MIN_SIDE_PX:
        raise ConfigError(f"{name}: image of {pixels.shape[1]}x{pixels.shape[0]} px is too small for a star field")
    if not np.all(np.isfinite(pixels)):
        pixels = np.where(np.isfinite(pixels), pixels, np.float32(np.nanmedian(pixels) if np.isfinite(pixels).any()
                                                                  else 0.0))
    return Frame(name, np.ascontiguousarray(pixels), sat, colour)


def _saturation(arr: np.ndarray) -> float | None:
    if arr.dtype.kind == "b":
        return 1.0
    if arr.dtype.kind not in "ui":
        return None
    full = float(np.iinfo(arr.dtype).max)
    if arr.dtype.itemsize >= 2 and arr.size:
        top = float(arr.max())
        for bits in (10, 12, 14):          # a narrower ADC in a 16-bit container
            if top <= 2 ** bits - 1:
                return float(2 ** bits - 1)
    return full


def _read_fits(path: Path) -> np.ndarray:
    from astropy.io import fits

    with fits.open(path, memmap=False) as hdul:
        for hdu in hdul:
            data = getattr(hdu, "data", None)
            if data is None or not hasattr(data, "ndim") or data.dtype.names is not None:
                continue
            if data.ndim == 2 or (data.ndim == 3 and data.shape[0] in (3, 4)):
                return np.array(data)
    raise ConfigError(f"{path}: FITS file holds no 2-D image")


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            im.load()
            if im.mode in ("P", "PA", "LA", "CMYK", "YCbCr", "HSV", "LAB", "1"):
                im = im.convert("RGB" if im.mode not in ("LA", "1") else "L")
            if im.mode in ("I;16", "I;16B", "I;16L"):
                return np.array(im, dtype=np.uint16)
            return np.array(im)
    except UnidentifiedImageError:
        raise ConfigError(f"{path}: not a readable {path.suffix[1:].upper()} image (unknown or corrupt data)") from None


def _read_dump(path: Path) -> list[np.ndarray]:
    if path.suffix.lower() == ".npy":
        return [np.load(path, allow_pickle=False)]
    with np.load(path, allow_pickle=False) as z:
        if "frames" in z.files:
            frames = z["frames"]
            if frames.ndim != 3 or len(frames) == 0:
                raise ConfigError(f"{path}: 'frames' must be a (k, h, w) stack of frames, got shape {frames.shape}")
            return list(frames)
        if "image" in z.files:
            return [z["image"]]
    raise ConfigError(f"{path}: .npz holds neither 'frames' (k, h, w) nor 'image' (h, w)")
