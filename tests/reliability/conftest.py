"""Case counting for the hypothesis campaign (``-m fuzz``): every property adds the cases
it ran; the total is printed and written to build/reliability/hypothesis_cases.json."""

import json
from pathlib import Path

import pytest
from rel_fuzz_support import CASES

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cases():
    return CASES


def pytest_terminal_summary(terminalreporter):
    if not CASES:
        return
    total = sum(CASES.values())
    terminalreporter.write_line(f"hypothesis campaign: {total} cases over {len(CASES)} properties")
    for name, n in sorted(CASES.items()):
        terminalreporter.write_line(f"  {name}: {n}")
    out = REPO / "build" / "reliability"
    out.mkdir(parents=True, exist_ok=True)
    (out / "hypothesis_cases.json").write_text(json.dumps({"total": total, "per_property": dict(CASES)},
                                                          indent=1))
