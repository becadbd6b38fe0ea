"""Axis scales, unit labels and line colours shared by the app's charts, pages and the report
(docs/design.md §5: fixed, consistent axis scaling; measurement beneath, simulation on top)."""

from __future__ import annotations

import math

from railval.core.workshop import nice_range as _core_nice_range
from railval.core.workshop import nice_step as _core_nice_step

#: measurement black (drawn beneath); simulations in the Okabe–Ito colour-blind-safe palette
#: (Okabe & Ito 2008, "Color Universal Design"), vermillion first: distinct from black in
#: greyscale print and for the common colour-vision deficiencies
MEASURED_COLOR = "#000000"
SIM_COLORS = ("#D55E00", "#0072B2", "#009E73", "#CC79A7", "#E69F00")


def nice_step(lo: float, hi: float, intervals: int = 5) -> float:
    """A 'nice' step (1, 2, 2.5, 5 × 10^k) giving about ``intervals`` intervals on [lo, hi]
    (the one rule of :func:`railval.core.workshop.nice_step`)."""
    return _core_nice_step(hi - lo, intervals)


def nice_limits(lo: float, hi: float) -> tuple[float, float]:
    """Round ``[lo, hi]`` outwards to a multiple of :func:`nice_step` (~5 intervals).

    Used for fixed, consistent axis scaling (docs/design.md §5); the rule is
    :func:`railval.core.workshop.nice_range`, shared with the review workshops. Degenerate
    ranges are widened symmetrically by one unit of their magnitude (or ±1 around 0).
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return (-1.0, 1.0)
    if hi < lo:
        lo, hi = hi, lo
    r = _core_nice_range(lo, hi)
    return (r.lo, r.hi)


def nice_ticks(lo: float, hi: float) -> list[float]:
    """Tick positions: the multiples of :func:`nice_step` within [lo, hi]."""
    step = nice_step(lo, hi)
    first = math.ceil(lo / step - 1e-9)
    return [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def unit_label(unit: str) -> str:
    """A stored unit as shown to a reader: ``m/s^2`` → ``m/s²``, ``kN*m/rad`` → ``kN·m/rad``."""
    return unit.replace("m/s^2", "m/s²").replace("*", "·")


