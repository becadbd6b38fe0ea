"""Diagnosis: which missing effect or model-parameter error explains the residual of a
configuration, and how sure the answer is (docs/design.md §7, docs/diagnosis.md).

One module per concept:

* :mod:`~railval.core.diagnosis.patterns` — pattern components and the whitened residual
  pattern (normalised D_v per quantity × zone × position, log₂ PSD band ratios);
* :mod:`~railval.core.diagnosis.evidence` — per-section evidence, zone-stratified folds and
  bootstrap;
* :mod:`~railval.core.diagnosis.fit` — candidate families and the fit along one parameter;
* :mod:`~railval.core.diagnosis.plausibility` — plausible ranges, search bounds, what
  separates two candidates;
* :mod:`~railval.core.diagnosis.result` — ranked candidates and the result as plain dicts;
* :mod:`~railval.core.diagnosis.engine` — held-out ranking, noise floor and verdict;
* :mod:`~railval.core.diagnosis.families` — the same per quantity family, structural
  differences named;
* :mod:`~railval.core.diagnosis.grids` — heat-map grids for the page and reports.

References: Polach & Böttcher 2014 §5; Efron & Tibshirani 1993; Hastie, Tibshirani &
Friedman 2009 §7.10; Welch 1967.
"""

from __future__ import annotations

from railval.core.diagnosis.engine import ALIKE_CORRELATION, ALIKE_MARGIN, STRONG, diagnose_evidence
from railval.core.diagnosis.evidence import (
    SectionEvidence,
    section_evidence,
    zone_bootstrap,
    zone_folds,
)
from railval.core.diagnosis.families import QUANTITY_FAMILIES, diagnose_families, family_of
from railval.core.diagnosis.fit import PARAMETER_CANDIDATES, CandidateFamily, scan_values
from railval.core.diagnosis.grids import ZONE_COLUMNS, PatternGrid, pattern_grids, where_grid
from railval.core.diagnosis.patterns import (
    DEFAULT_BANDS_HZ,
    Component,
    Pattern,
    band_powers,
    band_ratio_pattern,
    component_parts,
    difference_pairs,
    pattern_from_pairs,
    psd_band_pattern,
    section_band_powers,
    sections_band_powers,
)
from railval.core.diagnosis.plausibility import plausibility_flags, separating_evidence
from railval.core.diagnosis.result import DiagnosisResult, TrustedCandidate

__all__ = [
    "ALIKE_CORRELATION",
    "ALIKE_MARGIN",
    "DEFAULT_BANDS_HZ",
    "PARAMETER_CANDIDATES",
    "QUANTITY_FAMILIES",
    "STRONG",
    "ZONE_COLUMNS",
    "CandidateFamily",
    "Component",
    "DiagnosisResult",
    "Pattern",
    "PatternGrid",
    "SectionEvidence",
    "TrustedCandidate",
    "band_powers",
    "band_ratio_pattern",
    "component_parts",
    "diagnose_evidence",
    "diagnose_families",
    "difference_pairs",
    "family_of",
    "pattern_from_pairs",
    "pattern_grids",
    "plausibility_flags",
    "psd_band_pattern",
    "scan_values",
    "section_band_powers",
    "sections_band_powers",
    "section_evidence",
    "separating_evidence",
    "where_grid",
    "zone_bootstrap",
    "zone_folds",
]
