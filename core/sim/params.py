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

    ``plausible`` is the physically plausible range of the value for a real vehicle/track (inside
    ``[lower, upper]``; the bounds are the wider search/validation range), ``plausible_source``
    where that range comes from (literature, standard clause, or "assumption: …" when it is an
    engineering estimate of this simulator). Diagnosis uses it to flag fitted values outside
    what vehicles have (:func:`plausibility`).
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    description: str
    source: str = ""
    scale: str = "linear"
    plausible: tuple[float, float] | None = None
    plausible_source: str = ""

    def __post_init__(self):
        if self.plausible is not None:
            lo, hi = self.plausible
            if not (self.lower <= lo <= hi <= self.upper):
                raise ValueError(f"parameter {self.name!r}: plausible range {self.plausible} must lie "
                                 f"inside the bounds [{self.lower}, {self.upper}]")

    @property
    def plausible_range(self) -> tuple[float, float]:
        """The plausible range, or the bounds when none is given."""
        return self.plausible if self.plausible is not None else (self.lower, self.upper)

    def is_plausible(self, value: float) -> bool:
        """True when ``value`` lies inside the plausible range (inclusive)."""
        lo, hi = self.plausible_range
        return lo <= float(value) <= hi

    def to_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit, "default": self.default, "lower": self.lower,
                "upper": self.upper, "description": self.description, "source": self.source,
                "scale": self.scale,
                "plausible": list(self.plausible) if self.plausible is not None else None,
                "plausible_source": self.plausible_source}


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


def plausibility(params: tuple[Param, ...], values: dict) -> dict[str, dict]:
    """For every named value: ``{"value", "plausible": [lo, hi], "inside": bool, "source"}``;
    names not in ``params`` are skipped."""
    by_name = {p.name: p for p in params}
    out = {}
    for k, v in values.items():
        p = by_name.get(k)
        if p is None:
            continue
        lo, hi = p.plausible_range
        out[k] = {"value": float(v), "plausible": [lo, hi], "inside": p.is_plausible(v),
                  "source": p.plausible_source}
    return out


def resolve(owner: str, params: tuple[Param, ...], given: dict | None) -> dict[str, float]:
    """Defaults overlaid by ``given`` (checked). Unknown names raise :class:`InvalidParameter`."""
    by_name = {p.name: p for p in params}
    out = {p.name: float(p.default) for p in params}
    for k, v in (given or {}).items():
        if k not in by_name:
            raise InvalidParameter(f"{owner}: unknown parameter {k!r}; known: {sorted(by_name)}")
        out[k] = check_value(owner, by_name[k], v)
    return out
