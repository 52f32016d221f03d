"""Bytes on the head link: a counting link wrapper and the windowed-vs-full-frame measurement.

:class:`CountingLink` wraps a packet link (``send(bytes)``, ``recv(timeout)``) and counts
the bytes that actually cross it: every byte written, and every received packet plus its
0x00 delimiter. :func:`star_trajectory_windows` builds the windows of N stars moving at a
given body rate over one exposure (paper 000's union of k×k squares along the trajectory,
via :func:`gyrostar.core.windows.trajectory_window`), and :func:`measure_capture_bytes`
compares the link bytes of one windowed capture with those of one full-frame readout.
"""

from __future__ import annotations

import math

import numpy as np


class CountingLink:
    """Pass-through link that counts bytes in both directions (``tx``, ``rx``)."""

    def __init__(self, link):
        self.link = link
        self.url = getattr(link, "url", "?")
        self.tx = 0
        self.rx = 0

    def send(self, data: bytes) -> float:
        self.tx += len(data)
        return self.link.send(data)

    def recv(self, timeout: float):
        got = self.link.recv(timeout)
        if got is not None and got[1] is not None:
            self.rx += len(got[1]) + 1  # the packet and its delimiter
        return got

    def __getattr__(self, name):
        return getattr(self.link, name)

    @property
    def total(self) -> int:
        return self.tx + self.rx

    def reset(self) -> None:
        self.tx = self.rx = 0


def smear_px(rate_dps: float, exposure_s: float, focal_mm: float, pitch_um: float) -> float:
    """Image-plane path length (px) of a star during one exposure at a cross-boresight rate."""
    return focal_mm * 1e-3 * math.radians(rate_dps) * exposure_s / (pitch_um * 1e-6)


def star_trajectory_windows(n_stars: int = 10, rate_dps: float = 5.0, exposure_s: float = 0.010,
                            focal_mm: float = 100.0, pitch_um: float = 15.0, width: int = 1024,
                            height: int = 1024, k: int = 6, seed: int = 0) -> tuple[np.ndarray, float]:
    """Span table (N×4 int32) of ``n_stars`` trajectory windows, and the smear length (px).

    The body rate is ``rate_dps`` about an axis in the x–y plane (random azimuth); to first
    order every star then moves by ``(-ω_y, ω_x)·F·t`` in (column, row) over the exposure
    (``docs/ARCHITECTURE.md``). Star positions are uniform on the sensor, 20 px from its edges.
    """
    from ..core.windows import concat_windows, trajectory_window

    rng = np.random.default_rng(seed)
    az = rng.uniform(0, 2 * np.pi)
    w = np.radians(rate_dps) * np.array([np.cos(az), np.sin(az)])  # (ω_x, ω_y) rad/s
    f_px = focal_mm * 1e-3 / (pitch_um * 1e-6)
    vel = np.array([-w[1], w[0]]) * f_px  # (du/dt, dv/dt) px/s
    steps = np.linspace(0.0, exposure_s, 33)
    parts = []
    for sid in range(n_stars):
        u0, v0 = rng.uniform(20, width - 20), rng.uniform(20, height - 20)
        traj = np.stack([u0 + vel[0] * steps, v0 + vel[1] * steps], axis=1)
        parts.append(trajectory_window(traj, k, height, width, sid))
    return concat_windows(parts), float(np.hypot(*vel) * exposure_s)


def measure_capture_bytes(client, link: CountingLink, spans: np.ndarray, pixel_format: int) -> dict:
    """Link bytes of one windowed capture (SET_WINDOWS + CAPTURE + WINDOW_DATA) and of one
    full-frame readout (all FULL_FRAME chunks), both directions, in ``pixel_format``."""
    client.sync(2)  # so the capture does not trigger a clock exchange inside the measurement
    link.reset()
    client.set_windows(spans)
    cap = client.capture(fetch=True, pixel_format=pixel_format)
    windowed = link.total
    link.reset()
    image, _ = client.full_frame(pixel_format=pixel_format)
    full = link.total
    return {"windowed_bytes": windowed, "full_frame_bytes": full, "ratio": windowed / full,
            "n_windows": cap.n_windows, "n_pixels": cap.n_pixels, "image": image, "capture": cap}
