"""Where an evaluation writes its figures, checked when the command line is read (argparse
types): a bad ``--plot`` is refused before any computing, not after it."""

from __future__ import annotations

import argparse
from pathlib import Path


def png_file(text: str) -> str:
    """``--plot FILE.png``: a .png name in an existing folder, not a folder, and not some other
    existing file (a PNG of an earlier run is replaced)."""
    p = Path(text)
    if p.suffix.lower() != ".png":
        raise argparse.ArgumentTypeError(f"expects a .png file name, got {text!r}")
    _check_parent(p, text)
    if p.exists() and not p.is_file():
        raise argparse.ArgumentTypeError(f"{text!r} exists and is not a file")
    return text


def png_file_or_folder(text: str) -> str:
    """``--plot FILE.png`` (one figure) or ``--plot FOLDER`` (one PNG per figure; created if
    missing, inside an existing folder)."""
    p = Path(text)
    if p.suffix.lower() == ".png":
        return png_file(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} exists and is not a folder (give a folder or a .png name)")
    if p.suffix:
        raise argparse.ArgumentTypeError(f"expects a folder or a .png file name, got {text!r}")
    if not p.exists():
        _check_parent(p, text)
    return text


def _check_parent(p: Path, text: str) -> None:
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r}: the folder {str(parent)!r} does not exist")
