"""``gyrostar sim pixels FRAME --sensor FILE``: load one frame into the firmware host's pixel file.

The firmware's host program (``gyrostar fw host --sensor FILE``) and its QEMU image read their
sensor from a GSPX pixel file (firmware/README.md); ``gyrostar fw spots`` then lists what the
firmware finds in it. FRAME is a ``.fits`` image (what ``gyrostar sim frame`` writes, or a real
sensor's frame) or a ``.npy`` array: 10-bit ADU (0 … 1023), the sensor's size. An existing file
is rewritten in place under its sequence lock (the host program keeps it mapped: it is never
replaced); a missing one is created with the frame's size and ``--planes`` (the dark plane zero).
"""

from __future__ import annotations

from pathlib import Path

from gyrostar.cli.main import add_json
from gyrostar.errors import ConfigError

HELP = "load a frame (FITS or .npy) into the firmware host's GSPX pixel file, for fw spots"
MAX_ADU = 1023                # the pixel file holds 10-bit pixels


def configure(parser) -> None:
    parser.add_argument("frame", metavar="FRAME", help="image: .fits (gyrostar sim frame) or .npy, ADU")
    parser.add_argument("--sensor", required=True, metavar="FILE",
                        help="GSPX pixel file of gyrostar fw host (rewritten in place; created if missing)")
    parser.add_argument("--planes", type=int, choices=(1, 2), default=2,
                        help="planes of a file created here: 1 = light, 2 = light + dark (default 2, as fw host)")
    add_json(parser)


def read_frame(path: Path):
    """The image of ``path`` as a 2-D array (the FITS primary HDU, or the array)."""
    import numpy as np

    suffix = path.suffix.lower()
    try:
        if suffix in (".fits", ".fit", ".fts"):
            from astropy.io import fits

            with fits.open(path, memmap=False) as hdul:
                img = hdul[0].data
        elif suffix == ".npy":
            img = np.load(path, allow_pickle=False)
        else:
            raise ConfigError(f"FRAME {path}: give a .fits or .npy image")
    except ConfigError:
        raise
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"FRAME {path}: not a readable image ({exc})") from None
    if img is None or np.ndim(img) != 2:
        raise ConfigError(f"FRAME {path}: a 2-D image is needed, got shape {np.shape(img)}")
    img = np.asarray(img)
    if img.dtype.kind not in "uif" or not np.all(np.isfinite(img)):
        raise ConfigError(f"FRAME {path}: pixels must be finite numbers")
    if img.min() < 0 or img.max() > MAX_ADU or not np.array_equal(img, np.round(img)):
        raise ConfigError(f"FRAME {path}: pixels must be whole ADU in 0 … {MAX_ADU} (10 bits); "
                          f"they span {img.min():g} … {img.max():g}")
    return img.astype(np.uint16)


def run(args) -> int:
    from gyrostar.cli.output import emit

    from .firmware_host import PixelFile

    frame, sensor = Path(args.frame), Path(args.sensor)
    if not frame.is_file():
        raise ConfigError(f"FRAME {frame} " + ("is not a file" if frame.exists() else "does not exist"))
    if sensor.is_dir() or not sensor.parent.is_dir():
        raise ConfigError(f"--sensor {sensor}: " + ("is a folder: give the pixel file's path" if sensor.is_dir()
                                                     else f"folder {sensor.parent} does not exist"))
    img = read_frame(frame)
    h, w = img.shape
    created = not sensor.exists()
    if created:
        if not (1 <= w <= 65535 and 1 <= h <= 65535):
            raise ConfigError(f"FRAME {frame}: {w}×{h} pixels, more than a pixel file holds (65535 a side)")
        pix = PixelFile(sensor, w, h, planes=args.planes)
    else:
        if not sensor.is_file():
            raise ConfigError(f"--sensor {sensor} is not a regular file")
        try:
            pix = PixelFile.attach(sensor)
        except ValueError as exc:
            raise ConfigError(f"--sensor {exc}") from None
        if (pix.width, pix.height) != (w, h):
            pix.close()
            raise ConfigError(f"FRAME {frame} is {w}×{h} pixels, the pixel file {sensor} {pix.width}×{pix.height}")
    try:
        counter = pix.write_frame(img)
    finally:
        pix.close()
    res = {"sensor": str(sensor), "frame": str(frame), "width": w, "height": h, "frame_counter": counter,
           "created": created, "max_adu": int(img.max())}
    emit(args, res, f"{'created' if created else 'updated'} {sensor}: frame {counter} ({w}×{h}, max {img.max()} ADU) "
                    f"from {frame}; gyrostar fw spots PORT lists what the firmware finds in it")
    return 0
