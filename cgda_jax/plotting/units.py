"""Units of the features, for axis labels: ``"X [m]"``, ``"painted [%]"``.

A feature name may carry its unit in brackets (``"box.x [m]"``, as the object scenes
name theirs); the tables below give the units of the names that do not, per source.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

__all__ = [
    "ARM_UNITS",
    "MARKER_UNITS",
    "SIM_UNITS",
    "XGNITIVE_UNITS",
    "common_unit",
    "label",
    "split_unit",
    "with_units",
]

#: The simulated scenes: marker position in the robot's root frame (m), painted
#: share of the wall (%).
SIM_UNITS: dict[str, str] = {"X": "m", "Y": "m", "Z": "m", "painted": "%"}

#: The synthetic Kinect marker features (`cgda_jax.datasets.synthetic_actions`).
MARKER_UNITS: dict[str, str] = {
    "X": "mm", "Y": "mm", "Z": "mm", "area": "px", "hue": "OpenCV, 0-180",
    "saturation": "0-255", "value": "0-255", "angle": "deg",
}

#: The demonstrator's arm points (``hand_x`` ...): metres.
ARM_UNITS: dict[str, str] = {
    f"{p}_{c}": "m" for p in ("hand", "wrist", "elbow", "shoulder") for c in "xyz"
}

#: The real TEO logs (codebook of /work/shared/data/xgnitive): TCP position in m,
#: axis-angle orientation (unit axis, angle in degrees), wrist force in N and torque
#: in N m, painted share of the screen in %.
XGNITIVE_UNITS: dict[str, str] = {
    "X": "m", "Y": "m", "Z": "m", "ax": "unit axis", "ay": "unit axis",
    "az": "unit axis", "angle": "deg", "Fx": "N", "Fy": "N", "Fz": "N",
    "Tx": "N m", "Ty": "N m", "Tz": "N m", "percent": "%",
}

_BRACKET = re.compile(r"^(.*?)\s*\[([^\[\]]+)\]\s*$")


def split_unit(name: str) -> tuple[str, str | None]:
    """``"box.x [m]"`` -> ``("box.x", "m")``; ``"X"`` -> ``("X", None)``."""
    m = _BRACKET.match(str(name))
    return (m.group(1), m.group(2)) if m else (str(name), None)


def label(name: str, unit: str | None = None) -> str:
    """``name [unit]``; a name that already carries a unit keeps it."""
    base, own = split_unit(name)
    unit = own or unit
    return f"{base} [{unit}]" if unit else base


def with_units(names: Sequence[str], table: Mapping[str, str]) -> tuple[str, ...]:
    """Every name labelled with its unit from ``table`` (or the one it carries)."""
    return tuple(label(n, table.get(split_unit(n)[0])) for n in names)


def common_unit(names: Sequence[str]) -> str | None:
    """The unit all ``names`` share (the unit of a distance between points of these
    features), or None when they differ or one has none."""
    units = {split_unit(n)[1] for n in names}
    return units.pop() if len(units) == 1 else None
