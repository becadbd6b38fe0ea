"""Diagnosis: which missing physical effect explains the residual of a configuration
(docs/design.md §7).

Residual pattern
----------------
A :class:`Pattern` is a vector of dimensionless components with labels and groups:

* per quantity × test zone × signal position: the mean over the sections of the normalised
  difference D_v / std-limit (D_v = (S_v − M_v)·sign(M_v), Polach & Böttcher 2014 §5; the limit from Table 2
  via the validation), label ``"Y_qst zone 4 w1L"``, group the quantity id — built by
  :func:`pattern_from_pairs`;
* per car body acceleration channel × frequency band: log-ratio of the band powers of
  simulation and measurement (Welch PSD, :func:`railval.core.psd.welch_psd`), ln(P_sim/P_meas)/ln 2,
  so a factor-2 power error counts 1 — the same order as a normalised D_v at its limit;
  label ``"psd az_cb_b1 5-10 Hz"``, group ``"psd az"`` — built by :func:`psd_band_pattern`.

"Whitened": every component is dimensionless (value/limit or log₂ ratio) and each group gets
the weight 1/√(number of its components), so every quantity carries the same total weight
whatever its number of positions and zones (Y has eight wheels, ay two sensors).

Signature and explained share
-----------------------------
For an effect e not in the configuration, the caller simulates the configuration + e at a few
values v of one parameter (all others at their defaults) over the campaign's sections and
builds the pattern P_e(v) of each. The signature is what adding e removes from the residual,
s_e(v) = r − P_e(v), with r the pattern of the configuration itself. The pattern is
interpolated linearly between the simulated values and v* minimises ‖P_e(v)‖_W on a fine grid
(a bounded 1-D search); the explained share is
``explained = clip(1 − ‖r − s_e(v*)‖²_W / ‖r‖²_W, 0, 1)`` (W the group weights). For an effect
with several parameters each parameter is scanned and the best is kept.

A candidate *fixes* a quantity whose weighted residual falls by more than ``change`` (default
20 %) and *worsens* one whose residual grows by more than that. When the two best candidates
explain shares within ``margin`` (0.1) and their signatures are correlated above
``correlation`` (0.9, cosine in the W metric) they are reported as not separable, with the
pattern components where their signatures differ most as the evidence to look at.

References
----------
Polach & Böttcher 2014, §5: D_v, limits, zones. docs/design.md §7 (this procedure).
Welch 1967 (PSD estimate, via :mod:`railval.core.psd`).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.psd import welch_psd

__all__ = [
    "DEFAULT_BANDS_HZ",
    "Candidate",
    "DiagnosisResult",
    "ParameterScan",
    "Pattern",
    "PatternGrid",
    "band_powers",
    "band_ratio_pattern",
    "diagnose_patterns",
    "difference_pairs",
    "fit_scan",
    "pattern_from_pairs",
    "pattern_grids",
    "psd_band_pattern",
    "scan_values",
    "where_grid",
]

#: Frequency bands (Hz) of the car body acceleration log-PSD ratios: body modes (0.4–2),
#: bogie/suspension range (2–5), upper band of the EN filter (5–10).
DEFAULT_BANDS_HZ: tuple[tuple[float, float], ...] = ((0.4, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0))


@dataclass
class Pattern:
    """Labelled dimensionless residual vector; ``groups[i]`` names the quantity of component i."""

    labels: list[str]
    groups: list[str]
    values: np.ndarray

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=float)
        if not (len(self.labels) == len(self.groups) == self.values.size):
            raise InvalidSignal(
                f"pattern needs equal numbers of labels ({len(self.labels)}), groups ({len(self.groups)}) "
                f"and values ({self.values.size})")

    def weights(self) -> np.ndarray:
        """Per-component weight 1/√n_group (each group's total weight is 1)."""
        count: dict[str, int] = defaultdict(int)
        for g in self.groups:
            count[g] += 1
        return np.array([1.0 / math.sqrt(count[g]) for g in self.groups])

    def norm2(self, values: np.ndarray | None = None) -> float:
        v = self.values if values is None else values
        w = self.weights()
        return float(np.sum((w * v) ** 2))

    def aligned(self, labels: Sequence[str], groups: Sequence[str]) -> Pattern:
        """This pattern on another label set (missing components are 0 — nothing to explain)."""
        idx = {lab: k for k, lab in enumerate(self.labels)}
        vals = np.array([self.values[idx[lab]] if lab in idx else 0.0 for lab in labels])
        return Pattern(list(labels), list(groups), vals)

    def group_norms(self, values: np.ndarray | None = None) -> dict[str, float]:
        v = self.values if values is None else values
        out: dict[str, float] = defaultdict(float)
        for g, x in zip(self.groups, v, strict=True):
            out[g] += float(x) ** 2
        cnt: dict[str, int] = defaultdict(int)
        for g in self.groups:
            cnt[g] += 1
        return {g: math.sqrt(out[g] / cnt[g]) for g in out}

    @staticmethod
    def concat(*patterns: Pattern) -> Pattern:
        labels: list[str] = []
        groups: list[str] = []
        vals: list[np.ndarray] = []
        for p in patterns:
            labels += p.labels
            groups += p.groups
            vals.append(p.values)
        return Pattern(labels, groups, np.concatenate(vals) if vals else np.zeros(0))

    def to_dict(self) -> dict[str, Any]:
        return {"labels": list(self.labels), "groups": list(self.groups), "values": self.values.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Pattern:
        """Inverse of :meth:`to_dict` (a stored run read back)."""
        return cls(list(d["labels"]), list(d["groups"]), np.asarray(d["values"], dtype=float))


def pattern_from_pairs(pairs: Iterable[Mapping[str, Any]], *, value_key: str = "norm") -> Pattern:
    """Aggregate per-pair normalised differences into the quantity × zone × position pattern.

    Each record needs ``quantity``, ``zone``, ``position`` and ``value_key`` (D_v divided by
    the quantity's std limit, dimensionless); the component is the mean over the sections of
    that (quantity, zone, position). Non-finite values are skipped. Components are ordered by
    quantity, zone, position.
    """
    acc: dict[tuple[str, int, str], list[float]] = defaultdict(list)
    for r in pairs:
        v = float(r[value_key])
        if math.isfinite(v):
            acc[(str(r["quantity"]), int(r["zone"]), str(r["position"]))].append(v)
    if not acc:
        raise InvalidSignal(f"no finite '{value_key}' values in the validation pairs")
    keys = sorted(acc)
    return Pattern([f"{q} zone {z} {p}" for q, z, p in keys], [q for q, _, _ in keys],
                   np.array([float(np.mean(acc[k])) for k in keys]))


def difference_pairs(measured: Mapping[str, Mapping[tuple[str, str], float]],
                     simulated: Mapping[str, Mapping[tuple[str, str], float]],
                     zones: Mapping[str, int], std_limits: Mapping[str, float]) -> list[dict[str, Any]]:
    """Normalised differences of every (section, quantity, position) present in both sources.

    ``measured[section][(quantity, position)]`` = M_v, ``simulated[…]`` = S_v (EN 14363
    section values, e.g. :func:`railval.core.en14363.evaluate_batch`); D_v = (S_v − M_v)·M_v/|M_v|, and
    D_v = S_v where M_v = 0 (Polach & Böttcher 2014 §5, docs/design.md §3); ``norm`` = D_v / std limit of the
    quantity (Table 2). Records: ``section, zone, quantity, position, D_v, norm``.
    """
    out = []
    for sid, mv in measured.items():
        sv = simulated.get(sid)
        if sv is None:
            continue
        for key, m in mv.items():
            if key not in sv:
                continue
            q, pos = key
            s = float(sv[key])
            m = float(m)
            d = (s - m) * math.copysign(1.0, m) if m != 0 else s
            out.append({"section": sid, "zone": int(zones[sid]), "quantity": q, "position": pos,
                        "D_v": d, "norm": d / float(std_limits[q])})
    return out


def band_powers(x: np.ndarray, fs: float, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                segment_s: float = 10.0) -> np.ndarray:
    """Power of ``x`` (unit²) in each band [lo, hi) Hz: the Welch PSD (:func:`railval.core.psd.welch_psd`,
    ``segment_s`` segments) summed over the band's bins times the bin width."""
    psd = welch_psd(np.asarray(x, float), fs, segment_s=segment_s)
    f, d = np.asarray(psd.frequency_hz), np.asarray(psd.density)
    df = f[1] - f[0]
    return np.array([float(np.sum(d[(f >= lo) & (f < hi)]) * df) for lo, hi in bands])


def band_ratio_pattern(simulated: Mapping[str, np.ndarray], measured: Mapping[str, np.ndarray],
                       bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ) -> Pattern:
    """Log₂ ratio of band powers simulated/measured per acceleration channel and band.

    ``simulated[channel]``/``measured[channel]``: band powers (one per band, e.g. summed over
    the sections with :func:`band_powers`). Value ln(P_sim/P_meas)/ln 2 (dimensionless;
    1 = twice the power). Label ``"psd az_cb_b1 5-10 Hz"``, group ``"psd ay"``/``"psd az"``
    from the channel kind. A band without power on either side is skipped.
    """
    labels, groups, vals = [], [], []
    for ch in sorted(set(simulated) & set(measured)):
        for (lo, hi), a, b in zip(bands, np.atleast_1d(simulated[ch]), np.atleast_1d(measured[ch]), strict=True):
            if b > 0 and a > 0:
                labels.append(f"psd {ch} {lo:g}-{hi:g} Hz")
                groups.append(f"psd {ch.split('_')[0]}")
                vals.append(math.log(a / b) / math.log(2.0))
    return Pattern(labels, groups, np.array(vals))


def psd_band_pattern(simulated: Mapping[str, Sequence[np.ndarray]], measured: Mapping[str, Sequence[np.ndarray]],
                     fs: float, *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                     segment_s: float = 10.0) -> Pattern:
    """:func:`band_ratio_pattern` of signals: ``simulated[channel]`` and ``measured[channel]``
    are lists of signals (one per section, m/s², sampled at ``fs`` Hz) whose band powers are
    summed over the sections before the ratio."""
    def total(sets):
        return {ch: sum(band_powers(x, fs, bands, segment_s) for x in xs) for ch, xs in sets.items()}

    return band_ratio_pattern(total(simulated), total(measured), bands)


@dataclass
class ParameterScan:
    """Patterns of configuration + effect at several values of one parameter (others at
    ``defaults``). ``values`` ascending within ``bounds``; ``log``: interpolate in log(value)
    (stiffness-like parameters scanned on a logarithmic grid)."""

    effect: str
    parameter: str
    values: list[float]
    patterns: list[Pattern]
    defaults: dict[str, float] = field(default_factory=dict)
    bounds: tuple[float, float] | None = None
    log: bool = False


@dataclass
class Candidate:
    """One ranked explanation: the effect, the share of the residual its fitted signature
    explains, the fitted parameters, quantities it fixes/worsens (residual RMS before → after
    per group), its physical explanation and its fitted signature."""

    effect: str
    explained: float
    parameters: dict[str, float]
    fixes: list[str]
    worsens: list[str]
    explanation: str
    signature: Pattern
    residual_after: float
    group_change: dict[str, tuple[float, float]] = field(default_factory=dict)

    def to_dict(self, with_signature: bool = False) -> dict[str, Any]:
        d = {"effect": self.effect, "explained": self.explained, "parameters": dict(self.parameters),
             "fixes": list(self.fixes), "worsens": list(self.worsens), "explanation": self.explanation,
             "residual_after": self.residual_after,
             "quantities": {g: {"before": a, "after": b} for g, (a, b) in self.group_change.items()}}
        if with_signature:
            d["signature"] = self.signature.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Candidate:
        """Inverse of :meth:`to_dict` with ``with_signature=True``."""
        return cls(effect=d["effect"], explained=float(d["explained"]),
                   parameters={k: float(v) for k, v in d["parameters"].items()},
                   fixes=list(d["fixes"]), worsens=list(d["worsens"]), explanation=d["explanation"],
                   signature=Pattern.from_dict(d["signature"]), residual_after=float(d["residual_after"]),
                   group_change={g: (float(v["before"]), float(v["after"]))
                                 for g, v in d.get("quantities", {}).items()})


@dataclass
class DiagnosisResult:
    """Ranked candidates plus the separability verdict between the two best."""

    residual: Pattern
    candidates: list[Candidate]
    separable: bool
    evidence: list[dict[str, Any]]
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self, with_signatures: bool = False) -> dict[str, Any]:
        """Plain dict; ``with_signatures`` adds the residual's components (``labels``,
        ``values``) and every candidate's fitted signature (for plots of where it acts)."""
        residual: dict[str, Any] = {"norm": math.sqrt(self.residual.norm2()),
                                    "groups": self.residual.group_norms()}
        if with_signatures:
            residual.update(self.residual.to_dict())
        d = {"candidates": [c.to_dict(with_signature=with_signatures) for c in self.candidates],
             "separable": self.separable, "evidence": list(self.evidence), "note": self.note,
             "residual": residual}
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DiagnosisResult:
        """Inverse of :meth:`to_dict` with ``with_signatures=True`` (a stored run read back);
        the keys beyond the ranked result go to ``extra``."""
        own = {"candidates", "separable", "evidence", "note", "residual"}
        return cls(residual=Pattern.from_dict(d["residual"]),
                   candidates=[Candidate.from_dict(c) for c in d["candidates"]],
                   separable=bool(d["separable"]), evidence=list(d["evidence"]), note=d.get("note", ""),
                   extra={k: v for k, v in d.items() if k not in own})

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{k: v for k, v in c.to_dict().items() if k != "quantities"} for c in self.candidates])


def fit_scan(residual: Pattern, scan: ParameterScan, *, n_fine: int = 401) -> tuple[float, float, np.ndarray]:
    """Bounded 1-D search along one parameter: interpolate the scanned patterns linearly in
    the parameter value (in log(value) when ``scan.log``) and return (v*, ‖P(v*)‖²_W, P(v*))
    minimising the remaining residual.
    With one scanned value it is that value."""
    if len(scan.values) != len(scan.patterns) or not scan.values:
        raise InvalidParameter(
            f"scan of {scan.effect}.{scan.parameter}: {len(scan.values)} values for {len(scan.patterns)} patterns")
    order = np.argsort(scan.values)
    v = np.asarray(scan.values, float)[order]
    P = np.stack([scan.patterns[k].aligned(residual.labels, residual.groups).values for k in order])
    w = residual.weights()
    if v.size == 1:
        return float(v[0]), float(np.sum((w * P[0]) ** 2)), P[0]
    u = np.log(v) if scan.log else v
    fine = np.linspace(u[0], u[-1], n_fine)
    idx = np.clip(np.searchsorted(u, fine, side="right") - 1, 0, u.size - 2)
    t = (fine - u[idx]) / (u[idx + 1] - u[idx])
    Pf = P[idx] * (1 - t)[:, None] + P[idx + 1] * t[:, None]
    cost = np.sum((Pf * w) ** 2, axis=1)
    k = int(np.argmin(cost))
    best = float(np.exp(fine[k])) if scan.log else float(fine[k])
    return best, float(cost[k]), Pf[k]


def diagnose_patterns(residual: Pattern, scans: Mapping[str, Sequence[ParameterScan]], *,
                      explanations: Mapping[str, str] | None = None, margin: float = 0.1,
                      correlation: float = 0.9, change: float = 0.2, n_evidence: int = 3) -> DiagnosisResult:
    """Rank the effects of ``scans`` (effect → one scan per parameter) by explained share of
    ``residual`` (module docstring). Returns :class:`DiagnosisResult`."""
    r2 = residual.norm2()
    if not r2 > 0:
        raise InvalidSignal("the residual pattern is zero: nothing to diagnose")
    w = residual.weights()
    before = residual.group_norms()
    cands: list[Candidate] = []
    for effect, eff_scans in scans.items():
        best = None
        for scan in eff_scans:
            v, cost, P = fit_scan(residual, scan)
            if best is None or cost < best[1]:
                best = (scan, v, cost, P)
        if best is None:
            continue
        scan, v, cost, P = best
        after = residual.group_norms(P)
        fixes = [g for g in before if after[g] < (1 - change) * before[g]]
        worsens = [g for g in before if after[g] > (1 + change) * before[g] + 1e-12]
        params = {**scan.defaults, scan.parameter: v}
        cands.append(Candidate(effect, float(np.clip(1 - cost / r2, 0.0, 1.0)), params,
                               sorted(fixes, key=lambda g: after[g] - before[g]),
                               sorted(worsens, key=lambda g: before[g] - after[g]),
                               (explanations or {}).get(effect, ""),
                               Pattern(residual.labels, residual.groups, residual.values - P),
                               math.sqrt(cost), {g: (before[g], after[g]) for g in before}))
    cands.sort(key=lambda c: -c.explained)
    separable, evidence, note = True, [], ""
    if len(cands) >= 2:
        a, b = cands[0], cands[1]
        sa, sb = a.signature.values * w, b.signature.values * w
        den = float(np.linalg.norm(sa) * np.linalg.norm(sb))
        corr = float(sa @ sb / den) if den > 0 else 0.0
        diff = sa - sb
        for k in np.argsort(-np.abs(diff))[:n_evidence]:
            evidence.append({"component": residual.labels[k], a.effect: float(a.signature.values[k]),
                             b.effect: float(b.signature.values[k]), "residual": float(residual.values[k])})
        if a.explained - b.explained < margin and corr > correlation:
            separable = False
            note = (f"{a.effect} and {b.effect} explain nearly the same share ({a.explained:.2f} vs "
                    f"{b.explained:.2f}) with correlated signatures (r = {corr:.2f}); look at "
                    + ", ".join(e["component"] for e in evidence) + " to separate them")
        else:
            note = (f"{a.effect} explains {a.explained:.2f} of the residual, next {b.effect} "
                    f"{b.explained:.2f} (signature correlation {corr:.2f})")
    return DiagnosisResult(residual, cands, separable, evidence, note)


# ----------------------------------------------------------------------------- grids
@dataclass
class PatternGrid:
    """Components of a residual pattern arranged for a heat map: ``rows`` × ``cols`` with
    ``values[i][j]`` the mean over positions (NaN where nothing was evaluated)."""

    rows: list[str]
    cols: list[str]
    values: np.ndarray


ZONE_COLUMNS = tuple(f"zone {z}" for z in (1, 2, 3, 4))


def _grid(rows: Sequence[str], cols: Sequence[str], acc: Mapping[tuple[str, str], list[float]]) -> PatternGrid:
    m = np.full((len(rows), len(cols)), np.nan)
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            if (r, c) in acc:
                m[i, j] = float(np.mean(acc[(r, c)]))
    return PatternGrid(list(rows), list(cols), m)


def _quantity_zone_grid(acc: Mapping[tuple[str, str], list[float]]) -> PatternGrid:
    from railval.core.quantities import QUANTITY_IDS

    quantities = [q for q in QUANTITY_IDS if any((q, z) in acc for z in ZONE_COLUMNS)]
    return _grid(quantities, ZONE_COLUMNS, acc)


def where_grid(pairs: Mapping[str, Sequence]) -> PatternGrid:
    """Where a configuration fails: the mean of D_v / std limit (Polach & Böttcher 2014 §5)
    over the sections and positions of each quantity × EN 14363 test zone. ``pairs`` has the
    columns ``quantity``, ``zone`` and ``D_norm`` (``railval.core.validation.ValidationResult.pairs``).
    Quantities in the order of :mod:`railval.core.quantities`."""
    acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    for q, z, v in zip(pairs["quantity"], pairs["zone"], np.asarray(pairs["D_norm"], float), strict=True):
        if math.isfinite(v):
            acc[(str(q), f"zone {int(z)}")].append(float(v))
    return _quantity_zone_grid(acc)


def pattern_grids(labels: Sequence[str], values) -> tuple[PatternGrid, PatternGrid]:
    """Arrange a diagnosis pattern (components ``"Y_qst zone 4 w1L"`` = mean normalised D_v
    of a quantity in a zone at a position, and ``"psd az_cb_b1 5-10 Hz"`` = log2 PSD ratio
    simulation/measurement in a band) into (quantity × zone, car body acceleration
    direction × band) grids, averaging over positions."""
    q_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    p_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    bands: list[str] = []
    for label, v in zip(labels, np.asarray(values, float), strict=True):
        if not math.isfinite(v):
            continue
        parts = label.split()
        if parts[0] == "psd":  # psd <channel> <lo-hi> Hz
            kind = parts[1].split("_")[0]
            band = f"{parts[2]} Hz"
            if band not in bands:
                bands.append(band)
            p_acc[(kind, band)].append(v)
        elif len(parts) >= 3 and parts[1] == "zone":
            q_acc[(parts[0], f"zone {parts[2]}")].append(v)
    bands.sort(key=lambda b: float(b.split("-")[0]))
    kinds = [k for k in ("ay", "az") if any((k, b) in p_acc for b in bands)]
    return _quantity_zone_grid(q_acc), _grid(kinds, bands, p_acc)


def scan_values(lower: float, upper: float, default: float, n: int, log: bool = False) -> list[float]:
    """The values of one effect parameter a diagnosis simulates (docs/design.md §7): ``n``
    values spanning [lower, upper] (equally spaced, or geometrically with ``log``) plus the
    default, sorted, unique."""
    grid = np.geomspace(lower, upper, n) if log else np.linspace(lower, upper, n)
    return sorted(set(grid.tolist()) | {float(default)})
