"""Annotated PNG of a solved (or unsolved) image: the frame with a square-root stretch, every
spot the solver took (yellow circle), identified stars (green circle, catalog id and the IAU
name of a named star), unmatched spots (red ×), spots left out by their flag (grey square:
hot, extended…), and a title with the solution."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .detect import FLAG_EXTENDED, FLAG_HOT


def write_png(path: Path, pixels: np.ndarray, res, names: dict[int, str], credit: str | None = None) -> None:
    from matplotlib.figure import Figure

    h, w = pixels.shape
    lo, hi = np.percentile(pixels[:: max(1, h // 256), :: max(1, w // 256)], [1.0, 99.8])
    img = np.sqrt(np.clip((pixels - lo) / max(hi - lo, 1e-9), 0.0, 1.0))
    dpi = 100
    fig = Figure(figsize=(max(6.0, w / dpi), max(4.5, h / dpi) + 0.6), dpi=dpi)
    ax = fig.add_axes((0, 0, 1, h / (h + 0.6 * dpi)))
    ax.imshow(img, cmap="gray", origin="upper", interpolation="nearest", extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    ax.set_axis_off()
    det = res.detection
    flags = det.flags
    left_out = np.flatnonzero((flags & (FLAG_HOT | FLAG_EXTENDED)) != 0)
    if len(left_out):
        ax.scatter(det.spots[left_out, 0], det.spots[left_out, 1], s=60, marker="s", facecolors="none",
                   edgecolors="0.6", linewidths=0.8)
    s = res.solution
    xy = res.xy
    match = s.match if len(s.match) == len(xy) else np.full(len(xy), -1)
    ok = match >= 0
    if (~ok).any():
        ax.scatter(xy[~ok, 0], xy[~ok, 1], s=40, marker="x", c="red", linewidths=0.9)
    if ok.any():
        ax.scatter(xy[ok, 0], xy[ok, 1], s=120, marker="o", facecolors="none", edgecolors="lime", linewidths=1.0)
        for (u, v), cid in zip(xy[ok], match[ok]):
            label = f"{int(cid)}" + (f" {names[int(cid)]}" if int(cid) in names else "")
            ax.annotate(label, (u, v), xytext=(6, -6), textcoords="offset points", color="lime", fontsize=7)
    if s.solved:
        title = (f"{Path(res.name).name}: RA {s.ra_deg:.4f}° Dec {s.dec_deg:+.4f}° roll {s.roll_deg:.2f}° "
                 f"FOV {s.fov_deg:.3f}° — {s.stars_matched} stars, {s.residual_arcsec_rms:.1f}\" RMS")
    else:
        title = f"{Path(res.name).name}: not solved ({s.status}); {len(xy)} spots"
    fig.text(0.01, 1 - 0.3 * dpi / (h + 0.6 * dpi), title, fontsize=9, va="center")
    if credit:
        fig.text(0.99, 0.01, credit, fontsize=6, color="0.8", ha="right", va="bottom")
    fig.savefig(path, dpi=dpi)
