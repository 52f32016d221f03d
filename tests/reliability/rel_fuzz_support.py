"""Shared pieces of the hypothesis campaign: case counter and campaign size."""

import os
from collections import Counter

CASES: Counter = Counter()


def fuzz_examples(default: int = 200) -> int:
    """Examples per property: ``GYROSTAR_FUZZ_EXAMPLES`` (``make fuzz``) or a small default."""
    return int(os.environ.get("GYROSTAR_FUZZ_EXAMPLES", default))
