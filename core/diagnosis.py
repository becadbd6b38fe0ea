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
    "PARAMETER_CANDIDATES",
    "Candidate",
    "CandidateFamily",
    "Component",
    "DiagnosisResult",
    "ParameterScan",
    "Pattern",
    "PatternGrid",
    "SectionEvidence",
    "TrustedCandidate",
    "band_powers",
    "band_ratio_pattern",
    "component_parts",
    "diagnose_evidence",
    "diagnose_patterns",
    "difference_pairs",
    "fit_scan",
    "pattern_from_pairs",
    "pattern_grids",
    "plausibility_flags",
    "psd_band_pattern",
    "scan_values",
    "section_evidence",
    "separating_evidence",
    "where_grid",
    "zone_bootstrap",
    "zone_folds",
]

#: Frequency bands (Hz) of the car body acceleration log-PSD ratios: body modes (0.4–2),
#: bogie/suspension range (2–5), upper band of the EN filter (5–10).
DEFAULT_BANDS_HZ: tuple[tuple[float, float], ...] = ((0.4, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0))


@dataclass(frozen=True)
class Component:
    """What one pattern component measures, as fields: a validation pair aggregate
    (``kind="pair"``: ``quantity``, EN 14363 ``zone``, ``position``), a band-power ratio
    (``kind="psd"``: acceleration ``channel``, ``band`` in Hz) or a supplementary quantity
    (``kind="supplementary"``: ``quantity``, ``position``, ``channel`` = its channel kind,
    :mod:`railval.core.supplementary`)."""

    kind: str
    quantity: str = ""
    zone: int = 0
    position: str = ""
    channel: str = ""
    band: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def pair(cls, quantity: str, zone: int, position: str) -> Component:
        return cls("pair", quantity=quantity, zone=int(zone), position=position)

    @classmethod
    def psd(cls, channel: str, band: tuple[float, float]) -> Component:
        return cls("psd", channel=channel, band=(float(band[0]), float(band[1])))

    @classmethod
    def supplementary(cls, quantity: str, position: str, channel_kind: str) -> Component:
        return cls("supplementary", quantity=quantity, position=position, channel=channel_kind)

    @property
    def direction(self) -> str:
        """Of a band-power or supplementary component: the acceleration direction (``"ay"``, ``"az"``)."""
        return self.channel.split("_")[0]

    @property
    def band_label(self) -> str:
        return f"{self.band[0]:g}-{self.band[1]:g} Hz"

    @property
    def label(self) -> str:
        """As shown to a reader: ``"Y_qst zone 4 w1L"``, ``"psd az_cb_b1 5-10 Hz"``."""
        if self.kind == "psd":
            return f"psd {self.channel} {self.band_label}"
        if self.kind == "supplementary":
            return f"supp {self.quantity} {self.position}"
        return f"{self.quantity} zone {self.zone} {self.position}"

    @property
    def group(self) -> str:
        """The weighting group: the quantity id, ``"psd ay"``/``"psd az"`` or ``"bogie ay"``/``"bogie az"``."""
        if self.kind == "psd":
            return f"psd {self.direction}"
        return f"bogie {self.direction}" if self.kind == "supplementary" else self.quantity

    def to_dict(self) -> dict[str, Any]:
        if self.kind == "psd":
            return {"kind": "psd", "channel": self.channel, "band": list(self.band)}
        if self.kind == "supplementary":
            return {"kind": "supplementary", "quantity": self.quantity, "position": self.position,
                    "channel": self.channel}
        return {"kind": "pair", "quantity": self.quantity, "zone": self.zone, "position": self.position}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Component:
        if d["kind"] == "psd":
            return cls.psd(d["channel"], tuple(d["band"]))
        if d["kind"] == "supplementary":
            return cls.supplementary(d["quantity"], d["position"], d["channel"])
        return cls.pair(d["quantity"], d["zone"], d["position"])


@dataclass
class Pattern:
    """Labelled dimensionless residual vector; ``groups[i]`` names the quantity of component i;
    ``components[i]`` (when built from data) says what component i measures, as fields."""

    labels: list[str]
    groups: list[str]
    values: np.ndarray
    components: list[Component] | None = None

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=float)
        if not (len(self.labels) == len(self.groups) == self.values.size):
            raise InvalidSignal(
                f"pattern needs equal numbers of labels ({len(self.labels)}), groups ({len(self.groups)}) "
                f"and values ({self.values.size})")
        if self.components is not None and len(self.components) != len(self.labels):
            raise InvalidSignal(f"pattern has {len(self.components)} components for {len(self.labels)} labels")

    @classmethod
    def of(cls, components: Sequence[Component], values) -> Pattern:
        """A pattern of structured components (labels and groups from them)."""
        comps = list(components)
        return cls([c.label for c in comps], [c.group for c in comps], values, comps)

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
        comps = (None if any(p.components is None for p in patterns)
                 else [c for p in patterns for c in p.components])
        return Pattern(labels, groups, np.concatenate(vals) if vals else np.zeros(0), comps)

    def with_values(self, values) -> Pattern:
        """The same components with other values."""
        return Pattern(self.labels, self.groups, values, self.components)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"labels": list(self.labels), "groups": list(self.groups),
                             "values": self.values.tolist()}
        if self.components is not None:
            d["components"] = [c.to_dict() for c in self.components]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Pattern:
        """Inverse of :meth:`to_dict` (a stored run read back)."""
        comps = d.get("components")
        return cls(list(d["labels"]), list(d["groups"]), np.asarray(d["values"], dtype=float),
                   None if comps is None else [Component.from_dict(c) for c in comps])


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
    return Pattern.of([Component.pair(q, z, p) for q, z, p in keys],
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
    comps, vals = [], []
    for ch in sorted(set(simulated) & set(measured)):
        for band, a, b in zip(bands, np.atleast_1d(simulated[ch]), np.atleast_1d(measured[ch]), strict=True):
            if b > 0 and a > 0:
                comps.append(Component.psd(ch, band))
                vals.append(math.log(a / b) / math.log(2.0))
    return Pattern.of(comps, np.array(vals))


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
        def num(v: Any) -> float:
            return float("nan") if v is None else float(v)  # NaN is stored as null

        base = dict(effect=d["effect"], explained=num(d["explained"]),
                    parameters={k: num(v) for k, v in d["parameters"].items()},
                    fixes=list(d["fixes"]), worsens=list(d["worsens"]), explanation=d["explanation"],
                    signature=Pattern.from_dict(d["signature"]), residual_after=num(d["residual_after"]),
                    group_change={g: (num(v["before"]), num(v["after"]))
                                  for g, v in d.get("quantities", {}).items()})
        if "held_out_explained" not in d:
            return cls(**base)
        ci = d.get("explained_ci") or (0.0, 0.0)
        return TrustedCandidate(
            **base, kind=d.get("kind", "effect"), name=d.get("name", d["effect"]),
            held_out_explained=num(d["held_out_explained"]), explained_ci=(num(ci[0]), num(ci[1])),
            significant=bool(d.get("significant")), plausible=bool(d.get("plausible", True)),
            at_bound=bool(d.get("at_bound")), flags=list(d.get("flags") or []), summary=d.get("summary", ""),
            reference=d.get("reference"), fitted=num(d.get("fitted")), parameter=d.get("parameter", ""),
            fitted_ci=tuple(num(x) for x in (d.get("fitted_ci") or (None, None))),  # older runs: unknown
            clearly_implausible=bool(d.get("clearly_implausible", not d.get("plausible", True))))


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
                               residual.with_values(residual.values - P),
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


# =====================================================================================
# Trustworthy diagnosis on per-section evidence (issue 16): parameter errors as candidates,
# noise floor, held-out share, plausibility, identifiability and a verdict.
# =====================================================================================

#: Vehicle-template parameters tried as candidate causes beside the effects (masses, inertias,
#: stiffnesses and dampings per direction: primary, secondary, yaw dampers). Each entry
#: ``name: (step, low, high)``: ``step`` is the factor of the one perturbed simulation of the
#: linearised sensitivity (stiffness/damping ×0.5 — worn or soft components are the frequent
#: error; masses/inertias ×1.2), ``low``–``high`` the search box as factors of the model's
#: value (log scale, clipped to the template bounds). Names, units, defaults and bounds come
#: from the template registry :mod:`railval.core.sim.vehicles`.
_KC = (0.5, 0.1, 4.0)
_MI = (1.2, 0.5, 2.0)
PARAMETER_CANDIDATES: dict[str, dict[str, tuple[float, float, float]]] = {
    "coach": {"m_carbody": _MI, "I_pitch_carbody": _MI, "I_yaw_carbody": _MI, "m_bogie": _MI,
              "k_primary_x": _KC, "k_primary_y": _KC, "k_primary_z": _KC, "c_primary_z": _KC,
              "k_secondary_y": _KC, "k_secondary_z": _KC, "c_secondary_y": _KC, "c_secondary_z": _KC,
              "c_yaw_damper": _KC},
    "wagon": {"m_body_tare": _MI, "payload": _MI, "k_leaf_z": _KC, "leaf_friction": _KC,
              "link_length": _KC, "link_friction": _KC},
}

#: Verdict thresholds: a cause must explain at least ``STRONG`` of the residual on held-out
#: sections; two candidates "explain alike" when their held-out shares differ by less than
#: ``ALIKE_MARGIN`` and their signatures correlate above ``ALIKE_CORRELATION``.
STRONG = 0.5
ALIKE_MARGIN = 0.15
ALIKE_CORRELATION = 0.8


def component_parts(label: str, group: str) -> dict[str, Any]:
    """Structured view of a pattern component: ``quantity``, ``zone``, ``position`` for a
    quantity × zone × position component (label ``"Y_qst zone 4 w1L"``), ``quantity`` (the
    group, ``"psd az"``), ``channel`` and ``band`` for a band-power component
    (``"psd az_cb_b1 5-10 Hz"``)."""
    words = label.split()
    if group.startswith("psd") and len(words) >= 3:
        return {"quantity": group, "channel": words[1], "band": " ".join(words[2:]), "zone": None,
                "position": None}
    if len(words) >= 4 and words[1] == "zone":
        return {"quantity": words[0], "zone": int(words[2]), "position": " ".join(words[3:]),
                "channel": None, "band": None}
    return {"quantity": group, "zone": None, "position": None, "channel": None, "band": None}


@dataclass
class SectionEvidence:
    """Per-section contributions of one simulated model to the residual pattern, so that the
    pattern of any subset or resample of the sections is a weighted sum (held-out folds and
    the bootstrap need no new simulation).

    ``sums[s, j]``/``counts[s, j]``: sum and number of the normalised differences D_v/limit of
    section s in quantity × zone × position component j (the first ``n_pair`` labels);
    ``sim_power``/``meas_power[s, j]``: band power of section s in band component j (the
    remaining labels). :meth:`values` with section weights w gives
    Σ_s w_s·sums / Σ_s w_s·counts and log₂(Σ_s w_s·P_sim / Σ_s w_s·P_meas) — with all weights 1
    exactly :func:`pattern_from_pairs` + :func:`band_ratio_pattern` of the whole campaign.
    Components without data under the weights are 0 (nothing to explain).
    """

    sections: list[str]
    zones: list[int]
    labels: list[str]
    groups: list[str]
    n_pair: int
    sums: np.ndarray
    counts: np.ndarray
    sim_power: np.ndarray
    meas_power: np.ndarray
    components: list[Component] | None = None

    def values(self, weights: np.ndarray | None = None) -> np.ndarray:
        """Pattern values for section weights (shape (S,) → (n,), or (B, S) → (B, n))."""
        w = np.ones(len(self.sections)) if weights is None else np.asarray(weights, float)
        W = np.atleast_2d(w)
        s, c = W @ self.sums, W @ self.counts
        pv = np.divide(s, c, out=np.zeros_like(s), where=c > 0)
        a, b = W @ self.sim_power, W @ self.meas_power
        ok = (a > 0) & (b > 0)
        bv = np.zeros_like(a)
        bv[ok] = np.log2(a[ok] / b[ok])
        out = np.concatenate([pv, bv], axis=1)
        return out[0] if w.ndim == 1 else out

    def pattern(self, weights: np.ndarray | None = None) -> Pattern:
        comps = None if self.components is None else list(self.components)
        return Pattern(list(self.labels), list(self.groups), self.values(weights), comps)


def section_evidence(pairs: Iterable[Mapping[str, Any]], sim_bands: Mapping[str, Mapping[str, np.ndarray]],
                     meas_bands: Mapping[str, Mapping[str, np.ndarray]], sections: Sequence[tuple[str, int]], *,
                     bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ, value_key: str = "norm",
                     like: SectionEvidence | None = None) -> SectionEvidence:
    """Build :class:`SectionEvidence` from validation pairs (records with ``section``,
    ``quantity``, ``zone``, ``position`` and ``value_key``) and per-section band powers
    (``sim_bands[section][channel]`` = powers per band, e.g. :func:`band_powers`).
    ``sections``: ``(id, zone)`` of every section. ``like``: reuse its component layout (what
    it lacks is dropped, what this one lacks has no data) so that evidences of several
    simulations are comparable component by component."""
    sids = [s for s, _ in sections]
    row = {s: k for k, s in enumerate(sids)}
    recs = []
    for r in pairs:
        v = float(r[value_key])
        if math.isfinite(v) and str(r["section"]) in row:
            recs.append((row[str(r["section"])], (str(r["quantity"]), int(r["zone"]), str(r["position"])), v))
    if like is None:
        keys = sorted({k for _, k, _ in recs})
        chans = sorted({c for d in sim_bands.values() for c in d} & {c for d in meas_bands.values() for c in d})
        comps = ([Component.pair(q, z, p) for q, z, p in keys]
                 + [Component.psd(ch, band) for ch in chans for band in bands])
        labels, groups, n_pair = [c.label for c in comps], [c.group for c in comps], len(keys)
    else:
        labels, groups, n_pair = list(like.labels), list(like.groups), like.n_pair
        comps = None if like.components is None else list(like.components)
    col = {lab: j for j, lab in enumerate(labels[:n_pair])}
    sums = np.zeros((len(sids), n_pair))
    counts = np.zeros((len(sids), n_pair))
    for i, (q, z, p), v in recs:
        j = col.get(f"{q} zone {z} {p}")
        if j is not None:
            sums[i, j] += v
            counts[i, j] += 1
    nb = len(labels) - n_pair
    sim_p, meas_p = np.zeros((len(sids), nb)), np.zeros((len(sids), nb))
    bcol = {lab: j for j, lab in enumerate(labels[n_pair:])}
    for src, dst in ((sim_bands, sim_p), (meas_bands, meas_p)):
        for sid, chans in src.items():
            if sid not in row:
                continue
            for ch, powers in chans.items():
                for (lo, hi), x in zip(bands, np.atleast_1d(powers), strict=True):
                    j = bcol.get(f"psd {ch} {lo:g}-{hi:g} Hz")
                    if j is not None:
                        dst[row[sid], j] = float(x)
    return SectionEvidence(sids, [int(z) for _, z in sections], labels, groups, n_pair, sums, counts, sim_p, meas_p,
                           comps)


@dataclass
class CandidateFamily:
    """A candidate cause and its simulated evidence along one parameter.

    ``kind`` ``"effect"`` (``name`` = effect id; ``values`` the scanned values of
    ``parameter``, the others at ``defaults``) or ``"parameter"`` (``name`` = ``model.PARAM``;
    ``values`` = the model's value ``reference`` and one perturbed value: a linearised
    sensitivity, extrapolated linearly in log(value) over ``bounds``). ``evidence[k]`` belongs
    to ``values[k]``. ``plausible``: physically plausible range (``plausible_source`` cites it).
    """

    kind: str
    name: str
    parameter: str
    values: list[float]
    evidence: list[SectionEvidence]
    bounds: tuple[float, float]
    log: bool = False
    extrapolate: bool = False
    defaults: dict[str, float] = field(default_factory=dict)
    reference: float | None = None
    plausible: tuple[float, float] | None = None
    plausible_source: str = ""
    unit: str = ""
    title: str = ""
    explanation: str = ""


def _u(v: np.ndarray | float, log: bool):
    return np.log(v) if log else v


class _Curve:
    """Piecewise-linear pattern curve of a family along u = value or log(value) (with linear
    extrapolation beyond the simulated values when the family asks for it)."""

    def __init__(self, fam: CandidateFamily, n_fine: int = 201):
        order = np.argsort(fam.values)
        self.v = np.asarray(fam.values, float)[order]
        self.order = order
        self.log = fam.log
        u = _u(self.v, fam.log)
        if u.size < 2 or np.any(np.diff(u) <= 0):
            raise InvalidParameter(f"candidate {fam.name}: needs ≥ 2 distinct simulated values, got {fam.values}")
        lo, hi = (fam.bounds if fam.extrapolate else (self.v[0], self.v[-1]))
        self.range = (float(lo), float(hi))
        self.fine = np.linspace(float(_u(lo, fam.log)), float(_u(hi, fam.log)), n_fine)
        idx = np.clip(np.searchsorted(u, self.fine, side="right") - 1, 0, u.size - 2)
        self.idx = idx
        self.t = (self.fine - u[idx]) / (u[idx + 1] - u[idx])
        self.u = u

    def patterns(self, P: np.ndarray) -> np.ndarray:
        """Fine-grid patterns (F, n) from the simulated ones ``P`` (K, n) in family order."""
        P = P[self.order]
        return P[self.idx] * (1 - self.t)[:, None] + P[self.idx + 1] * self.t[:, None]

    def value(self, k: int) -> float:
        """The value at fine-grid point ``k``: the range's ends exactly at the ends, inside the
        range elsewhere (exp(log(bound)) may round past the bound by one ulp, which a later
        simulation would refuse)."""
        if k in (0, self.fine.size - 1, -1):
            return self.range[0] if k == 0 else self.range[1]
        x = float(self.fine[k])
        return float(min(max(float(np.exp(x)) if self.log else x, self.range[0]), self.range[1]))


def _min_cost(curve: _Curve, P: np.ndarray, w: np.ndarray, argmin: bool = False):
    """min over the curve's range of ‖w·P(u)‖² for many node sets at once: ``P`` (B, K, n) in
    family order → (B,). Exact on each linear segment (a quadratic in the segment parameter,
    minimised in closed form and clipped to the segment; the first and last segments extend
    to the ends of the range when the family extrapolates). ``argmin=True``: also the values
    (in the parameter's unit, inside the range) where the minima lie."""
    P = P[:, curve.order, :] * w
    u = curve.u
    lo_end, hi_end = float(curve.fine[0]), float(curve.fine[-1])
    best = np.full(P.shape[0], np.inf)
    where = np.full(P.shape[0], lo_end)
    for j in range(u.size - 1):
        du = u[j + 1] - u[j]
        t_lo = (lo_end - u[j]) / du if j == 0 else 0.0
        t_hi = (hi_end - u[j]) / du if j == u.size - 2 else 1.0
        if t_hi < t_lo:
            continue
        a, d = P[:, j, :], P[:, j + 1, :] - P[:, j, :]
        dd = np.sum(d * d, axis=1)
        ad = np.sum(a * d, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(dd > 0, -ad / dd, t_lo)
        t = np.clip(t, t_lo, t_hi)
        cost = np.sum((a + t[:, None] * d) ** 2, axis=1)
        better = cost < best
        where = np.where(better, u[j] + t * du, where)
        best = np.minimum(best, cost)
    if not argmin:
        return best
    vals = np.exp(where) if curve.log else where
    return best, np.clip(vals, curve.range[0], curve.range[1])


def _fit(curve: _Curve, P: np.ndarray, w: np.ndarray) -> tuple[int, float, np.ndarray]:
    Pf = curve.patterns(P)
    cost = np.sum((Pf * w) ** 2, axis=1)
    k = int(np.argmin(cost))
    return k, float(cost[k]), Pf[k]


def zone_folds(zones: Sequence[int], k: int = 3) -> list[np.ndarray]:
    """Test masks of a k-fold split over sections stratified by zone: the sections of every
    zone are dealt round-robin to the folds, so that every zone with ≥ 2 sections lies on both
    sides of each split (k = min(k, largest zone count); folds without sections dropped)."""
    zones = list(zones)
    by_zone: dict[int, list[int]] = defaultdict(list)
    for i, z in enumerate(zones):
        by_zone[z].append(i)
    k = max(2, min(k, max(len(v) for v in by_zone.values()))) if zones else 2
    masks = [np.zeros(len(zones)) for _ in range(k)]
    offset = 0
    for z in sorted(by_zone):
        for j, i in enumerate(by_zone[z]):
            masks[(j + offset) % k][i] = 1.0
        offset += len(by_zone[z])
    return [m for m in masks if m.sum() > 0 and m.sum() < len(zones)]


def zone_bootstrap(zones: Sequence[int], n_boot: int, seed: int = 0) -> np.ndarray:
    """Section weights (n_boot, S) of a bootstrap stratified by zone: within each zone its
    sections are drawn with replacement (Efron & Tibshirani 1993 §8.2, stratified resampling),
    so every resample keeps every zone."""
    rng = np.random.default_rng(seed)
    zones = np.asarray(list(zones))
    W = np.zeros((n_boot, zones.size))
    for z in np.unique(zones):
        idx = np.flatnonzero(zones == z)
        draws = rng.integers(0, idx.size, size=(n_boot, idx.size))
        for b in range(n_boot):
            np.add.at(W[b], idx[draws[b]], 1.0)
    return W


@dataclass
class TrustedCandidate(Candidate):
    """A :class:`Candidate` with the evidence that lets a user trust it (issue 16 contract)."""

    kind: str = "effect"
    name: str = ""
    held_out_explained: float = 0.0
    explained_ci: tuple[float, float] = (0.0, 0.0)
    significant: bool = False
    plausible: bool = True
    at_bound: bool = False
    flags: list[str] = field(default_factory=list)
    summary: str = ""
    reference: float | None = None
    fitted: float = float("nan")
    parameter: str = ""
    #: 5–95 % bootstrap interval of the fitted value (refit on every resample of the sections)
    fitted_ci: tuple[float, float] = (float("nan"), float("nan"))
    #: the whole interval lies outside the plausible range (or the value sits at a search bound)
    clearly_implausible: bool = False

    def remaining(self, residual: Pattern) -> np.ndarray:
        """The residual left after this candidate at its fitted value, r − s."""
        return residual.values - self.signature.values

    def to_dict(self, with_signature: bool = False) -> dict[str, Any]:
        d = super().to_dict(with_signature)
        d.update({"kind": self.kind, "name": self.name,
                  "effect": self.name,
                  "held_out_explained": self.held_out_explained,
                  "explained_ci": list(self.explained_ci), "significant": self.significant,
                  "plausible": self.plausible, "at_bound": self.at_bound, "flags": list(self.flags),
                  "summary": self.summary, "parameter": self.parameter, "fitted": self.fitted,
                  "fitted_ci": list(self.fitted_ci), "clearly_implausible": self.clearly_implausible,
                  "reference": self.reference})
        return d


def plausibility_flags(name: str, value: float, *, bounds: tuple[float, float] | None,
                       plausible: tuple[float, float] | None, source: str = "", unit: str = "",
                       at_bound: bool | None = None, interval: tuple[float, float] | None = None,
                       kind: str = "effect") -> tuple[bool, list[str]]:
    """(plausible, flags) of a fitted value: outside the physically plausible range, or at a
    bound of the search box, is flagged ("the model may be compensating for something else").
    ``interval``: the value's bootstrap interval, said in the flag (whether it reaches into the
    plausible range); ``kind="parameter"``: a vehicle part outside the range of serviceable
    parts may also be worn or failed — the flag says to check the vehicle."""
    flags: list[str] = []
    ok = True
    if plausible is not None and not (plausible[0] <= value <= plausible[1]):
        ok = False
        spread = ""
        if interval is not None and np.all(np.isfinite(interval)):
            lo, hi = min(interval[0], value), max(interval[1], value)
            reaches = not (hi < plausible[0] or lo > plausible[1])
            spread = (f" (bootstrap interval {lo:.4g}–{hi:.4g} {unit}, "
                      + ("reaching into the range)" if reaches else "entirely outside it)"))
        part = (" — check the vehicle (a worn or failed part) or" if kind == "parameter" else ":")
        flags.append(f"{name} = {value:.4g} {unit} is outside the physically plausible range "
                     f"[{plausible[0]:.4g}, {plausible[1]:.4g}] {unit}"
                     + (f" ({source})" if source else "") + spread
                     + f"{part} the model may be compensating for something else")
    if at_bound is None and bounds is not None:
        span = bounds[1] - bounds[0]
        at_bound = bool(span > 0 and min(abs(value - bounds[0]), abs(bounds[1] - value)) <= 1e-3 * span)
    if at_bound:
        ok = False
        flags.append(f"{name} = {value:.4g} {unit} lies at a bound of the search range "
                     f"[{bounds[0]:.4g}, {bounds[1]:.4g}] {unit}: the model may be compensating for "
                     "something else" if bounds else f"{name} lies at a bound of its search range")
    return ok, flags


_MEASUREMENT = {"Y": "guiding forces Y (instrumented wheelsets)", "Q": "wheel forces Q (instrumented wheelsets)",
                "YQ": "derailment ratio Y/Q (instrumented wheelsets)", "SumY": "track shifting force ΣY",
                "ay": "car body lateral accelerations", "az": "car body vertical accelerations"}


def separating_evidence(a: TrustedCandidate, b: TrustedCandidate, residual: Pattern, n: int = 3) -> tuple[list[dict], str]:
    """The components where the signatures of two candidates differ most (weighted), as
    structured records, and a plain-language advice on what tells them apart."""
    w = residual.weights()
    diff = (a.signature.values - b.signature.values) * w
    out = []
    for k in np.argsort(-np.abs(diff))[:n]:
        parts = component_parts(residual.labels[k], residual.groups[k])
        out.append({"component": residual.labels[k], **parts, a.name: float(a.signature.values[k]),
                    b.name: float(b.signature.values[k]), "residual": float(residual.values[k])})
    if not out:
        return out, ""
    top = out[0]
    if top["band"]:
        kind = top["quantity"].split()[-1]
        where = f"the {top['band']} band of {top['channel']}"
        meas = f"a longer record or more sections with {_MEASUREMENT.get(kind, kind)} ({top['band']})"
    else:
        kind = top["quantity"].split("_")[0]
        where = f"{top['quantity']} in zone {top['zone']} at {top['position']}"
        meas = f"more sections in zone {top['zone']} with {_MEASUREMENT.get(kind, top['quantity'])}"
    advice = (f"{a.name} and {b.name} differ most in {where} ({a.name} {top[a.name]:+.2f}, "
              f"{b.name} {top[b.name]:+.2f}, residual {top['residual']:+.2f}); {meas} would tell them apart")
    return out, advice


def _family_summary(fam: CandidateFamily, value: float) -> str:
    if fam.kind == "parameter" and fam.reference:
        return (f"{fam.title or fam.parameter} ≈ {100 * value / fam.reference:.0f} % of the model's value "
                f"({value:.4g} {fam.unit} instead of {fam.reference:.4g})")
    unit = "" if fam.unit in ("", "-") else f" {fam.unit}"
    return f"{fam.title or fam.name}: {fam.parameter} ≈ {value:.4g}{unit}"


def diagnose_evidence(base: SectionEvidence, families: Sequence[CandidateFamily], *, validated: bool = False,
                      n_boot: int = 100, folds: int = 3, seed: int = 0, change: float = 0.2,
                      strong: float = STRONG, alike_margin: float = ALIKE_MARGIN,
                      alike_correlation: float = ALIKE_CORRELATION) -> DiagnosisResult:
    """Rank candidate causes (effects and model parameters) of the residual of ``base`` with
    the evidence needed to trust the answer.

    * explained share on all sections (as :func:`diagnose_patterns`) and its stratified
      bootstrap interval (refit on every resample of the sections, :func:`zone_bootstrap`);
    * held-out share: k-fold over sections stratified by zone (:func:`zone_folds`); the
      fitted value of the training sections scored on the test sections,
      1 − Σ_f ‖P_f(v*_f)‖² / Σ_f ‖r_f‖²; candidates are ranked by it;
    * noise floor: the share of pure section scatter n_b = r(w_b) − r (bootstrap deviation of
      the residual) that the best candidate can explain, 95th percentile over the resamples —
      what the candidates "explain" when there is nothing but scatter; a candidate is
      significant when the lower end (5 %) of its bootstrap interval exceeds it;
    * plausibility flags (:func:`plausibility_flags`), identifiability of the two best
      (:func:`separating_evidence`);
    * ``verdict``: ``none`` (residual within the section scatter, nothing significant, or the
      configuration passes and nothing explains ≥ ``strong`` on held-out sections),
      ``uncertain`` (the best explains < ``strong`` held-out, explains alike with another,
      is clearly implausible — its whole bootstrap interval of fitted values outside the
      plausible range — or at a bound, or loses > 0.25 from in-sample to held-out) or
      ``cause`` (a fitted value just outside the plausible range, with an interval reaching
      into it, is flagged but does not make the answer uncertain).

    References: Efron & Tibshirani 1993 ch. 6/§8.2 (bootstrap, stratified), Hastie, Tibshirani
    & Friedman 2009 §7.10 (k-fold cross-validation); docs/diagnosis.md.
    """
    S = len(base.sections)
    r_full = base.values()
    residual = base.pattern()
    w = residual.weights()
    r2 = float(np.sum((w * r_full) ** 2))
    if not r2 > 0:
        raise InvalidSignal("the residual pattern is zero: nothing to diagnose")
    Wb = zone_bootstrap(base.zones, n_boot, seed) if n_boot > 0 else np.zeros((0, S))
    test_masks = zone_folds(base.zones, folds)
    R_boot = base.values(Wb) if n_boot > 0 else np.zeros((0, r_full.size))
    noise = R_boot - r_full[None, :]
    noise2 = np.sum((noise * w) ** 2, axis=1)
    before = residual.group_norms()
    cands: list[TrustedCandidate] = []
    noise_share = np.zeros((len(families), n_boot))
    for fi, fam in enumerate(families):
        curve = _Curve(fam)
        P_full = np.stack([e.values() for e in fam.evidence])
        k, cost, Pk = _fit(curve, P_full, w)
        v = curve.value(k)
        explained = float(np.clip(1 - cost / r2, 0.0, 1.0))
        # held-out
        num = den = 0.0
        for m in test_masks:
            P_tr = np.stack([e.values(1.0 - m) for e in fam.evidence])
            kt, _, _ = _fit(curve, P_tr, w)
            P_te = curve.patterns(np.stack([e.values(m) for e in fam.evidence]))[kt]
            r_te = base.values(m)
            num += float(np.sum((w * P_te) ** 2))
            den += float(np.sum((w * r_te) ** 2))
        held = float(np.clip(1 - num / den, 0.0, 1.0)) if den > 0 else 0.0
        # bootstrap: refit on resampled sections; and the share of pure scatter it explains
        boot: list[float] = []
        v_ci = (v, v)
        if n_boot:
            P_boot = np.stack([e.values(Wb) for e in fam.evidence], axis=1)  # (B, K, n), family order
            rb2 = np.sum((w * R_boot) ** 2, axis=1)
            cb, vb = _min_cost(curve, P_boot, w, argmin=True)
            boot = [1 - c / d if d > 0 else 0.0 for c, d in zip(cb, rb2, strict=True)]
            v_ci = (float(np.percentile(vb, 5)), float(np.percentile(vb, 95)))
            # the candidate's change P(v) − r added to pure scatter n_b: nodes P_k − r + n_b
            cn = _min_cost(curve, P_full[None, :, :] - r_full[None, None, :] + noise[:, None, :], w)
            with np.errstate(divide="ignore", invalid="ignore"):
                share = np.where(noise2 > 0, 1 - cn / noise2, 0.0)
            noise_share[fi] = np.maximum(share, 0.0)
        ci = (float(np.clip(np.percentile(boot, 5), 0, 1)), float(np.clip(np.percentile(boot, 95), 0, 1))) \
            if boot else (explained, explained)
        after = residual.group_norms(Pk)
        fixes = [g for g in before if after[g] < (1 - change) * before[g]]
        worsens = [g for g in before if after[g] > (1 + change) * before[g] + 1e-12]
        bounds = fam.bounds if fam.extrapolate else (float(curve.v[0]), float(curve.v[-1]))
        at_edge = k in (0, curve.fine.size - 1)
        ok, flags = plausibility_flags(f"{fam.name}.{fam.parameter}" if fam.kind == "effect" else fam.name, v,
                                       bounds=bounds, plausible=fam.plausible, source=fam.plausible_source,
                                       unit=fam.unit, at_bound=at_edge, interval=v_ci, kind=fam.kind)
        lo_ci, hi_ci = min(v_ci[0], v), max(v_ci[1], v)
        clearly = at_edge or (fam.plausible is not None and (hi_ci < fam.plausible[0] or lo_ci > fam.plausible[1]))
        params = {**fam.defaults, fam.parameter: v} if fam.kind == "effect" else {fam.parameter: v}
        summary = _family_summary(fam, v)
        expl = summary + (": " + fam.explanation if fam.explanation and fam.kind == "effect" else
                          ("; a model parameter error, not a missing effect" if fam.kind == "parameter" else ""))
        cands.append(TrustedCandidate(
            fam.name, explained, params, sorted(fixes, key=lambda g: after[g] - before[g]),
            sorted(worsens, key=lambda g: before[g] - after[g]), expl,
            Pattern(residual.labels, residual.groups, r_full - Pk, residual.components), math.sqrt(cost),
            {g: (before[g], after[g]) for g in before}, kind=fam.kind, name=fam.name,
            held_out_explained=held, explained_ci=ci, plausible=ok, at_bound=at_edge, flags=flags,
            summary=summary, reference=fam.reference, fitted=v, parameter=fam.parameter,
            fitted_ci=(lo_ci, hi_ci), clearly_implausible=bool(clearly)))
    noise_floor = float(np.percentile(noise_share.max(axis=0), 95)) if n_boot and families else 0.0
    within_noise = bool(n_boot and r2 <= float(np.percentile(noise2, 95)))
    for c in cands:
        c.significant = c.explained_ci[0] > noise_floor and c.held_out_explained > noise_floor
        if not c.significant:
            c.flags.append(f"explains no more than the section-to-section scatter alone can produce "
                           f"(noise floor {noise_floor:.2f}; explained {c.explained_ci[0]:.2f}–"
                           f"{c.explained_ci[1]:.2f}, held-out {c.held_out_explained:.2f})")
        if c.explained - c.held_out_explained > 0.25:
            c.flags.append(f"explains {c.explained:.2f} of the residual on the sections it was fitted to but "
                           f"only {c.held_out_explained:.2f} on held-out sections")
    cands.sort(key=lambda c: (-c.held_out_explained, -c.explained))
    separable, evidence, note, alike = True, [], "", []
    if len(cands) >= 2:
        a = cands[0]
        for b in cands[1:3]:
            sa, sb = a.signature.values * w, b.signature.values * w
            den = float(np.linalg.norm(sa) * np.linalg.norm(sb))
            corr = float(sa @ sb / den) if den > 0 else 0.0
            ev, advice = separating_evidence(a, b, residual)
            if b is cands[1]:
                evidence = ev
            if a.held_out_explained - b.held_out_explained < alike_margin and corr > alike_correlation:
                alike.append({"candidates": [a.name, b.name], "correlation": corr, "evidence": ev, "advice": advice})
                a.flags.append(f"explains alike with {b.name} (signature correlation {corr:.2f}): {advice}")
                b.flags.append(f"explains alike with {a.name} (signature correlation {corr:.2f}): {advice}")
        separable = not alike
    unexplained = _unexplained(residual, cands[0] if cands else None)
    best = cands[0] if cands else None
    if best is None:
        verdict, why = "none", "no candidate applies"
    elif within_noise:
        verdict, why = "none", "the residual is within the section-to-section scatter"
    elif not best.significant:
        verdict, why = "none", f"no candidate explains more than the noise floor ({noise_floor:.2f})"
    elif validated and best.held_out_explained < strong:
        verdict, why = "none", (f"the configuration passes and no candidate explains ≥ {strong:.1f} of the "
                                f"rest on held-out sections (best {best.name} {best.held_out_explained:.2f})")
    elif best.held_out_explained < strong or best.explained < strong:
        verdict, why = "uncertain", (f"the best candidate {best.name} explains only {best.held_out_explained:.2f} "
                                     f"on held-out sections ({best.explained:.2f} in-sample)")
    elif alike:
        verdict, why = "uncertain", "; ".join(x["advice"] for x in alike)
    elif not best.plausible and best.clearly_implausible:
        verdict, why = "uncertain", "; ".join(best.flags[:1])
    elif best.explained - best.held_out_explained > 0.25:
        verdict, why = "uncertain", f"{best.name} does not hold on held-out sections"
    else:
        verdict, why = "cause", (f"{best.summary} explains {best.held_out_explained:.2f} of the residual on "
                                 f"held-out sections ({best.explained:.2f} in-sample; noise floor {noise_floor:.2f})")
    if verdict == "none":
        note = "no candidate explains the residual: " + why
    elif verdict == "uncertain":
        note = "uncertain: " + why
    else:
        note = why
    res = DiagnosisResult(residual, list(cands), separable, evidence, note)
    res.extra.update({"verdict": verdict, "noise_floor": noise_floor, "residual_within_noise": within_noise,
                      "alike": alike, "unexplained": unexplained, "folds": len(test_masks),
                      "bootstrap": n_boot})
    return res


def _unexplained(residual: Pattern, best: Candidate | None, n: int = 6) -> list[dict[str, Any]]:
    """The largest components left after the best candidate (or of the residual): quantity,
    zone, position or PSD band with value before/after."""
    w = residual.weights()
    after = best.remaining(residual) if isinstance(best, TrustedCandidate) else residual.values
    out = []
    for k in np.argsort(-np.abs(after * w))[:n]:
        if after[k] == 0:
            break
        out.append({"component": residual.labels[k], **component_parts(residual.labels[k], residual.groups[k]),
                    "residual": float(residual.values[k]), "after_best": float(after[k])})
    return out


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


def pattern_grids(components: Sequence[Component], values) -> tuple[PatternGrid, PatternGrid]:
    """Arrange a diagnosis pattern (its :class:`Component` s and values: mean normalised D_v
    of a quantity in a zone at a position, and log₂ PSD ratio simulation/measurement of an
    acceleration channel in a band) into (quantity × zone, car body acceleration direction ×
    band) grids, averaging over positions and channels; supplementary components are on
    neither grid."""
    q_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    p_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    bands: dict[str, float] = {}
    for c, v in zip(components, np.asarray(values, float), strict=True):
        if not math.isfinite(v):
            continue
        if c.kind == "psd":
            bands[c.band_label] = c.band[0]
            p_acc[(c.direction, c.band_label)].append(v)
        elif c.kind == "pair":
            q_acc[(c.quantity, f"zone {c.zone}")].append(v)
    cols = sorted(bands, key=bands.__getitem__)
    kinds = [k for k in ("ay", "az") if any((k, b) in p_acc for b in cols)]
    return _quantity_zone_grid(q_acc), _grid(kinds, cols, p_acc)


def scan_values(lower: float, upper: float, default: float, n: int, log: bool = False) -> list[float]:
    """The values of one effect parameter a diagnosis simulates (docs/design.md §7): ``n``
    values spanning [lower, upper] (equally spaced, or geometrically with ``log``) plus the
    default, sorted, unique."""
    grid = np.geomspace(lower, upper, n) if log else np.linspace(lower, upper, n)
    return sorted(set(grid.tolist()) | {float(default)})
