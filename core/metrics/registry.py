"""The one registry of curve-comparison metrics (docs/design.md §4). UI and CLI read it; no other list.

Two levels:

* :data:`METRICS` — every reported value: ``name`` (column/JSON key), ``label``, ``description``,
  ``unit`` (``"signal"`` means the unit of the compared signal), ``range``, ``best`` (the value
  of perfect agreement), ``better`` (``"lower"``, ``"higher"``, ``"closer to 0"``), ``family``
  and ``source`` (paper/standard).
* :data:`FAMILIES` — the computations, each producing several values from one
  ``(measured, simulated, fs, options)`` call. ``compare(..., families=...)`` selects them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from railval.core.errors import InvalidParameter
from railval.core.metrics.distribution import (
    anderson_darling,
    area_validation_metric,
    kolmogorov_smirnov,
)
from railval.core.metrics.iso18571 import ISOParameters, iso18571
from railval.core.metrics.russell import russell
from railval.core.metrics.sprague_geers import sprague_geers

_SG = "Sprague & Geers 2004; Polach & Böttcher 2014 §3.3 eq. 1–3"
_RU = "Russell 1997 (Part I)"
_KS = "[ref 2] §4.1 eq. 1; scipy.stats.ks_2samp"
_ISO = "ISO/TS 18571:2014"


@dataclass(frozen=True)
class MetricInfo:
    name: str
    label: str
    description: str
    unit: str
    range: str
    best: float | str
    better: str
    family: str
    source: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class MetricFamily:
    name: str
    label: str
    metrics: tuple[str, ...]
    compute: Callable[..., dict[str, Any]]
    order_invariant: bool  # ignores time order (distribution metric): sync only trims samples


def _sg(m, c, fs, opts):
    r = sprague_geers(m, c)
    return {"sg_M": r.M, "sg_P": r.P, "sg_C": r.C}


def _ru(m, c, fs, opts):
    r = russell(m, c)
    return {"russell_M": r.RM, "russell_P": r.RP, "russell_C": r.RC}


def _ks(m, c, fs, opts):
    r = kolmogorov_smirnov(m, c, neff_method=opts.get("neff_method", "bartlett"))
    return {"ks_D": r.D, "ks_p": r.p, "ks_p_eff": r.p_eff,
            "ks_n_eff": min(r.n_eff_measured, r.n_eff_simulated)}


def _area(m, c, fs, opts):
    return {"area": area_validation_metric(m, c)}


def _ad(m, c, fs, opts):
    r = anderson_darling(m, c)
    return {"ad_stat": r.statistic, "ad_p": r.p}


def _iso(m, c, fs, opts):
    r = iso18571(m, c, fs, opts.get("iso_params") or ISOParameters())
    return {"iso_corridor": r.corridor, "iso_phase": r.phase, "iso_magnitude": r.magnitude,
            "iso_slope": r.slope, "iso_rating": r.rating, "iso_grade": r.grade}


METRICS: dict[str, MetricInfo] = {m.name: m for m in (
    MetricInfo("sg_M", "Sprague–Geers M", "magnitude error factor sqrt(Σc²/Σm²) − 1; k·m gives k − 1",
               "-", "(−1, ∞)", 0.0, "closer to 0", "sprague_geers", _SG),
    MetricInfo("sg_P", "Sprague–Geers P", "phase error factor arccos(Σcm/sqrt(Σc²Σm²))/π",
               "-", "[0, 1]", 0.0, "lower", "sprague_geers", _SG),
    MetricInfo("sg_C", "Sprague–Geers C", "comprehensive error factor sqrt(M² + P²)",
               "-", "[0, ∞)", 0.0, "lower", "sprague_geers", _SG),
    MetricInfo("russell_M", "Russell RM", "magnitude error sign(m)·log10(1+|m|), m = (A−B)/sqrt(AB)",
               "-", "(−∞, ∞)", 0.0, "closer to 0", "russell", _RU),
    MetricInfo("russell_P", "Russell RP", "phase error arccos(Σcm/sqrt(AB))/π",
               "-", "[0, 1]", 0.0, "lower", "russell", _RU),
    MetricInfo("russell_C", "Russell RC", "comprehensive error sqrt(π/4·(RM² + RP²))",
               "-", "[0, ∞)", 0.0, "lower", "russell", _RU),
    MetricInfo("ks_D", "KS distance", "largest vertical distance between the empirical CDFs",
               "-", "[0, 1]", 0.0, "lower", "ks", _KS),
    MetricInfo("ks_p", "KS p-value", "classical two-sample p-value (assumes independent samples)",
               "-", "[0, 1]", 1.0, "higher", "ks", _KS),
    MetricInfo("ks_p_eff", "KS p-value (n_eff)",
               "p-value with effective sample sizes from the autocorrelation (Bartlett 1946)",
               "-", "[0, 1]", 1.0, "higher", "ks", _KS + "; Bartlett 1946; Thiébaux & Zwiers 1984"),
    MetricInfo("ks_n_eff", "effective sample size", "smaller of the two effective sample sizes",
               "samples", "[2, n]", "n", "higher", "ks", "Bartlett 1946; Thiébaux & Zwiers 1984"),
    MetricInfo("area", "area validation metric", "area between the empirical CDFs (1-Wasserstein)",
               "signal", "[0, ∞)", 0.0, "lower", "area",
               "Ferson, Oberkampf & Ginzburg 2008; [ref 2] §4.2 eq. 2"),
    MetricInfo("ad_stat", "Anderson–Darling", "normalised k-sample statistic (k = 2), midrank",
               "-", "(−∞, ∞)", "≤ 0", "lower", "anderson_darling",
               "Scholz & Stephens 1987; scipy.stats.anderson_ksamp"),
    MetricInfo("ad_p", "Anderson–Darling p", "tabulated p-value, clipped to [0.001, 0.25]; assumes "
               "independent samples", "-", "[0.001, 0.25]", 0.25, "higher", "anderson_darling",
               "Scholz & Stephens 1987; scipy.stats.anderson_ksamp"),
    MetricInfo("iso_corridor", "ISO corridor Z", "share inside inner/outer corridors (a0, b0, kz = 2)",
               "-", "[0, 1]", 1.0, "higher", "iso18571", _ISO),
    MetricInfo("iso_phase", "ISO phase E_P", "score of the best-correlation time shift (≤ 20 %)",
               "-", "[0, 1]", 1.0, "higher", "iso18571", _ISO),
    MetricInfo("iso_magnitude", "ISO magnitude E_M", "DTW magnitude error score (ε = 0.5)",
               "-", "[0, 1]", 1.0, "higher", "iso18571", _ISO),
    MetricInfo("iso_slope", "ISO slope E_S", "smoothed-derivative error score (ε = 2)",
               "-", "[0, 1]", 1.0, "higher", "iso18571", _ISO),
    MetricInfo("iso_rating", "ISO rating R", "0.4 Z + 0.2 E_P + 0.2 E_M + 0.2 E_S",
               "-", "[0, 1]", 1.0, "higher", "iso18571", _ISO),
    MetricInfo("iso_grade", "ISO grade", "excellent > 0.94, good > 0.80, fair > 0.58, else poor",
               "-", "poor…excellent", "excellent", "higher", "iso18571", _ISO),
)}

FAMILIES: dict[str, MetricFamily] = {f.name: f for f in (
    MetricFamily("sprague_geers", "Sprague–Geers", ("sg_M", "sg_P", "sg_C"), _sg, False),
    MetricFamily("russell", "Russell", ("russell_M", "russell_P", "russell_C"), _ru, False),
    MetricFamily("ks", "Kolmogorov–Smirnov", ("ks_D", "ks_p", "ks_p_eff", "ks_n_eff"), _ks, True),
    MetricFamily("area", "Area validation metric", ("area",), _area, True),
    MetricFamily("anderson_darling", "Anderson–Darling k-sample", ("ad_stat", "ad_p"), _ad, True),
    MetricFamily("iso18571", "ISO/TS 18571 rating",
                 ("iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "iso_rating",
                  "iso_grade"), _iso, False),
)}

DEFAULT_FAMILIES: tuple[str, ...] = tuple(FAMILIES)


def resolve_families(families: object = None) -> tuple[str, ...]:
    """Validate a selection of families (``None`` → all)."""
    if families is None:
        return DEFAULT_FAMILIES
    if isinstance(families, str):
        families = [families]
    out = tuple(families)  # type: ignore[arg-type]
    unknown = [f for f in out if f not in FAMILIES]
    if unknown:
        raise InvalidParameter(f"unknown metric family {unknown}; known: {sorted(FAMILIES)}")
    return out


def metric_names(families: object = None) -> list[str]:
    """Names of the values the selected families report, in registry order."""
    fams = resolve_families(families)
    return [name for f in fams for name in FAMILIES[f].metrics]


def registry_table() -> list[dict[str, Any]]:
    """The registry as JSON-ready rows (for the UI and ``railval metrics --list``)."""
    return [m.to_dict() for m in METRICS.values()]

