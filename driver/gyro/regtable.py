"""A gyro's configuration as one register table: (register, bits set, bits clear).

The same table configures the part (:func:`apply`: read-modify-write of the entries whose
bits differ, then :func:`verify` of every entry) and checks it in flight (the driver
re-reads one entry every few FIFO reads, :class:`RegisterCheck`): a part that reset
silently (brown-out, ESD, a glitch on its supply) shows up as an entry that no longer
holds, and is counted and reconfigured. Bits in neither mask are the part's own (status,
reserved, bits that read back differently) and are never looked at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class RegisterSetting:
    """Register ``reg`` must have every bit of ``set_bits`` set and every bit of ``clear_bits`` clear."""

    name: str
    reg: int
    set_bits: int
    clear_bits: int = 0

    def __post_init__(self):
        if self.set_bits & self.clear_bits:
            raise ValueError(f"{self.name}: bits 0x{self.set_bits & self.clear_bits:02X} both set and cleared")
        if not (0 <= self.reg <= 0x7F and 0 <= self.set_bits <= 0xFF and 0 <= self.clear_bits <= 0xFF):
            raise ValueError(f"{self.name}: register 0x{self.reg:X} or bits out of range")

    def holds(self, value: int) -> bool:
        return value & self.set_bits == self.set_bits and not value & self.clear_bits

    def applied(self, value: int) -> int:
        """``value`` with the entry's bits set and cleared."""
        return (value & ~self.clear_bits & 0xFF) | self.set_bits

    def describe(self, value: int) -> str:
        return (f"{self.name} (0x{self.reg:02X}) reads 0x{value:02X}, expected bits 0x{self.set_bits:02X} set "
                f"and 0x{self.clear_bits:02X} clear")


def apply(regs, table) -> None:
    """Set and clear every entry's bits, writing only the registers that differ."""
    for entry in table:
        old = regs.read(entry.reg, 1)[0]
        new = entry.applied(old)
        if new != old:
            regs.write(entry.reg, bytes([new]))


def verify(regs, table) -> list[str]:
    """One line per entry that does not hold (empty when the part is configured)."""
    bad = []
    for entry in table:
        value = regs.read(entry.reg, 1)[0]
        if not entry.holds(value):
            bad.append(entry.describe(value))
    return bad


class RegisterCheck:
    """Round-robin in-flight check. :meth:`due` turns true every ``every`` calls, but not
    sooner than ``min_interval_s`` after the last check (a loop polling at the full ODR pays
    one register read per ~10 frames, not per 4); :meth:`check_next` reads one entry and
    returns the mismatch text or None."""

    def __init__(self, table, every: int = 4, min_interval_s: float = 0.025):
        if every < 1:
            raise ValueError(f"register check interval must be >= 1 read, got {every}")
        self.table = tuple(table)
        self.every = every
        self.min_interval_s = min_interval_s
        self._calls = 0
        self._t_last = -math.inf
        self._pos = 0

    def due(self, now: float) -> bool:
        """``now``: host time (s) of the read."""
        self._calls += 1
        if not self.table or self._calls < self.every or now - self._t_last < self.min_interval_s:
            return False
        self._calls = 0
        self._t_last = now
        return True

    def check_next(self, regs) -> str | None:
        entry = self.table[self._pos]
        self._pos = (self._pos + 1) % len(self.table)
        value = regs.read(entry.reg, 1)[0]
        return None if entry.holds(value) else entry.describe(value)
