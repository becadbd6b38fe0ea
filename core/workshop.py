"""Review-workshop plot sets: the one registry of plot kinds, the fixed axis scaling of a
kind, each plot's objective deviation and the reviewers' plot order (docs/design.md §5,
docs/workshops.md).

Plot kinds
----------
A *plot kind* is one quantity drawn one way (time/distance history or PSD). The default
plot set of one (section, configuration) follows the DynoTRAIN review forms [ref 1, §3.2]:
time/distance plots of the guiding force Y, the vertical wheel force Q and the ratio Y/Q on
the leading wheelsets of both bogies (wheelsets 1 and 3, left and right wheel: 12 plots) and
of the car body accelerations (lateral and vertical above both bogies: 4 plots) — the
seed's 16 time/distance plots — plus the bogie frame accelerations where the vehicle has
such channels (4 more, coach only), and PSDs of the car body lateral and vertical
accelerations above both bogies (4 plots). Every signal is low-pass filtered at 20 Hz
[ref 1, §3.2] and drawn over the whole recorded section, transitions included.

:data:`PLOT_KINDS` is the only list of kinds; the CLI, the organiser page, the renderer and
the analysis read it.

Fixed scaling
-------------
Every plot of one kind in a workshop uses the same axis ranges, chosen once from the whole
workshop's data (:func:`kind_scale`), so that a reviewer's answer cannot depend on the
scaling of one plot — the DynoTRAIN workshop saw axis scaling move answers [ref 1, §4.2].
Linear ranges are widened to round numbers with :func:`nice_range` (ticks at 1, 2, 2.5 or 5
× 10ⁿ, the "nice numbers" of Heckbert, Graphics Gems, 1990, "Nice numbers for graph
labels"); logarithmic PSD ranges to whole decades (:func:`decade_range`).

Objective deviation
-------------------
:func:`plot_deviation`: the largest |D_v| / std limit over the EN 14363 quantities computed
from the plotted signal at the plotted position in that section (D_v of
Polach & Böttcher 2014 eq. (4), std limits of Table 2 via :mod:`railval.core.quantities`). A PSD
plot takes its signal's value; a signal without an EN quantity (bogie accelerations) has
none (``None``).

Plot order
----------
:func:`review_order`: a per-reviewer random permutation from a stored seed, with about a
share ``repeat_share`` of the plots shown a second time later (hidden repeats, to measure a
reviewer's consistency).

Pure computation: no database, UI or file access.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITIES

#: low-pass cut-off of every review plot in Hz [ref 1, §3.2]
LOWPASS_HZ = 20.0
#: upper frequency shown on PSD plots in Hz (the low-pass cut-off)
PSD_MAX_HZ = 20.0
#: Welch segment length of the PSD plots in s (railval.core.psd.welch_psd)
PSD_SEGMENT_S = 10.0
#: lowest PSD level shown, relative to the kind's largest density (6 decades)
PSD_DYNAMIC_RANGE = 1e-6

DOMAINS = ("time", "psd")


@dataclass(frozen=True)
class PlotKind:
    """One kind of review plot.

    ``signal``: the plotted signal family — a channel kind of :mod:`railval.core.types`
    (``Y``, ``Q``, ``ay_cb``, ``az_cb``, ``ay_bg``, ``az_bg``) or ``YQ`` (the sample-wise
    ratio Y/Q of one wheel); ``positions``: the default positions (channel name
    ``f"{signal}_{position}"``); ``quantities``: the EN 14363 quantity ids whose D_v gives
    the plot's objective deviation (empty: none); ``table1``: the row of the seed's Table 1
    the kind belongs to [ref 1, Table 1].
    """

    id: str
    label: str
    domain: str
    signal: str
    unit: str
    positions: tuple[str, ...]
    quantities: tuple[str, ...]
    table1: str

    def channel(self, position: str) -> str:
        """The plotted channel's name at ``position`` (``YQ_w1L`` for a ratio)."""
        return f"{self.signal}_{position}"

    def source_channels(self, position: str) -> tuple[str, ...]:
        """The stored channels the plot is computed from."""
        if self.signal == "YQ":
            return (f"Y_{position}", f"Q_{position}")
        return (f"{self.signal}_{position}",)

    @property
    def y_label(self) -> str:
        if self.domain == "psd":
            return f"PSD of {self.label.removeprefix('PSD ')} in ({self.unit})²/Hz"
        return f"{self.label} in {self.unit}" if self.unit != "-" else f"{self.label} (–)"

    @property
    def x_label(self) -> str:
        return "frequency in Hz" if self.domain == "psd" else "distance in m"

    def to_dict(self) -> dict:
        return asdict(self)


_LEADING = ("w1L", "w1R", "w3L", "w3R")
_BODY = ("b1", "b2")

#: the registry of plot kinds (id → kind), in display order
PLOT_KINDS: dict[str, PlotKind] = {k.id: k for k in (
    PlotKind("Y_time", "guiding force Y", "time", "Y", "kN", _LEADING, ("Y_qst", "Y_max"),
             "Guiding forces Y"),
    PlotKind("Q_time", "vertical wheel force Q", "time", "Q", "kN", _LEADING,
             ("Q_qst", "Q_max"), "Vertical wheel forces Q"),
    PlotKind("YQ_time", "ratio Y/Q", "time", "YQ", "-", _LEADING, ("YQ_qst", "YQ_max"),
             "Ratios Y/Q"),
    PlotKind("ay_cb_time", "car body lateral acceleration", "time", "ay_cb", "m/s²", _BODY,
             ("ay_rms", "ay_max"), "Vehicle body accelerations"),
    PlotKind("az_cb_time", "car body vertical acceleration", "time", "az_cb", "m/s²", _BODY,
             ("az_rms", "az_max"), "Vehicle body accelerations"),
    PlotKind("ay_bg_time", "bogie frame lateral acceleration", "time", "ay_bg", "m/s²", _BODY,
             (), "Bogie accelerations"),
    PlotKind("az_bg_time", "bogie frame vertical acceleration", "time", "az_bg", "m/s²", _BODY,
             (), "Bogie accelerations"),
    PlotKind("ay_cb_psd", "PSD car body lateral acceleration", "psd", "ay_cb", "m/s²", _BODY,
             ("ay_rms", "ay_max"), "PSDs of bogie and body accelerations"),
    PlotKind("az_cb_psd", "PSD car body vertical acceleration", "psd", "az_cb", "m/s²", _BODY,
             ("az_rms", "az_max"), "PSDs of bogie and body accelerations"),
)}

PLOT_KIND_IDS: tuple[str, ...] = tuple(PLOT_KINDS)


def get_kind(kind_id: str) -> PlotKind:
    """Registry lookup; :class:`InvalidParameter` names the known kinds."""
    try:
        return PLOT_KINDS[kind_id]
    except KeyError:
        raise InvalidParameter(
            f"unknown plot kind {kind_id!r}; known: {', '.join(PLOT_KIND_IDS)}") from None


def plots_for(kinds: Iterable[str], channel_names: Iterable[str]) -> list[tuple[str, str]]:
    """``(kind id, position)`` of every plot the given kinds make from the available
    channels of one (section, configuration), registry order; positions whose source
    channels are missing are left out."""
    names = set(channel_names)
    wanted = [get_kind(k).id for k in kinds]
    return [(k.id, p) for k in PLOT_KINDS.values() if k.id in wanted
            for p in k.positions if all(c in names for c in k.source_channels(p))]


# ------------------------------------------------------------------------- scaling
@dataclass(frozen=True)
class AxisRange:
    """A linear axis from ``lo`` to ``hi`` with ticks every ``step`` (or, for a logarithmic
    axis, ``log=True`` and ``lo``/``hi`` whole powers of ten)."""

    lo: float
    hi: float
    step: float
    log: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


def nice_step(span: float, target_ticks: int = 5) -> float:
    """The round tick step (1, 2, 2.5 or 5 × 10ⁿ) that divides ``span`` into about
    ``target_ticks`` intervals (Heckbert 1990, nice numbers, with 2.5 added)."""
    if not (span > 0 and math.isfinite(span)):
        raise InvalidParameter(f"nice_step: span must be a positive finite number, got {span!r}")
    if target_ticks < 1:
        raise InvalidParameter(f"nice_step: target_ticks must be ≥ 1, got {target_ticks!r}")
    raw = span / target_ticks
    exponent = math.floor(math.log10(raw))
    base = 10.0 ** exponent
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if raw <= m * base * (1 + 1e-12):
            return _clean(m * base)
    return _clean(10.0 * base)  # pragma: no cover - the loop ends at 10


def _clean(x: float) -> float:
    """Remove binary noise from a decimal number such as 0.30000000000000004."""
    return float(f"{x:.12g}")


def nice_range(lo: float, hi: float, target_ticks: int = 5) -> AxisRange:
    """The smallest range of whole tick steps (:func:`nice_step`) that contains
    ``[lo, hi]``. A degenerate range (``lo == hi``) is widened by ±1 unit of its magnitude
    (±1 for zero)."""
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InvalidParameter(f"nice_range: limits must be finite, got {lo!r}, {hi!r}")
    if hi < lo:
        raise InvalidParameter(f"nice_range: hi {hi!r} is below lo {lo!r}")
    if hi == lo:
        pad = abs(lo) if lo != 0 else 1.0
        lo, hi = lo - pad, hi + pad
    step = nice_step(hi - lo, target_ticks)
    n_lo = math.floor(lo / step + 1e-9)
    n_hi = math.ceil(hi / step - 1e-9)
    return AxisRange(_clean(n_lo * step), _clean(n_hi * step), step)


def decade_range(lo: float, hi: float, dynamic_range: float = PSD_DYNAMIC_RANGE) -> AxisRange:
    """Whole decades containing ``[lo, hi]`` (both > 0) for a logarithmic axis; ``lo`` is
    raised to at least ``hi · dynamic_range`` so that numerical noise floors do not squeeze
    the curves."""
    if not (hi > 0 and math.isfinite(hi)):
        raise InvalidParameter(f"decade_range: hi must be positive and finite, got {hi!r}")
    lo = max(float(lo) if lo > 0 else 0.0, hi * dynamic_range)
    d_lo = math.floor(math.log10(lo) + 1e-9)
    d_hi = math.ceil(math.log10(hi) - 1e-9)
    if d_hi <= d_lo:
        d_hi = d_lo + 1
    return AxisRange(_clean(10.0 ** d_lo), _clean(10.0 ** d_hi), 10.0, log=True)


@dataclass(frozen=True)
class Extent:
    """What one plot needs to show: x from ``x_lo`` to ``x_hi`` and y from ``y_lo`` to
    ``y_hi`` (for a PSD: the smallest positive and the largest density shown)."""

    x_lo: float
    x_hi: float
    y_lo: float
    y_hi: float


@dataclass(frozen=True)
class Scale:
    """The axis ranges of one plot (fixed: shared by its whole kind)."""

    x: AxisRange
    y: AxisRange

    def to_dict(self) -> dict:
        return {"x": self.x.to_dict(), "y": self.y.to_dict()}

    @classmethod
    def from_dict(cls, d: Mapping) -> Scale:
        return cls(AxisRange(**d["x"]), AxisRange(**d["y"]))


def kind_scale(domain: str, extents: Sequence[Extent]) -> Scale:
    """The one scaling of a kind from the extents of all its plots in a workshop.

    time: x from 0 to the longest section rounded up (:func:`nice_range`), y the round range
    containing every sample of every plot; psd: x from 0 to :data:`PSD_MAX_HZ`, y whole
    decades (:func:`decade_range`) containing every density shown.
    """
    if domain not in DOMAINS:
        raise InvalidParameter(f"domain must be one of {DOMAINS}, got {domain!r}")
    if not extents:
        raise InvalidParameter("kind_scale needs the extent of at least one plot")
    y_lo = min(e.y_lo for e in extents)
    y_hi = max(e.y_hi for e in extents)
    if domain == "psd":
        return Scale(AxisRange(0.0, PSD_MAX_HZ, 5.0), decade_range(y_lo, y_hi))
    x = nice_range(min(0.0, min(e.x_lo for e in extents)), max(e.x_hi for e in extents))
    return Scale(x, nice_range(y_lo, y_hi))


#: The consistent scalings an organiser chooses between (docs/workshops.md "Scaling"):
#: ``zone`` — one range per kind within each EN 14363 test zone (the default); ``workshop`` —
#: one range per kind over the whole workshop (the scaling of workshops made before the choice).
SCALINGS = ("zone", "workshop")
DEFAULT_SCALING = "zone"
#: How the presentation experiment's twin of a plot is scaled: per-plot automatic ranges, or
#: the other consistent scaling (pairs zone against workshop scaling on the same plot).
TWIN_SCALINGS = ("auto", *SCALINGS)
#: A plot is *flat* when its filtered signal spans less than this share of its y range.
FLAT_SPAN = 0.10


def check_scaling(scaling: str) -> str:
    if scaling not in SCALINGS:
        raise InvalidParameter(f"scaling must be one of {', '.join(SCALINGS)}, got {scaling!r}")
    return scaling


def scale_key(kind: str, zone: int | None, scaling: str) -> str:
    """The key of the range a plot of ``kind`` in test ``zone`` shares: the kind itself for
    ``workshop`` scaling, ``"KIND zone Z"`` for ``zone`` scaling."""
    check_scaling(scaling)
    return kind if scaling == "workshop" else f"{kind} zone {int(zone)}"


def span_share(extent: Extent, y: AxisRange) -> float:
    """How much of the y range ``y`` a plot's own extent covers (0–1): linear on a linear
    axis, in decades on a logarithmic one."""
    if y.log:
        lo, hi = max(extent.y_lo, y.lo), max(extent.y_hi, y.lo)
        return (math.log10(hi) - math.log10(lo)) / (math.log10(y.hi) - math.log10(y.lo))
    return (extent.y_hi - extent.y_lo) / (y.hi - y.lo)


def is_flat(extent: Extent, y: AxisRange) -> bool:
    """The plot's signal spans less than :data:`FLAT_SPAN` of the y range: a flat line on
    which no reviewer can judge the shape."""
    return span_share(extent, y) < FLAT_SPAN


def group_scales(domains: Mapping[str, str], extents: Sequence[tuple[str, Extent]]) -> dict[str, Scale]:
    """One :func:`kind_scale` per scale key: ``extents`` is a sequence of (key, extent of one
    plot), ``domains`` maps each key to its domain."""
    grouped: dict[str, list[Extent]] = {}
    for key, e in extents:
        grouped.setdefault(key, []).append(e)
    return {key: kind_scale(domains[key], ex) for key, ex in grouped.items()}


# ------------------------------------------------------------------------- objective value
def plot_deviation(kind: PlotKind | str, position: str,
                   dv_over_limit: Mapping[tuple[str, str], float]) -> float | None:
    """The plot's normalised deviation: the largest |D_v| / std limit over the kind's EN
    quantities at ``position`` (Polach & Böttcher 2014 eq. (4) and Table 2).

    ``dv_over_limit``: ``{(quantity id, position): D_v / std limit}`` of this section and
    configuration. ``None`` when the kind has no EN quantity (bogie accelerations) or none
    of its quantities was evaluated at this position.
    """
    k = get_kind(kind) if isinstance(kind, str) else kind
    vals = [abs(float(dv_over_limit[(q, position)])) for q in k.quantities
            if (q, position) in dv_over_limit and math.isfinite(dv_over_limit[(q, position)])]
    return max(vals) if vals else None


def dv_over_limit(measured: Mapping[tuple[str, str], float],
                  simulated: Mapping[tuple[str, str], float],
                  std_limits: Mapping[str, float]) -> dict[tuple[str, str], float]:
    """``D_v / std limit`` of every (quantity, position) evaluated on both sides of one
    section (D_v = (S − M)·sign(M), Polach & Böttcher 2014 eq. (4); S where M = 0)."""
    from railval.core.validation import difference

    out = {}
    for key, m in measured.items():
        if key in simulated and key[0] in QUANTITIES:
            out[key] = float(difference(simulated[key], m)) / float(std_limits[key[0]])
    return out


# ------------------------------------------------------------------------- order
def review_order(n_plots: int, seed: int, repeat_share: float = 0.1,
                 min_gap: int = 5) -> list[tuple[int, bool]]:
    """A reviewer's sequence: ``(plot index, is_repeat)`` for every plot once in a random
    order (``numpy.random.default_rng(seed)``), plus ``round(repeat_share · n_plots)``
    plots shown a second time, each at least ``min_gap`` places after its first showing
    (or as late as the sequence allows). Deterministic for a given seed.
    """
    if n_plots < 0:
        raise InvalidParameter(f"n_plots must be ≥ 0, got {n_plots}")
    if not (0.0 <= repeat_share <= 1.0):
        raise InvalidParameter(f"repeat share must be between 0 and 1, got {repeat_share!r}")
    rng = np.random.default_rng(seed)
    seq: list[tuple[int, bool]] = [(int(i), False) for i in rng.permutation(n_plots)]
    n_rep = round(repeat_share * n_plots)
    if n_rep == 0:
        return seq
    chosen = rng.choice(n_plots, size=n_rep, replace=False)
    for plot in chosen:
        first = next(i for i, (p, rep) in enumerate(seq) if p == plot and not rep)
        lo = min(first + 1 + min_gap, len(seq))
        at = int(rng.integers(lo, len(seq) + 1))
        seq.insert(at, (int(plot), True))
    return seq
