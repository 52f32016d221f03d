"""Labels of identified stars: the catalog id, with the proper name of the brightest stars.

The ids are Hipparcos numbers (the flatsat's ``hip2`` catalog). Names are the IAU names of
the 30 brightest stars; any other star is labelled by its number alone.
"""

from __future__ import annotations

BRIGHT_STAR_NAMES: dict[int, str] = {
    32349: "Sirius", 30438: "Canopus", 69673: "Arcturus", 91262: "Vega", 24608: "Capella",
    24436: "Rigel", 37279: "Procyon", 27989: "Betelgeuse", 7588: "Achernar", 68702: "Hadar",
    97649: "Altair", 60718: "Acrux", 21421: "Aldebaran", 80763: "Antares", 65474: "Spica",
    37826: "Pollux", 113368: "Fomalhaut", 102098: "Deneb", 62434: "Mimosa", 49669: "Regulus",
    33579: "Adhara", 36850: "Castor", 85927: "Shaula", 61084: "Gacrux", 25336: "Bellatrix",
    25428: "Elnath", 45238: "Miaplacidus", 26311: "Alnilam", 109268: "Alnair", 11767: "Polaris",
}


def star_label(star_id: int) -> str:
    """``HIP n`` (and the name of a bright star), or ``?`` for a star the loop has not identified (−1)."""
    if star_id < 0:
        return "?"
    name = BRIGHT_STAR_NAMES.get(int(star_id))
    return f"HIP {int(star_id)}" + (f" {name}" if name else "")
