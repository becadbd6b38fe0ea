"""Curve-comparison metrics (docs/design.md §4; seeds 000 §3.3 and 001 §4).

Public API::

    compare(measured, simulated, fs, *, max_lag_s=2.0, ...) -> ComparisonResult
    compare_signalsets(measured: SignalSet, simulated: SignalSet, channels=None,
                       lowpass_hz=20.0, **options) -> pandas.DataFrame
    METRICS, FAMILIES, registry_table()           # the one metric registry
    sprague_geers, russell, kolmogorov_smirnov, area_validation_metric,
    anderson_darling, effective_sample_size, iso18571, ISOParameters, grade,
    estimate_lag, apply_lag, common_grid

Modules: ``sprague_geers``, ``russell``, ``distribution`` (KS, n_eff, area, AD), ``iso18571``
(with the numba DTW), ``sync``, ``grid``, ``registry``, ``compare``.
"""

from railval.core.metrics.compare import (
    ComparisonResult,
    compare,
    compare_signalsets,
    cut_evaluated,
    lowpass,
)
from railval.core.metrics.distribution import (
    ADResult,
    KSResult,
    anderson_darling,
    area_validation_metric,
    autocorrelation,
    effective_sample_size,
    kolmogorov_smirnov,
    ks_pvalue,
)
from railval.core.metrics.grid import CommonGrid, common_grid
from railval.core.metrics.iso18571 import ISOParameters, ISORating, grade, iso18571
from railval.core.metrics.registry import (
    FAMILIES,
    METRICS,
    MetricInfo,
    metric_names,
    registry_table,
)
from railval.core.metrics.russell import Russell, russell
from railval.core.metrics.sprague_geers import SpragueGeers, sprague_geers
from railval.core.metrics.sync import SyncResult, apply_lag, estimate_lag

__all__ = [
    "FAMILIES",
    "METRICS",
    "ADResult",
    "CommonGrid",
    "ComparisonResult",
    "ISOParameters",
    "ISORating",
    "KSResult",
    "MetricInfo",
    "Russell",
    "SpragueGeers",
    "SyncResult",
    "anderson_darling",
    "apply_lag",
    "area_validation_metric",
    "autocorrelation",
    "common_grid",
    "compare",
    "compare_signalsets",
    "cut_evaluated",
    "effective_sample_size",
    "estimate_lag",
    "grade",
    "iso18571",
    "kolmogorov_smirnov",
    "ks_pvalue",
    "lowpass",
    "metric_names",
    "registry_table",
    "russell",
    "sprague_geers",
]
