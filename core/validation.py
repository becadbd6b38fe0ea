"""DynoTRAIN validation of a model configuration (Polach & Böttcher 2014 §5, eq. 4; docs/design.md §3).

For every pair (section, signal position) of a quantity the difference

    D_v = (S_v − M_v) · M_v / |M_v|   for M_v ≠ 0,      D_v = S_v   for M_v = 0     (eq. 4)

is positive when the simulation overestimates the magnitude of the measurement. Per quantity,
over all pairs: mean and **sample** standard deviation (ddof = 1, i.e. divided by n − 1) of
D_v, compared with the limits of Table 2 (:mod:`railval.core.quantities`; mean limit = 2/3 of the std
limit, accelerations doubled for freight / no secondary suspension). Normalised values are
value / limit (Polach & Böttcher 2014 Fig. 12–13), each with a percentile bootstrap confidence interval
over the pairs (resampling pairs with replacement, seeded).

A configuration is *validated* when every quantity has |mean| ≤ mean limit and std ≤ std
limit **and** the coverage holds: ≥ 12 sections, each of the 4 EN 14363 zones with ≥ 3
sections, and per quantity ≥ 2 signals (positions) and ≥ 24 values. Every shortfall is
reported as a sentence ("zone 3 has 2 sections, needs 3"); the rules live in
:mod:`railval.core.coverage`.

Definition sensitivity: when the section values carry the values of the other readings of the
open definitions (percentile method, sliding-window grid and mean;
:mod:`railval.core.definitions`, filled by :mod:`railval.core.en14363`), every quantity's
mean, std and pass/fail are recomputed under each reading that can change it, over the same
pairs. A quantity is ``definition_sensitive`` when some reading flips its pass/fail; the
verdict is sensitive when some reading flips ``validated``. Supplementary quantities
(:mod:`railval.core.supplementary`) get the same D_v statistics and never enter the verdict.

:func:`validate` works purely from memory: ``{section_id: {(quantity_id, position): value}}``
for measurement and simulation (e.g. from :func:`railval.core.en14363.evaluate_batch`), the
:class:`~railval.core.types.SectionInfo` records and the vehicle.

References
----------
Polach & Böttcher 2014, §5, eq. (4), Table 2, Fig. 11–13.
Efron, B. & Tibshirani, R. (1993) An Introduction to the Bootstrap, ch. 13 (percentile
interval).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.core.bootstrap import (  # noqa: F401 - the bootstrap, re-exported for callers
    _CACHED_DRAW,
    _resample_indices,
    _resampled_rows,
    bootstrap_cis,
    bootstrap_norm_ci,
)
from railval.core.coverage import (  # noqa: F401 - the coverage rules, re-exported for callers
    MIN_POSITIONS,
    MIN_SECTIONS,
    MIN_SECTIONS_PER_ZONE,
    MIN_VALUES,
    Coverage,
    coverage,
    layout_shortfalls,
    zone_shortfalls,
)
from railval.core.definitions import CHOSEN, READINGS, alternatives_for
from railval.core.en14363 import evaluate_present
from railval.core.errors import InvalidParameter
from railval.core.filters import DEFAULT_ORDER
from railval.core.pairing import Pairs, QuantityPairs, gather_pairs, values_under
from railval.core.quantities import QUANTITIES, QUANTITY_IDS, VEHICLE_KINDS
from railval.core.stages import stage
from railval.core.supplementary import supplementary_results
from railval.core.types import SectionInfo, SignalSet

STD_DDOF = 1
STD_DEFINITION = "sample standard deviation (ddof = 1, divided by n − 1)"


@dataclass(frozen=True)
class Vehicle:
    """What the limits depend on: ``kind`` passenger/freight, secondary suspension present,
    ``Q0_kN`` static vertical wheel force in kN."""

    kind: str = "passenger"
    secondary_suspension: bool = True
    Q0_kN: float = 80.0

    def __post_init__(self):
        if self.kind not in VEHICLE_KINDS:
            raise InvalidParameter(f"vehicle kind must be one of {VEHICLE_KINDS}, got {self.kind!r}")
        if not (self.Q0_kN > 0):
            raise InvalidParameter(f"vehicle Q0_kN must be > 0 kN, got {self.Q0_kN!r}")

    @classmethod
    def from_any(cls, obj) -> Vehicle:
        """Build from a :class:`Vehicle`, a mapping or an object with attributes ``kind``,
        ``secondary_suspension``, ``Q0_kN`` (e.g. a db vehicle record).

        Parameters
        ----------
        obj : Vehicle, mapping or object
            ``Q0_kN`` may also be spelt ``q0_kn`` (the database column); a missing
            secondary suspension counts as present.

        Returns
        -------
        Vehicle
        """
        if isinstance(obj, Vehicle):
            return obj
        get = obj.get if isinstance(obj, Mapping) else (lambda k, d=None: getattr(obj, k, d))
        q0 = get("Q0_kN")
        if q0 is None:
            q0 = get("q0_kn")
        sec = get("secondary_suspension", True)
        return cls(kind=str(get("kind", "passenger")),
                   secondary_suspension=bool(True if sec is None else sec),
                   Q0_kN=float(q0) if q0 is not None else float("nan"))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "secondary_suspension": self.secondary_suspension,
                "Q0_kN": self.Q0_kN}


def difference(simulated, measured) -> np.ndarray:
    """D_v of Polach & Böttcher 2014 eq. (4), element-wise: ``(S − M)·sign(M)``, and ``S`` where ``M = 0``.

    Parameters
    ----------
    simulated, measured : array_like
        S_v and M_v in the unit of the quantity, broadcastable.

    Returns
    -------
    numpy.ndarray
        D_v in the unit of the quantity; positive = the simulation overestimates the
        measured magnitude.
    """
    s = np.asarray(simulated, dtype=np.float64)
    m = np.asarray(measured, dtype=np.float64)
    return np.where(m == 0.0, s, (s - m) * np.sign(m))


def _none_if_nan(x):
    return None if x is None or not math.isfinite(x) else float(x)


def judge(n: int, mean: float, std: float, mean_limit: float, std_limit: float) -> bool:
    """Pass/fail of one quantity: n ≥ 2, |mean| ≤ mean limit and std ≤ std limit
    (Polach & Böttcher 2014 §5).

    Parameters
    ----------
    n : int
        Number of pairs.
    mean, std : float
        Mean and sample standard deviation (n − 1) of D_v.
    mean_limit, std_limit : float
        The limits of Table 2 for this vehicle.

    Returns
    -------
    bool
    """
    return bool(n >= 2 and math.isfinite(std) and abs(mean) <= mean_limit and std <= std_limit)


@dataclass
class QuantityResult:
    """Statistics of D_v of one quantity over all its pairs."""

    quantity: str
    unit: str
    n: int
    n_positions: int
    n_sections: int
    mean: float
    std: float
    mean_limit: float
    std_limit: float
    mean_norm_ci: tuple[float, float]
    std_norm_ci: tuple[float, float]
    drilldown: list[dict] = field(default_factory=list)
    #: results under the other readings of the open definitions (None: values carried none)
    alternatives: list[dict] | None = None

    @property
    def mean_norm(self) -> float:
        return self.mean / self.mean_limit

    @property
    def std_norm(self) -> float:
        return self.std / self.std_limit

    @property
    def passed(self) -> bool:
        return judge(self.n, self.mean, self.std, self.mean_limit, self.std_limit)

    @property
    def definition_sensitive(self) -> bool | None:
        """True when another reading of the open definitions flips pass/fail; None when the
        values carried no alternatives (plain dictionaries)."""
        if self.alternatives is None:
            return None
        return any(a["flips"] for a in self.alternatives)

    @property
    def robust(self) -> bool:
        """True when both confidence intervals lie on the same side of 1 as the verdict."""
        lo_m, hi_m = self.mean_norm_ci
        lo_s, hi_s = self.std_norm_ci
        if not all(np.isfinite([lo_m, hi_m, lo_s, hi_s])):
            return False
        worst_mean = max(abs(lo_m), abs(hi_m))
        if self.passed:
            return worst_mean <= 1.0 and hi_s <= 1.0
        mean_fails = min(abs(lo_m), abs(hi_m)) > 1.0 and lo_m * hi_m > 0
        return mean_fails or lo_s > 1.0

    def to_dict(self) -> dict:
        return {
            "quantity": self.quantity, "unit": self.unit, "n": self.n,
            "n_positions": self.n_positions, "n_sections": self.n_sections,
            "mean": _none_if_nan(self.mean), "std": _none_if_nan(self.std),
            "std_ddof": STD_DDOF,
            "mean_limit": self.mean_limit, "std_limit": self.std_limit,
            "mean_norm": _none_if_nan(self.mean_norm), "std_norm": _none_if_nan(self.std_norm),
            "mean_norm_ci": [_none_if_nan(v) for v in self.mean_norm_ci],
            "std_norm_ci": [_none_if_nan(v) for v in self.std_norm_ci],
            "pass": self.passed, "robust": self.robust,
            "definition_sensitive": self.definition_sensitive,
            "definition_flips": [a["reading"]["id"] for a in self.alternatives or ()
                                 if a["flips"]],
            "definition_alternatives": list(self.alternatives or ()),
            "drilldown": self.drilldown,
        }


@dataclass
class ValidationResult:
    """Verdict, coverage, per-quantity statistics and the per-pair table of one
    configuration. ``pairs``: DataFrame with columns quantity, section, zone, position, M, S,
    D, D_norm (= D / std limit) — the normalised residual pattern; built on first use
    (``pairs_table`` holds the function that builds it until then), so a verdict that
    nobody draws costs no DataFrame (nor the import of pandas)."""

    validated: bool
    coverage: Coverage
    quantities: dict[str, QuantityResult]
    vehicle: Vehicle
    n_boot: int
    seed: int
    ci_level: float
    pairs_table: object  # pandas.DataFrame, or a function without arguments returning it
    warnings: list[str] = field(default_factory=list)
    #: free-form context added by callers (campaign, configuration, cache statistics)
    info: dict = field(default_factory=dict)
    #: :func:`railval.core.supplementary.supplementary_results` (empty: no supplementary values)
    supplementary: dict = field(default_factory=dict)
    #: reading id → validated under that reading (empty: no alternatives carried)
    validated_under: dict = field(default_factory=dict)

    @property
    def pairs(self):
        """The per-pair table (pandas.DataFrame), built on first use."""
        if callable(self.pairs_table):
            self.pairs_table = self.pairs_table()
        return self.pairs_table

    @property
    def definition_sensitive(self) -> bool | None:
        """True when some reading of the open definitions flips the verdict."""
        if not self.validated_under:
            return None
        return any(v != self.validated for v in self.validated_under.values())

    def to_dict(self) -> dict:
        from railval.core.en14363 import PROCESSING_VERSION

        return {
            "validated": self.validated,
            "coverage": self.coverage.to_dict(),
            "quantities": [q.to_dict() for q in self.quantities.values()],
            "std_ddof": STD_DDOF,
            "std_definition": STD_DEFINITION,
            "vehicle": self.vehicle.to_dict(),
            "bootstrap": {"n_boot": self.n_boot, "seed": self.seed, "ci_level": self.ci_level,
                          "method": "percentile interval, pairs resampled with replacement"},
            "processing_version": PROCESSING_VERSION,
            "warnings": list(self.warnings),
            "definitions": {
                "chosen": CHOSEN.to_dict(),
                "readings": [r.to_dict() for r in READINGS],
                "sensitive_quantities": [q for q, r in self.quantities.items()
                                         if r.definition_sensitive],
                "verdict_sensitive": self.definition_sensitive,
                "validated_under": dict(self.validated_under),
            },
            "supplementary": {k: v for k, v in self.supplementary.items() if k != "pairs"},
            **({"info": self.info} if self.info else {}),
        }

    def to_pandas(self):
        import pandas as pd

        rows = []
        for q in self.quantities.values():
            d = q.to_dict()
            d.pop("drilldown")
            d.pop("definition_alternatives")
            d["definition_flips"] = ", ".join(d["definition_flips"])
            d["mean_norm_ci_low"], d["mean_norm_ci_high"] = d.pop("mean_norm_ci")
            d["std_norm_ci_low"], d["std_norm_ci_high"] = d.pop("std_norm_ci")
            rows.append(d)
        return pd.DataFrame(rows).set_index("quantity")


def validate(measured_values: Mapping[str, Mapping[tuple[str, str], float]],
             simulated_values: Mapping[str, Mapping[tuple[str, str], float]],
             sections: Sequence[SectionInfo] | Mapping[str, SectionInfo],
             vehicle, *, n_boot: int = 1000, seed: int = 0, ci_level: float = 0.95,
             top: int = 5, warnings: Sequence[str] = (), memo: dict | None = None
             ) -> ValidationResult:
    """Validate one configuration from in-memory values (Polach & Böttcher 2014 §5).

    Three steps: gather the pairs of every quantity (:func:`_gather_pairs`, as arrays),
    compute the D_v statistics per quantity (:func:`quantity_result`) and the coverage
    (:func:`coverage`), then the verdict under the other readings of the open definitions and
    the supplementary results.

    Parameters
    ----------
    measured_values, simulated_values : mapping
        ``{section_id: {(quantity_id, position): value}}`` in the units of the quantity
        registry; a pair exists where both hold a finite value. Values carrying
        ``value_under`` (``railval.core.en14363.SectionValues``) add the definition
        sensitivity, values carrying ``supplementary`` the supplementary results.
    sections : sequence or mapping of SectionInfo
        Every section with values (its zone is used for the coverage).
    vehicle : Vehicle or mapping
        Anything :meth:`Vehicle.from_any` accepts (kind, secondary suspension, Q0 in kN).
    n_boot : int
        Bootstrap resamples of the normalised values (0: no intervals), seeded by ``seed``.
    seed : int
        Seed of the bootstrap.
    ci_level : float
        Confidence level of the percentile intervals, in (0, 1).
    top : int
        Pairs listed per quantity in the drill-down (largest |D_v| / std limit first).
    warnings : sequence of str
        Processing warnings carried into the result.
    memo : dict, optional
        Kept by the caller across the validations of several configurations against the
        same measured values (unchanged meanwhile): the measured side's columns are built
        once and reused (:func:`railval.core.pairing.gather_pairs`; the same numbers).

    Returns
    -------
    ValidationResult
        Verdict, coverage, per-quantity statistics and the per-pair table.

    Raises
    ------
    InvalidParameter
        Bad ``n_boot``/``ci_level``, a section without SectionInfo, an unknown quantity.
    """
    if n_boot < 0:
        raise InvalidParameter(f"n_boot must be ≥ 0, got {n_boot}")
    if not 0.0 < ci_level < 1.0:
        raise InvalidParameter(f"ci_level must be in (0, 1), got {ci_level}")
    veh = Vehicle.from_any(vehicle)
    secs = dict(sections) if isinstance(sections, Mapping) else {s.id: s for s in sections}
    common = sorted(set(measured_values) & set(simulated_values))
    pairs = gather_pairs(measured_values, simulated_values, secs, common, memo)
    results = _quantity_results(pairs, veh, n_boot, seed, ci_level, top)
    zone_of = {sid: int(info.zone) for sid, info in secs.items()}
    cov = coverage({q: set(pairs.of(qi).section) for qi, q in enumerate(QUANTITY_IDS)},
                   {q: set(pairs.of(qi).position) for qi, q in enumerate(QUANTITY_IDS)},
                   {q: pairs.of(qi).n for qi, q in enumerate(QUANTITY_IDS)}, zone_of)
    validated = cov.ok and all(r.passed for r in results.values())
    validated_under: dict[str, bool] = {}
    if bool(common) and all(hasattr(measured_values[sid], "value_under")
                            and hasattr(simulated_values[sid], "value_under") for sid in common):
        validated_under = _verdicts_under_readings(results, pairs, measured_values,
                                                   simulated_values, cov.ok, memo)
    supp = _supplementary(measured_values, simulated_values, common, zone_of)
    return ValidationResult(validated, cov, results, veh, n_boot, seed, ci_level,
                            functools.partial(_pairs_frame, pairs, results), list(warnings),
                            supplementary=supp, validated_under=validated_under)


def _quantity_results(pairs: Pairs, veh: Vehicle, n_boot: int, seed: int, ci_level: float,
                      top: int) -> dict[str, QuantityResult]:
    """:func:`quantity_result` of every quantity (bootstrap seeded by (seed, quantity
    index)), the intervals of all quantities from one percentile call
    (:func:`railval.core.bootstrap.bootstrap_cis`)."""
    parts = [pairs.of(qi) for qi in range(len(QUANTITY_IDS))]
    ds = [difference(p.s, p.m) for p in parts]
    with stage("bootstrap"):
        cis = bootstrap_cis([_resampled_rows(d, n_boot=n_boot, seed_key=(seed, qi))
                             for qi, d in enumerate(ds)],
                            [_limits(QUANTITIES[q], veh) for q in QUANTITY_IDS], ci_level)
    return {qid: quantity_result(qid, parts[qi], veh, n_boot=n_boot, seed_key=(seed, qi),
                                 ci_level=ci_level, top=top, _d=ds[qi], _cis=cis[qi])
            for qi, qid in enumerate(QUANTITY_IDS)}


def _pairs_frame(pairs: Pairs, results: Mapping[str, QuantityResult]):
    """``ValidationResult.pairs``: quantity, section, zone, position, M, S, D, D_norm,
    quantities in registry order."""
    import pandas as pd

    parts = [pairs.of(qi) for qi in range(len(QUANTITY_IDS))]
    if any(p.n == 0 for p in parts):  # the per-quantity frames fix the empty columns' dtypes
        return pd.concat([pd.DataFrame(_frame_columns(q, p, results[q].std_limit))
                          for q, p in zip(QUANTITY_IDS, parts, strict=True)],
                         ignore_index=True)
    cols = [_frame_columns(q, p, results[q].std_limit)
            for q, p in zip(QUANTITY_IDS, parts, strict=True)]
    return pd.DataFrame({
        "quantity": [q for q, p in zip(QUANTITY_IDS, parts, strict=True) for _ in range(p.n)],
        **{k: [x for c in cols for x in c[k]] for k in ("section", "zone", "position")},
        **{k: np.concatenate([c[k] for c in cols]) for k in ("M", "S", "D", "D_norm")}})


def _frame_columns(qid: str, p: QuantityPairs, std_limit: float) -> dict[str, Any]:
    d = difference(p.s, p.m)
    return {"quantity": qid, "section": p.section, "zone": p.zone, "position": p.position,
            "M": p.m, "S": p.s, "D": d, "D_norm": d / std_limit}


def quantity_result(qid: str, pairs: QuantityPairs, vehicle: Vehicle, *, n_boot: int,
                    rng: np.random.Generator | None = None, ci_level: float = 0.95,
                    top: int = 5, seed_key: tuple | None = None, _d=None,
                    _cis=None) -> QuantityResult:
    """D_v statistics of one quantity over its pairs (Polach & Böttcher 2014 §5, eq. 4).

    Parameters
    ----------
    qid : str
        Quantity id of :data:`railval.core.quantities.QUANTITIES`.
    pairs : QuantityPairs
        The pairs of the quantity (section, zone, position, M, S).
    vehicle : Vehicle
        What the limits depend on (Table 2).
    n_boot, rng, ci_level, seed_key
        Bootstrap of the normalised values (:func:`bootstrap_norm_ci`).
    top : int
        Pairs listed in the drill-down.
    _d, _cis
        D_v of the pairs and the intervals, when the caller computed them
        (:func:`validate`: the intervals of all quantities at once, :func:`bootstrap_cis`).

    Returns
    -------
    QuantityResult
        The statistics; the per-pair columns are built by ``_Pairs.frame``.
    """
    q = QUANTITIES[qid]
    mean_limit, std_limit = _limits(q, vehicle)
    m, s = pairs.m, pairs.s
    d = difference(s, m) if _d is None else _d
    n = d.size
    mean = float(d.mean()) if n else float("nan")
    std = float(d.std(ddof=STD_DDOF)) if n >= 2 else float("nan")
    if _cis is not None:  # computed by the caller (validate: all quantities at once)
        mci, sci = _cis
    else:
        with stage("bootstrap"):
            mci, sci = bootstrap_norm_ci(d, mean_limit, std_limit, n_boot=n_boot, rng=rng,
                                         ci_level=ci_level, seed_key=seed_key)
    d_norm = d / std_limit
    ss = float(np.sum(d * d))
    order = np.argsort(-np.abs(d_norm), kind="stable")[:top].tolist()
    drill = [{"section": pairs.section[i], "zone": pairs.zone[i], "position": pairs.position[i],
              "M": float(m[i]), "S": float(s[i]), "D": float(d[i]),
              "D_norm": float(d_norm[i]),
              "share_of_sum_of_squares": float(d[i] ** 2 / ss) if ss > 0 else 0.0}
             for i in order]
    return QuantityResult(qid, q.unit, n, len(set(pairs.position)), len(set(pairs.section)),
                          mean, std, mean_limit, std_limit, mci, sci, drill)


def _limits(q, vehicle: Vehicle) -> tuple[float, float]:
    """(mean limit, std limit) of quantity ``q`` for ``vehicle`` (Table 2)."""
    return (q.mean_limit(vehicle.Q0_kN, vehicle.kind, vehicle.secondary_suspension),
            q.std_limit(vehicle.Q0_kN, vehicle.kind, vehicle.secondary_suspension))


def _verdicts_under_readings(results: dict[str, QuantityResult], pairs: Pairs,
                             measured_values, simulated_values, coverage_ok: bool,
                             memo: dict | None = None) -> dict[str, bool]:
    """Fill every quantity's ``alternatives`` and return reading id → validated under that
    reading (a quantity whose reading is undefined keeps its chosen pass/fail)."""
    m_under = values_under(pairs, measured_values, 2, memo)
    s_under = values_under(pairs, simulated_values, 3)
    rids = list(m_under)  # every reading's column stacked once, the quantities' rows taken
    stacked = (np.stack([m_under[r] for r in rids]), np.stack([s_under[r] for r in rids]),
               {r: k for k, r in enumerate(rids)}) if rids else None
    for qi, (qid, res) in enumerate(results.items()):
        res.alternatives = _alternatives(qid, res, pairs.of(qi), m_under, s_under, stacked)
    validated_under: dict[str, bool] = {}
    by_reading = []  # per quantity: its pass/fail and reading id → its first alternative
    for res in results.values():
        first: dict = {}
        for a in res.alternatives:
            first.setdefault(a["reading"]["id"], a)
        by_reading.append((res.passed, first))
    for reading in READINGS:
        if reading == CHOSEN:
            continue
        ok = []
        for passed, first in by_reading:
            alt = first.get(reading.id)
            ok.append(passed if alt is None or alt["pass"] is None else alt["pass"])
        validated_under[reading.id] = bool(coverage_ok and all(ok))
    return validated_under

def _supplementary(measured_values, simulated_values, common: Sequence[str],
                   zone_of: Mapping[str, int]) -> dict:
    """:func:`railval.core.supplementary.supplementary_results` when every common section
    carries supplementary values on both sides, else ``{}``."""
    if not (common and all(getattr(measured_values[s], "supplementary", None) is not None and
                           getattr(simulated_values[s], "supplementary", None) is not None
                           for s in common)):
        return {}
    return supplementary_results({s: measured_values[s].supplementary for s in common},
                                 {s: simulated_values[s].supplementary for s in common},
                                 {s: zone_of[s] for s in common if s in zone_of})


@functools.cache
def _reading_text(reading, sliding_mean: bool) -> tuple[dict, list, str, str]:
    """The constant descriptions of a reading for a quantity (built once)."""
    return (reading.to_dict(), reading.differs_from_chosen(sliding_mean),
            reading.describe(sliding_mean), reading.short(sliding_mean))


def _alternatives(qid: str, res: QuantityResult, pairs: QuantityPairs,
                  m_under: Mapping[str, np.ndarray], s_under: Mapping[str, np.ndarray],
                  stacked: tuple | None = None) -> list[dict]:
    """Mean, std and pass/fail of one quantity under each reading that can change it, over
    the pairs of the chosen reading. ``pass`` is None where the reading is undefined for
    some pair (NaN value, e.g. a sample window without samples). Every reading is a row of
    one array (row-wise mean and std: the same sums per row as one reading at a time)."""
    sliding = QUANTITIES[qid].sliding_mean
    readings = alternatives_for(QUANTITIES[qid])
    if not readings:
        return []
    if stacked is None:
        m = np.stack([m_under[r.id] for r in readings])[:, pairs.index]
        s = np.stack([s_under[r.id] for r in readings])[:, pairs.index]
    else:  # ``m_under``/``s_under`` stacked by the caller (rows: reading id → row)
        at = np.ix_([stacked[2][r.id] for r in readings], pairs.index)
        m, s = stacked[0][at], stacked[1][at]
    changed = ((m != pairs.m) | (s != pairs.s)).sum(axis=1).tolist()
    d = difference(s, m)
    n = d.shape[1]
    defined = np.isfinite(d).all(axis=1).tolist()
    nan = float("nan")
    means, stds = [nan] * len(readings), [nan] * len(readings)
    rows = [k for k, ok in enumerate(defined) if ok]  # statistics of defined readings only
    if n and rows:
        for k, v in zip(rows, d[rows].mean(axis=1).tolist(), strict=True):
            means[k] = v
    if n >= 2 and rows:
        for k, v in zip(rows, d[rows].std(axis=1, ddof=STD_DDOF).tolist(), strict=True):
            stds[k] = v
    out = []
    for k, reading in enumerate(readings):
        mean, std = means[k], stds[k]
        passed = judge(n, mean, std, res.mean_limit, res.std_limit) if defined[k] else None
        as_dict, differs, description, label = _reading_text(reading, sliding)
        out.append({
            "reading": dict(as_dict), "differs_in": list(differs),
            "description": description, "label": label,
            "values_changed": int(changed[k]),
            "mean": _none_if_nan(mean), "std": _none_if_nan(std),
            "mean_norm": _none_if_nan(mean / res.mean_limit),
            "std_norm": _none_if_nan(std / res.std_limit),
            "pass": passed,
            "flips": passed is not None and passed != res.passed,
        })
    return out


def source_warnings(label: str, values: Mapping[str, Any]) -> list[str]:
    """The processing warnings of one source's section values (``SectionValues.warnings``),
    each prefixed with ``label`` ("measurement", "configuration X"), sections in id order.

    Parameters
    ----------
    label : str
        Names the source in every warning.
    values : mapping of section id → SectionValues
        One source's evaluated sections.

    Returns
    -------
    list of str
    """
    return [f"{label}: {w}" for sid in sorted(values) for w in values[sid].warnings]


def validate_signalsets(measured: Mapping[str, SignalSet], simulated: Mapping[str, SignalSet],
                        sections: Sequence[SectionInfo], vehicle, *, order: int = DEFAULT_ORDER,
                        n_boot: int = 1000, seed: int = 0) -> ValidationResult:
    """:func:`validate` of in-memory signal sets (section id → SignalSet on each side),
    processed with :func:`railval.core.en14363.evaluate_present`. ``vehicle``: a
    :class:`Vehicle` or a mapping with ``kind``, ``secondary_suspension``, ``Q0_kN``. Sections
    missing on either side are skipped (and show up in the coverage).

    Parameters
    ----------
    measured, simulated : mapping of section id → SignalSet
        The recorded signals of each side.
    sections : sequence of SectionInfo
        Every section (zone and evaluated range).
    vehicle : Vehicle or mapping
        What the limits depend on.
    order : int
        Butterworth prototype order of the EN filters.
    n_boot, seed : int
        Bootstrap of the normalised values.

    Returns
    -------
    ValidationResult
    """
    m_values = evaluate_present(measured, sections, order=order)
    s_values = evaluate_present(simulated, sections, order=order)
    warnings = source_warnings("measurement", m_values) + source_warnings("simulation", s_values)
    return validate(m_values, s_values, sections, vehicle, n_boot=n_boot, seed=seed, warnings=warnings)


def normalised_errors(result: ValidationResult) -> dict[str, Any]:
    """How far a configuration is from validated, per quantity and overall: each quantity's
    ``mean_norm`` (mean D_v / mean limit), ``std_norm`` (std D_v / std limit) and
    ``error`` = max(|mean_norm|, std_norm) (Polach & Böttcher 2014 §5: validated when every
    error ≤ 1); ``max_error`` the largest (None when nothing is finite) and ``validated``.
    The lineage of a configuration (root → it) is drawn from these.

    Parameters
    ----------
    result : ValidationResult

    Returns
    -------
    dict
        ``validated``, ``max_error`` and per quantity ``mean_norm``, ``std_norm``, ``error``.
    """
    def finite(x: float | None) -> float | None:
        return float(x) if x is not None and math.isfinite(x) else None

    quantities = {q: {"mean_norm": finite(r.mean_norm), "std_norm": finite(r.std_norm),
                      "error": finite(max(abs(r.mean_norm), abs(r.std_norm)))}
                  for q, r in result.quantities.items()}
    worst = max((v["error"] for v in quantities.values() if v["error"] is not None), default=None)
    return {"validated": bool(result.validated), "max_error": worst, "quantities": quantities}
