"""Axis scales, unit labels and line colours shared by the app's charts, pages and the report
(docs/design.md §5: fixed, consistent axis scaling; measurement beneath, simulation on top)."""

from __future__ import annotations

import math

#: measurement black (drawn beneath); simulations in the Okabe–Ito colour-blind-safe palette
#: (Okabe & Ito 2008, "Color Universal Design"), vermillion first: distinct from black in
#: greyscale print and for the common colour-vision deficiencies
MEASURED_COLOR = "#000000"
SIM_COLORS = ("#D55E00", "#0072B2", "#009E73", "#CC79A7", "#E69F00")


def nice_step(lo: float, hi: float, intervals: int = 5) -> float:
    """A 'nice' step (1, 2, 2.5, 5 × 10^k) giving about ``intervals`` intervals on [lo, hi]."""
    raw = (hi - lo) / intervals
    mag = 10.0 ** math.floor(math.log10(raw))
    return next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw)


def nice_limits(lo: float, hi: float) -> tuple[float, float]:
    """Round ``[lo, hi]`` outwards to a multiple of :func:`nice_step` (~5 intervals).

    Used for fixed, consistent axis scaling (docs/design.md §5). Degenerate ranges are widened
    symmetrically by one unit of their magnitude (or ±1 around 0).
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return (-1.0, 1.0)
    if hi < lo:
        lo, hi = hi, lo
    if hi == lo:
        pad = abs(lo) or 1.0
        lo, hi = lo - pad, hi + pad
    step = nice_step(lo, hi)
    return (math.floor(lo / step + 1e-9) * step, math.ceil(hi / step - 1e-9) * step)


def nice_ticks(lo: float, hi: float) -> list[float]:
    """Tick positions: the multiples of :func:`nice_step` within [lo, hi]."""
    step = nice_step(lo, hi)
    first = math.ceil(lo / step - 1e-9)
    return [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]


#: half-height of the normalised-value axes (mean / limit, std / limit) of the dashboard and the
#: report, the same as the "where it fails" heat map's colour scale: every configuration is
#: drawn on the same axis so they compare at a glance (docs/design.md §5)
NORM_AXIS = 2.0


def norm_axis_top(values, base: float = NORM_AXIS) -> float:
    """Upper end of a normalised-value axis: ``base`` unless a finite |value| (bars and their
    interval ends) exceeds it, then the next nice value above it with a 5 % margin, so a
    bar or error bar never touches the edge."""
    finite = [abs(float(v)) for v in values if v is not None and math.isfinite(float(v))]
    m = max(finite, default=0.0)
    if m <= base:
        return float(base)
    return float(nice_limits(0.0, m * 1.05)[1])


def norm_ticks(top: float, signed: bool) -> list[float]:
    """Ticks of a normalised-value axis [−top or 0, top]: nice steps plus the limit 1.0 (and
    −1.0 when signed), always labelled."""
    lo = -top if signed else 0.0
    ticks = {round(t, 9) for t in nice_ticks(lo, top)} | {1.0} | ({-1.0} if signed else set())
    return sorted(ticks)


def unit_label(unit: str) -> str:
    """A stored unit as shown to a reader: ``m/s^2`` → ``m/s²``, ``kN*m/rad`` → ``kN·m/rad``."""
    return unit.replace("m/s^2", "m/s²").replace("*", "·")


