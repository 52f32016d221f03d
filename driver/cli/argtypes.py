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


def _interval(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def float_in(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, unit: str = ""):
    """An argparse type: a finite number in [``lo``, ``hi``] (an open end excludes its bound),
    ``unit`` named in the message."""
    where = _interval(lo, hi, lo_open, hi_open) + (f" {unit}" if unit else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects a number, got {text!r}") from None
        inside = lo < value if lo_open else lo <= value
        inside = inside and (value < hi if hi_open else value <= hi)
        if not math.isfinite(value) or not inside:
            raise argparse.ArgumentTypeError(f"must be a finite number in {where}, got {text!r}")
        return value

    parse.__name__ = f"number in {where}"
    return parse


def int_in(lo: int, hi: int):
    """An argparse type: an integer in [``lo``, ``hi``]."""
    at_least = int_at_least(lo)

    def parse(text: str) -> int:
        value = at_least(text)
        if value > hi:
            raise argparse.ArgumentTypeError(f"must be at most {hi}, got {text!r}")
        return value

    parse.__name__ = f"integer in [{lo}, {hi}]"
    return parse


def float_list_in(lo: float, hi: float, lo_open: bool = False, counts: tuple[int, ...] | None = None,
                  max_count: int = 64, unit: str = ""):
    """An argparse type: comma-separated finite numbers, each as :func:`float_in` checks it;
    as many as one of ``counts`` when given, else 1 … ``max_count``."""
    item = float_in(lo, hi, lo_open=lo_open, unit=unit)

    def parse(text: str) -> list[float]:
        items = [s.strip() for s in text.split(",")]
        if not text.strip() or any(not s for s in items):
            raise argparse.ArgumentTypeError(f"expects comma-separated numbers, got {text!r}")
        if counts is not None and len(items) not in counts:
            raise argparse.ArgumentTypeError(
                f"expects {' or '.join(str(c) for c in counts)} comma-separated numbers, got {text!r}")
        if len(items) > max_count:
            raise argparse.ArgumentTypeError(f"expects at most {max_count} numbers, got {len(items)} in {text!r}")
        return [item(s) for s in items]

    parse.__name__ = "comma-separated numbers"
    return parse


def existing_file(text: str):
    """An argparse type: the path of a file that exists (a folder or a missing path is refused)."""
    from pathlib import Path

    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text} does not exist")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text} is not a file")
    return path


def non_blank(text: str) -> str:
    """An argparse type: a name or path that is not empty or blank (``--scenario ""`` is a
    mistake, not a request for the default)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty (leave the flag out for the default)")
    return text
