"""The public core functions a reader calls carry numpydoc ``Parameters`` and ``Returns``
sections that name each of their parameters (issue 30; numpydoc docstring standard,
https://numpydoc.readthedocs.io/en/latest/format.html).

The sections are found with a small parser of the numpydoc layout (a heading line, a line
of dashes under it, then ``name : type`` entries at the section's indentation) and the
names are compared with :func:`inspect.signature`."""

from __future__ import annotations

import importlib
import inspect
import re

import pytest

#: ``module:function`` of every documented reader entry point
READER_API = (
    "railval.core.en14363:evaluate_section",
    "railval.core.en14363:evaluate_batch",
    "railval.core.en14363:quantity_trace",
    "railval.core.en14363:evaluate_present",
    "railval.core.filters:design",
    "railval.core.filters:filtfilt_rows",
    "railval.core.filters:settling_check",
    "railval.core.filters:check_order",
    "railval.core.psd:welch_psd",
    "railval.core.psd:welch_rows",
    "railval.core.psd:detrend_linear",
    "railval.core.supplementary:psd_band_values",
    "railval.core.supplementary:supplementary_results",
    "railval.core.supplementary:supplementary_pattern",
    "railval.core.metrics.iso18571:iso18571",
    "railval.core.metrics.iso18571:corridor_score",
    "railval.core.metrics.iso18571:phase_shift",
    "railval.core.metrics.iso18571:phase_score",
    "railval.core.metrics.iso18571:dtw_magnitude_error",
    "railval.core.metrics.iso18571:slope_error",
    "railval.core.metrics.iso18571:grade",
    "railval.core.metrics.iso18571:smoothed_slope",
    "railval.core.metrics.distribution:kolmogorov_smirnov",
    "railval.core.metrics.distribution:area_validation_metric",
    "railval.core.metrics.distribution:anderson_darling",
    "railval.core.metrics.distribution:effective_sample_size",
    "railval.core.metrics.distribution:autocorrelation",
    "railval.core.metrics.distribution:ks_pvalue",
    "railval.core.metrics.compare:compare",
    "railval.core.metrics.compare:compare_signalsets",
    "railval.core.metrics.compare:lowpass",
    "railval.core.metrics.sprague_geers:sprague_geers",
    "railval.core.metrics.sprague_geers:energies",
    "railval.core.metrics.sprague_geers:normalised_correlation",
    "railval.core.metrics.russell:russell",
    "railval.core.metrics.sync:estimate_lag",
    "railval.core.metrics.sync:best_lag_index",
    "railval.core.metrics.sync:apply_lag",
    "railval.core.metrics.sync:lag_correlations",
    "railval.core.modal:ssi_cov",
    "railval.core.modal:mac",
    "railval.core.modal:mac_matrix",
    "railval.core.modal:pair_modes",
    "railval.core.modal:decimated_records",
    "railval.core.modal:output_covariances",
    "railval.core.modal:modes_from_matrices",
    "railval.core.calibration:calibrate",
    "railval.core.calibration:calibrate_modal",
    "railval.core.calibration:validation_objective",
    "railval.core.calibration:modal_objective",
    "railval.core.calibration:coach_vertical_modes",
    "railval.core.calibration:coach_modal_base",
    "railval.core.calibration:max_evaluations",
    "railval.core.definitions:alternatives_for",
    "railval.core.definitions:sorted_percentiles",
    "railval.core.definitions:window_centres",
    "railval.core.definitions:sample_window_means",
    "railval.core.definitions:percentile_ranks",
    "railval.core.definitions:percentiles_from_order",
    "railval.core.zones:zone_for_radius",
    "railval.core.coverage:coverage",
    "railval.core.coverage:zone_shortfalls",
    "railval.core.coverage:layout_shortfalls",
    "railval.core.diagnosis.engine:diagnose_evidence",
    "railval.core.diagnosis.causes:cause_set",
    "railval.core.sim.model:simulate_section",
    "railval.core.sim.model:simulate_campaign",
    "railval.core.sim.model:channel_names",
    "railval.core.sim.synth:build_campaign",
    "railval.core.sim.synth:parse_hidden",
    "railval.core.sim.synth:hidden_defaults",
    "railval.core.sim.track:generate_irregularities",
    "railval.core.sim.track:ore_b176_psd",
)

_HEADING = re.compile(r"^(\S[^\n]*)\n-{3,}[ \t]*$", re.MULTILINE)
_ENTRY = re.compile(r"^(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s*(?::.*)?$")


def numpydoc_sections(doc: str | None) -> dict[str, str]:
    """Section heading → section body of a numpydoc docstring (the summary is left out)."""
    text = inspect.cleandoc(doc or "")
    heads = list(_HEADING.finditer(text))
    ends = [h.start() for h in heads[1:]] + [len(text)] if heads else []
    return {m.group(1).strip(): text[m.end():end] for m, end in zip(heads, ends, strict=True)}


def section_names(body: str) -> set[str]:
    """The names an entry line of a section introduces (``a, b : array_like`` gives a and b);
    entry lines are the non-blank lines at the section's smallest indentation."""
    lines = [ln for ln in body.splitlines() if ln.strip()]
    if not lines:
        return set()
    base = min(len(ln) - len(ln.lstrip()) for ln in lines)
    names: set[str] = set()
    for ln in lines:
        if len(ln) - len(ln.lstrip()) == base and (m := _ENTRY.match(ln.strip())):
            names.update(n.strip().lstrip("*") for n in m.group(1).split(","))
    return names


def numpydoc_problems(func) -> list[str]:
    """What the docstring of ``func`` lacks: a ``Parameters`` section naming every parameter
    of its signature (``self``/``cls`` aside) and a non-empty ``Returns`` section."""
    sections = numpydoc_sections(func.__doc__)
    params = [p for p in inspect.signature(func).parameters if p not in ("self", "cls")]
    problems = []
    if params:
        if "Parameters" not in sections:
            problems.append("no Parameters section")
        else:
            missing = [p for p in params if p not in section_names(sections["Parameters"])]
            if missing:
                problems.append(f"Parameters does not name {missing}")
    if not sections.get("Returns", "").strip():
        problems.append("no Returns section")
    return problems


def _resolve(spec: str):
    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


@pytest.mark.parametrize("spec", READER_API)
def test_reader_api_has_numpydoc_parameters_and_returns(spec):
    assert numpydoc_problems(_resolve(spec)) == [], spec


def test_reader_api_entries_are_public_functions():
    assert len(set(READER_API)) == len(READER_API)
    for spec in READER_API:
        func = inspect.unwrap(_resolve(spec))  # design() is behind functools.lru_cache
        assert inspect.isfunction(func) and not func.__name__.startswith("_"), spec


def _planted_bare(a, b=1):
    """Does something with a and b, documented in prose only."""


def _planted_partial(signal, fs, *, order=4):
    """Filters a signal.

    Parameters
    ----------
    signal : numpy.ndarray
        Samples, shape (N,).
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    numpy.ndarray
    """


def _planted_good(simulated, measured, *weights, order=4, **options):
    """Compares two signals.

    Parameters
    ----------
    simulated, measured : array_like
        Shape (N,); ``measured`` mentioned in prose
        order : not an entry, deeper indentation
    *weights : float
        Per-sample weights.
    order : int
    **options
        Passed on.

    Returns
    -------
    float
        The score.
    """


def test_check_fails_on_planted_functions_without_the_sections():
    assert numpydoc_problems(_planted_bare) == ["no Parameters section", "no Returns section"]
    assert numpydoc_problems(_planted_partial) == ["Parameters does not name ['order']"]
    assert numpydoc_problems(_planted_good) == []


def test_parser_reads_only_entry_lines():
    body = numpydoc_sections(_planted_good.__doc__)["Parameters"]
    assert section_names(body) == {"simulated", "measured", "weights", "order", "options"}
