"""argparse value types that reject what a command cannot use, at parse time (exit 2,
one line naming the flag): ``--duration 0``, ``nan``, ``inf``, ``--frames 0`` ..."""

from __future__ import annotations

import argparse
import math


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def int_at_least(minimum: int):
    """An argparse type: an integer ≥ ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text!r}")
        return value

    parse.__name__ = f"integer ≥ {minimum}"
    return parse


positive_int = int_at_least(1)

SEED_MAX = 2**32 - 1


def seed(text: str) -> int:
    """A random seed: an integer in [0, 2³² − 1] (what every generator of the simulator takes)."""
    value = int_at_least(0)(text)
    if value > SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be at most {SEED_MAX}, got {text!r}")
    return value


def run_seconds(text: str) -> float:
    """A run length: a finite number of seconds ≥ ``MIN_RUN_S`` (a run shorter than its first
    identification has no figures)."""
    value = positive_float(text)
    if value < MIN_RUN_S:
        raise argparse.ArgumentTypeError(f"must be at least {MIN_RUN_S:g} s, got {text!r}")
    return value


MIN_RUN_S = 1.0


def positive_float_list(text: str) -> list[float]:
    """Comma-separated finite numbers > 0 (at least one)."""
    items = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in items):
        raise argparse.ArgumentTypeError(f"expects comma-separated numbers > 0, got {text!r}")
    return [positive_float(s) for s in items]
