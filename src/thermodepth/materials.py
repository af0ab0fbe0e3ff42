"""A short table of surface materials and their long-wave (8-14 um) emissivity.

``material: NAME`` on an ROI sets its emissivity from here; an explicit ``emissivity:`` always
wins. Each value is one published in the emissivity tables of FLIR's camera manuals, which
compile them from the literature (the source of each is named in :data:`MATERIALS` and in
docs/thermography.md). A table value is a starting point: a surface's finish and oxidation
change it, and the reference-emitter method (``thermodepth emissivity``) measures it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """A material: its ``emissivity`` and where the value was published (``source``)."""

    emissivity: float
    source: str


_FLIR = "FLIR camera manuals' emissivity tables, after "
MATERIALS: dict[str, Material] = {
    "electrical-tape": Material(
        0.96, _FLIR + "ITC Technical publication 29 (3M Super 33+ black vinyl tape, LW, < 80 C)"
    ),
    "black-paint": Material(
        0.96, _FLIR + "ITC Technical publication 32 (Krylon Ultra-flat black 1602, LW, to 175 C)"
    ),
    "black-lacquer-matte": Material(
        0.97, _FLIR + "Wolfe & Zissis, The Infrared Handbook (black matte lacquer, 100 C)"
    ),
    "paint": Material(
        0.93,
        _FLIR + "Ohman, AGEMA E-Box report 1999 (8 colours and qualities, LW, 70 C: 0.92-0.94)",
    ),
    "anodised-aluminium-black": Material(
        0.95, _FLIR + "Ohman, AGEMA E-Box report 1999 (black, dull, LW, 70 C)"
    ),
    "oxidised-copper": Material(
        0.65, _FLIR + "Bramson, Infrared Radiation (oxidized copper, 50 C: 0.6-0.7)"
    ),
    "heavily-oxidised-copper": Material(
        0.78, _FLIR + "Wolfe & Zissis, The Infrared Handbook (heavily oxidized copper, 20 C)"
    ),
    "polished-copper": Material(
        0.03, _FLIR + "Wolfe & Zissis, The Infrared Handbook (polished copper, 100 C)"
    ),
    "galvanised-iron-oxidised": Material(
        0.85, _FLIR + "Ohman, AGEMA E-Box report 1999 (heavily oxidized galvanized iron, LW, 70 C)"
    ),
    "aluminium-foil": Material(
        0.04, _FLIR + "Madding, Thermographic Instruments and Systems (aluminium foil, 27 C)"
    ),
}
"""The material table (module docstring), by the name an ROI's ``material:`` gives."""
