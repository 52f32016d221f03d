"""What the head link can carry per frame, and how the loop degrades when it cannot.

Per streamed frame the head sends one FRAME message (fixed part + per window an 8-byte
header and its pixels, PACKED10 = 10 bits each) and the loop sends one SET_WINDOWS (8 bytes
per row span); each is framed (6-byte header, CRC-32C, COBS, delimiter). Each direction may
use ``target`` (0.8) of the link's sustained rate (:mod:`gyrostar.transport.linkrate`), so
the head never builds a backlog and time-sync exchanges still get through.

Degrading, in this order (``LinkBudget.plan`` / ``after_plan``):
1. fewer stars — the windows of the faintest stars are left out when the pixel or span
   budget of the frame runs out (``plan_windows`` takes them brightest first);
2. tighter windows — the prediction-uncertainty margin is dropped (k = window_k) while
   stars are being left out;
3. a lower frame rate — when even tight windows leave fewer than ``min_stars`` stars for
   ``patience`` frames, the frame period grows by a whole period (100 → 50 → 33 … Hz);
   it shrinks back when the windows would fit the faster rate with 30 % to spare.
"""

from __future__ import annotations

import struct

from ..protocol.defs import REPLY_LAYOUT, REQUEST_LAYOUT, MsgType

FRAMING = 6 + 4 + 2            # header, CRC-32C, COBS code byte + delimiter (plus 1 per 254 B)
FRAME_FIXED = struct.calcsize("<" + REPLY_LAYOUT[MsgType.FRAME][0])
SET_WINDOWS_FIXED = struct.calcsize("<" + REQUEST_LAYOUT[MsgType.SET_WINDOWS][0])
WIN_HEADER = 8
SPAN_BYTES = 8


def _framed(payload: int) -> int:
    return payload + FRAMING + payload // 254


def frame_bytes(n_pixels: int, n_windows: int) -> int:
    """Bytes on the wire of one streamed frame (PACKED10), head → host."""
    return _framed(FRAME_FIXED + WIN_HEADER * n_windows + (10 * n_pixels + 7) // 8 + n_windows)


def windows_bytes(n_spans: int) -> int:
    """Bytes on the wire of one SET_WINDOWS, host → head."""
    return _framed(SET_WINDOWS_FIXED + SPAN_BYTES * n_spans)


def time_sync_bytes() -> int:
    """Bytes on the wire of one TIME_SYNC exchange: the request up plus the reply down."""
    return (_framed(struct.calcsize("<" + REQUEST_LAYOUT[MsgType.TIME_SYNC][0]))
            + _framed(struct.calcsize("<" + REPLY_LAYOUT[MsgType.TIME_SYNC][0])))


class LinkBudget:
    """Per-frame budgets for ``link`` (a LinkPreset) at ``frame_hz`` and the degrade state."""

    def __init__(self, link, frame_hz: float, target: float = 0.8, min_stars: int = 4, patience: int = 10,
                 max_divisor: int = 10):
        self.link = link
        self.base_hz = frame_hz
        self.target = target
        self.min_stars = min_stars
        self.patience = patience
        self.max_divisor = max_divisor
        self.divisor = 1                   # frame period = divisor / base_hz
        self.short = 0                     # consecutive frames with too few stars even when tight
        self.roomy = 0                     # consecutive frames that would fit the faster rate
        self.tight = False
        self.frames_cut = 0                # frames planned with stars left out for the link
        self.frames_tight = 0              # frames planned with tightened windows
        self.rate_changes: list = []       # (t, frame_hz)

    @property
    def frame_hz(self) -> float:
        return self.base_hz / self.divisor

    def _bytes_per_frame(self, hz: float) -> float:
        return self.target * self.link.bytes_per_s / hz

    def limits(self, n_stars: int, hz: float | None = None) -> tuple[int, int]:
        """(pixel budget, span budget) of one frame for ``n_stars`` windows at ``hz``."""
        b = self._bytes_per_frame(hz or self.frame_hz)
        down = b - _framed(FRAME_FIXED) - (WIN_HEADER + 1) * n_stars
        pixels = max(0, int(down * 8 / 10))
        spans = max(0, int((b - _framed(SET_WINDOWS_FIXED)) / (SPAN_BYTES * 1.004)))
        return pixels, spans

    def margin_allowed(self) -> bool:
        """False while windows are tightened (no uncertainty margin)."""
        return not self.tight

    def after_plan(self, t: float, n_active: int, n_planned: int, n_pixels: int, n_spans: int) -> int | None:
        """Account for a planned frame; returns a new frame-rate divisor when the rate changes.
        Stars count as cut for the link only when the frame's budget was (nearly) used up —
        above 80 %, or with less left than a window of the frame's mean size (at 10 °/s on a
        UART two smeared windows of ~195 px took 74 % of 524 px: a third did not fit) — a
        star off the sensor is not the link's doing."""
        px, sp = self.limits(n_planned)
        mean_window = n_pixels / n_planned if n_planned else float(px)
        cut = n_planned < n_active and (n_pixels > 0.8 * px or n_spans > 0.8 * sp or px - n_pixels < mean_window)
        if cut:
            self.frames_cut += 1
        if self.tight:
            self.frames_tight += 1
        self.tight = cut
        want = min(self.min_stars, n_active)
        if cut and self.tight and n_planned < want:
            self.short += 1
        else:
            self.short = 0
        if self.short >= self.patience and self.divisor < self.max_divisor:
            return self._change(t, self.divisor + 1)
        # room to go faster: this frame's windows would fit the faster rate's budget with 30 % spare
        if self.divisor > 1 and not cut:
            faster = self.base_hz / (self.divisor - 1)
            px, sp = self.limits(n_planned, faster)
            fits = n_pixels <= 0.7 * px and n_spans <= 0.7 * sp
            self.roomy = self.roomy + 1 if fits else 0
            if self.roomy >= 2 * self.patience:
                return self._change(t, self.divisor - 1)
        return None

    def _change(self, t: float, divisor: int) -> int:
        self.divisor = divisor
        self.short = self.roomy = 0
        self.rate_changes.append((round(float(t), 3), round(self.frame_hz, 2)))
        return divisor

    def summary(self) -> dict:
        return {"preset": self.link.name, "frame_hz_now": self.frame_hz, "frames_stars_cut": self.frames_cut,
                "frames_windows_tightened": self.frames_tight, "rate_changes": list(self.rate_changes),
                "target_utilisation": self.target}

