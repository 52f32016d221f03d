"""Line-rate model of the head link: how long bytes take on the wire.

One model for every place that needs it: the simulated links pace bytes with it (a
simulation is never faster than the hardware), the loop budgets its windows with it, and
``gyrostar bench`` reports link utilisation with it.

A preset is a sustained payload rate (bytes/s after the transport's own overhead) plus a
per-transfer latency (s): the time from the sender's first byte to the receiver seeing any
of it, on top of the bytes' wire time.

* UART 8N1: 10 bits on the wire per payload byte (start + 8 data + stop); latency is one
  character time plus the receiver's FIFO/idle timeout (the host driver hands bytes up
  after about 2 character times of idle line, or when its FIFO fills).
* USB full-speed CDC-ACM (bulk): 12 Mbit/s raw, at most 19 × 64-byte packets per 1 ms
  frame (1.216 MB/s); a Linux host sustains about 0.9 MB/s. Bytes move in 1 ms frames,
  so a transfer waits up to one frame for the host's next IN token (0.5 ms on average; the
  model uses the full frame, never the kinder value).
* USB high-speed CDC-ACM (bulk): 480 Mbit/s raw, up to 13 × 512-byte packets per 125 µs
  microframe (53 MB/s); Linux hosts sustain 35–40 MB/s from a device that keeps up. The
  model takes 8 MB/s, what a Cortex-M7 head with an on-chip HS PHY (SAM V71 / its
  radiation-tolerant SAMV71Q21RT, STM32F723, i.MX RT1062) keeps up while it also packs
  pixels, and a whole 125 µs microframe of latency.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LinkPreset:
    """A head link: name, sustained payload bytes/s, per-transfer latency (s)."""

    name: str
    bytes_per_s: float
    latency_s: float
    description: str

    def wire_time(self, n_bytes: int) -> float:
        """Seconds from the first byte sent to the last byte received, for ``n_bytes``."""
        return self.latency_s + n_bytes / self.bytes_per_s

    def utilisation(self, bytes_per_frame: float, frame_hz: float) -> float:
        """Fraction of the link's sustained rate used by ``bytes_per_frame`` at ``frame_hz``."""
        return bytes_per_frame * frame_hz / self.bytes_per_s

    def max_frame_hz(self, bytes_per_frame: float, budget: float = 1.0) -> float:
        """Highest frame rate (Hz) whose traffic fits ``budget`` × the sustained rate."""
        return budget * self.bytes_per_s / max(bytes_per_frame, 1.0)


def _uart(name: str, baud: int, description: str) -> LinkPreset:
    byte_s = 10.0 / baud  # 8N1
    return LinkPreset(name, baud / 10.0, 3 * byte_s, description)


PRESETS: dict[str, LinkPreset] = {
    p.name: p
    for p in (
        _uart("uart-921k", 921_600, "UART 921.6 kBd 8N1 (92.16 kB/s)"),
        _uart("uart-3m", 3_000_000, "UART 3 MBd 8N1 (300 kB/s; short cable or RS-422)"),
        LinkPreset("usb-fs", 900_000.0, 1.0e-3,
                   "USB full-speed CDC-ACM bulk, 0.9 MB/s sustained, 1 ms frames"),
        LinkPreset("usb-hs", 8_000_000.0, 125e-6,
                   "USB high-speed CDC-ACM bulk, 8 MB/s sustained, 125 µs microframes"),
    )
}


def preset(name: str) -> LinkPreset:
    """The preset called ``name`` (``KeyError`` lists the known names)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown link preset {name!r}; known: {', '.join(PRESETS)}") from None


class Wire:
    """One direction of a link on the preset's timeline (times in s on any clock).

    ``transmit(n, t)``: ``n`` bytes handed to the transmitter at ``t`` go on the wire when it
    is free, at the sustained rate, and the receiver has the last of them ``latency_s``
    after their wire time ends; returns that delivery time. ``busy_until`` is when the
    transmitter is free again; ``queued_bytes(t)`` is what it still holds at ``t``.
    """

    def __init__(self, link: LinkPreset):
        self.link = link
        self.busy_until = float("-inf")
        self.bytes_sent = 0

    def transmit(self, n_bytes: int, t: float) -> float:
        start = max(t, self.busy_until)
        self.busy_until = start + n_bytes / self.link.bytes_per_s
        self.bytes_sent += n_bytes
        return self.busy_until + self.link.latency_s

    def queued_bytes(self, t: float) -> float:
        return max(0.0, (self.busy_until - t) * self.link.bytes_per_s)
