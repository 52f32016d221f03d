"""The docs state what the program does: the figures and tables a user reads there are checked
against the code that makes them."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_telemetry_column_table_is_the_export_schema():
    from gyrostar.telemetry.schema import COLUMNS

    text = (ROOT / "docs" / "TELEMETRY.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| (\w+) \| ([^|]+) \| ([^|]+) \|$", text, re.M)
    assert [r[0] for r in rows] == [c.name for c in COLUMNS]
    for (name, dtype, unit, desc), col in zip(rows, COLUMNS):
        assert (dtype, unit.strip(), desc.strip()) == (col.dtype, col.unit or "—", col.description), name


def test_flatsat_record_sizes_are_the_output_record():
    from gyrostar.loop.record import OUTPUT_DTYPE

    text = (ROOT / "docs" / "FLATSAT.md").read_text()
    stated = re.findall(r"record size \((\d+)", text) + re.findall(r"OUTPUT_DTYPE`, (\d+) bytes", text)
    assert len(stated) == 2 and {int(n) for n in stated} == {OUTPUT_DTYPE.itemsize}, stated


def test_readme_exit_codes_put_a_missing_device_under_3():
    text = " ".join((ROOT / "README.md").read_text().split())
    codes = text[text.index("Exit codes:"):]
    three, four = codes.index("3 device or link error"), codes.index("4 not available here")
    assert "missing" in codes[three:four] and "device" not in codes[four:codes.index("130 interrupted")]
