"""Chart conventions shared by the app's plots (HoloViews/Bokeh), pages and the HTML report
(docs/design.md §5: fixed, consistent axis scaling; measurement beneath, simulation on top):
nice axis limits and ticks, unit labels, line colours, pass/fail colours and the bar-chart
rule of the normalised values, and the downsampling of long signals for display."""

from __future__ import annotations

import math

import numpy as np
from tsdownsample import MinMaxLTTBDownsampler

PASS_COLOR = "#2e7d32"
FAIL_COLOR = "#c62828"
LIMIT_COLOR = "#000000"

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


def passes(value: float | None, limit: float = 1.0) -> bool:
    """A normalised value (value / its limit, Polach & Böttcher 2014 §5) within ±``limit``."""
    return value is not None and math.isfinite(value) and abs(value) <= limit


def verdict_color(value: float | None, limit: float = 1.0) -> str:
    """:data:`PASS_COLOR` for a value within ±``limit``, else :data:`FAIL_COLOR`."""
    return PASS_COLOR if passes(value, limit) else FAIL_COLOR


def downsample_xy(x: np.ndarray, y: np.ndarray, n_out: int = 2000,
                  x_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """At most ``n_out`` points of ``(x, y)`` within ``x_range`` (inclusive, plus one
    neighbour each side so lines reach the window edges), chosen by min-max LTTB
    (tsdownsample ``MinMaxLTTBDownsampler``: per-bucket min/max preselection, then
    largest-triangle-three-buckets, Steinarsson 2013; the first and last point kept).

    ``x`` must be increasing. Non-finite samples are dropped before selection.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x_range is not None and x.size:
        i0 = max(int(np.searchsorted(x, x_range[0], side="left")) - 1, 0)
        i1 = min(int(np.searchsorted(x, x_range[1], side="right")) + 1, x.size)
        x, y = x[i0:i1], y[i0:i1]
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.all():
        x, y = x[ok], y[ok]
    if x.size <= n_out:
        return x, y
    idx = MinMaxLTTBDownsampler().downsample(np.ascontiguousarray(x), np.ascontiguousarray(y), n_out=n_out)
    return x[idx], y[idx]
