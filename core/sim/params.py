"""Parameter descriptors with units, bounds, descriptions and sources, and one shared validator.

Every model parameter of the simulator (vehicle templates, effects) is a :class:`Param`; values
are checked against its bounds where they enter (:func:`check_value`) and a violation raises
:class:`railval.core.errors.InvalidParameter` naming the owner, the parameter, the bounds and the value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from railval.core.errors import InvalidParameter


@dataclass(frozen=True)
class Param:
    """One scalar model parameter.

    ``unit`` is the SI-derived unit the value is given in (as shown to users), ``lower``/
    ``upper`` the inclusive bounds, ``source`` where the default comes from. ``scale`` is
    ``"log"`` for parameters whose effect is roughly proportional to 1/value or spans decades
    (series stiffnesses, track stiffnesses): scan or search them on a logarithmic grid.
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    description: str
    source: str = ""
    scale: str = "linear"

    def to_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit, "default": self.default, "lower": self.lower,
                "upper": self.upper, "description": self.description, "source": self.source,
                "scale": self.scale}


def check_value(owner: str, p: Param, value) -> float:
    """Return ``value`` as float after checking it is finite and inside ``[p.lower, p.upper]``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidParameter(f"{owner}: parameter {p.name!r} must be a number in {p.unit}, "
                               f"got {value!r}") from None
    if not math.isfinite(v) or v < p.lower or v > p.upper:
        raise InvalidParameter(f"{owner}: parameter {p.name!r} = {value!r} {p.unit} is outside its "
                               f"bounds [{p.lower:g}, {p.upper:g}] {p.unit}")
    return v


def resolve(owner: str, params: tuple[Param, ...], given: dict | None) -> dict[str, float]:
    """Defaults overlaid by ``given`` (checked). Unknown names raise :class:`InvalidParameter`."""
    by_name = {p.name: p for p in params}
    out = {p.name: float(p.default) for p in params}
    for k, v in (given or {}).items():
        if k not in by_name:
            raise InvalidParameter(f"{owner}: unknown parameter {k!r}; known: {sorted(by_name)}")
        out[k] = check_value(owner, by_name[k], v)
    return out
