"""The shipped IAU star-name table against the Hipparcos catalog (independent truth: the
catalog's position and V of the star the table's HIP number names)."""

import math

import numpy as np
from gyrostar.catalog import load_catalog
from gyrostar.imaging.star_names import star_names, star_table


def test_every_name_points_at_the_catalog_star_it_claims():
    cat = load_catalog("hip2", 7.0)
    index = {int(i): k for k, i in enumerate(cat.ids)}
    bad = []
    for row in star_table():
        k = index.get(row["hip"])
        if k is None:
            bad.append((row["name"], "not in the catalog to V 7"))
            continue
        x, y, z = cat.vectors[k]
        ra, dec = math.degrees(math.atan2(y, x)) % 360.0, math.degrees(math.asin(z))
        ref = np.array([math.cos(math.radians(row["dec_deg"])) * math.cos(math.radians(row["ra_deg"])),
                        math.cos(math.radians(row["dec_deg"])) * math.sin(math.radians(row["ra_deg"])),
                        math.sin(math.radians(row["dec_deg"]))])
        sep = math.degrees(math.acos(min(1.0, float(ref @ cat.vectors[k]))))
        if sep > 0.2 or abs(cat.vmag[k] - row["vmag"]) > 0.4:
            bad.append((row["name"], round(ra, 2), round(dec, 2), round(float(cat.vmag[k]), 2), round(sep, 3)))
    assert not bad, bad


def test_names_unique():
    rows = star_table()
    assert len({r["hip"] for r in rows}) == len(rows) == len(star_names())
    assert len({r["name"] for r in rows}) == len(rows)
