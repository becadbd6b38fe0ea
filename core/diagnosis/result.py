"""What a diagnosis returns: one ranked candidate cause with the evidence to trust it, and the
ranked result with its verdict, both as plain dicts for ``--json``, the stored analysis run and
the Diagnose page (docs/diagnosis.md, contract of the fields there).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.core.diagnosis.patterns import Pattern


def _num(v: Any) -> float:
    return float("nan") if v is None else float(v)  # NaN is stored as null


@dataclass
class TrustedCandidate:
    """One ranked explanation: the effect or parameter, the share of the residual its fitted
    signature explains (in-sample, its bootstrap interval, on held-out sections), the fitted
    parameters, quantities it fixes/worsens (residual RMS before → after per group), its
    physical explanation, its fitted signature and its plausibility. ``name``: the effect id,
    ``model.PARAM`` or the measurement candidate — what ``calibrate --effect`` accepts (the
    JSON carries it as ``name`` and, for older readers, as ``effect``: docs/diagnosis.md)."""

    name: str
    explained: float
    parameters: dict[str, float]
    fixes: list[str]
    worsens: list[str]
    explanation: str
    signature: Pattern
    residual_after: float
    group_change: dict[str, tuple[float, float]] = field(default_factory=dict)
    kind: str = "effect"
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
    #: interval of the fitted value: the 5–95 % bootstrap interval (refit on every resample of
    #: the sections) widened to the values fitted on the training sections of every held-out
    #: fold (a spread that also reflects structural model error, not only section scatter)
    fitted_ci: tuple[float, float] = (float("nan"), float("nan"))
    #: the bootstrap part alone (what decides ``clearly_implausible``)
    fitted_ci_bootstrap: tuple[float, float] = (float("nan"), float("nan"))
    #: the value fitted on the training sections of each held-out fold
    fold_values: list[float] = field(default_factory=list)
    #: the whole interval lies outside the plausible range (or the value sits at a search bound)
    clearly_implausible: bool = False

    def remaining(self, residual: Pattern) -> np.ndarray:
        """The residual left after this candidate at its fitted value, r − s."""
        return residual.values - self.signature.values

    def to_dict(self, with_signatures: bool = False) -> dict[str, Any]:
        """The JSON document (docs/diagnosis.md); ``with_signatures``: with the fitted
        signature (the spelling of :meth:`DiagnosisResult.to_dict`)."""
        d = {"effect": self.name, "explained": self.explained, "parameters": dict(self.parameters),
             "fixes": list(self.fixes), "worsens": list(self.worsens), "explanation": self.explanation,
             "residual_after": self.residual_after,
             "quantities": {g: {"before": a, "after": b} for g, (a, b) in self.group_change.items()}}
        if with_signatures:
            d["signature"] = self.signature.to_dict()
        d.update({"kind": self.kind, "name": self.name,
             "held_out_explained": self.held_out_explained,
             "explained_ci": list(self.explained_ci), "significant": self.significant,
             "plausible": self.plausible, "at_bound": self.at_bound, "flags": list(self.flags),
             "summary": self.summary, "parameter": self.parameter, "fitted": self.fitted,
             "fitted_ci": list(self.fitted_ci), "fitted_ci_bootstrap": list(self.fitted_ci_bootstrap),
             "fold_values": list(self.fold_values), "clearly_implausible": self.clearly_implausible,
             "reference": self.reference})
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrustedCandidate:
        """Inverse of :meth:`to_dict` with ``with_signatures=True`` (a stored run read back)."""
        ci = d.get("explained_ci") or (0.0, 0.0)
        return cls(
            name=d.get("name") or d["effect"], explained=_num(d["explained"]),
            parameters={k: _num(v) for k, v in d["parameters"].items()},
            fixes=list(d["fixes"]), worsens=list(d["worsens"]), explanation=d["explanation"],
            signature=Pattern.from_dict(d["signature"]), residual_after=_num(d["residual_after"]),
            group_change={g: (_num(v["before"]), _num(v["after"])) for g, v in d.get("quantities", {}).items()},
            kind=d.get("kind", "effect"),
            held_out_explained=_num(d.get("held_out_explained", 0.0)), explained_ci=(_num(ci[0]), _num(ci[1])),
            significant=bool(d.get("significant")), plausible=bool(d.get("plausible", True)),
            at_bound=bool(d.get("at_bound")), flags=list(d.get("flags") or []), summary=d.get("summary", ""),
            reference=d.get("reference"), fitted=_num(d.get("fitted")), parameter=d.get("parameter", ""),
            fitted_ci=tuple(_num(x) for x in (d.get("fitted_ci") or (None, None))),  # older runs: unknown
            fitted_ci_bootstrap=tuple(_num(x) for x in (d.get("fitted_ci_bootstrap") or d.get("fitted_ci")
                                                         or (None, None))),
            fold_values=[_num(x) for x in d.get("fold_values") or []],
            clearly_implausible=bool(d.get("clearly_implausible", not d.get("plausible", True))))


#: the typed fields of a diagnosis and their JSON names (``--json``, stored runs, the page):
#: (attribute, JSON key); the JSON names are the contract of docs/diagnosis.md
_TYPED: tuple[tuple[str, str], ...] = (
    ("verdict", "verdict"), ("noise_floor", "noise_floor"), ("residual_within_noise", "residual_within_noise"),
    ("alike", "alike"), ("unexplained", "unexplained"), ("folds", "folds"), ("bootstrap", "bootstrap"),
    ("families", "families"), ("interface_support", "interface_support"), ("causes", "causes"),
    ("cause_set", "cause_set"), ("campaign", "campaign"), ("configuration", "configuration"),
    ("validated", "validated"), ("effects_in_configuration", "effects_in_configuration"),
    ("parameters_in_configuration", "parameters_in_configuration"),
    ("values_per_parameter", "values_per_parameter"), ("simulations", "simulations"),
    ("stored_residual_norm", "stored_residual_norm"), ("simulated_residual_norm", "simulated_residual_norm"),
    ("effects_simulated", "effects_simulated"), ("skipped", "skipped"), ("next_step", "next"), ("run", "run"),
    ("statements", "statements"), ("lineage", "lineage"), ("screen", "screen"),
)


@dataclass
class DiagnosisResult:
    """Ranked candidates, the separability verdict between the two best, and the verdict with
    its evidence (:func:`railval.core.diagnosis.diagnose_evidence`); the fields from ``families``
    on are filled by the diagnosis service (``None``: not part of this result, left out of the
    dict). ``extra``: keys of a stored run this version does not know."""

    residual: Pattern
    candidates: list[TrustedCandidate]
    separable: bool
    evidence: list[dict[str, Any]]
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    verdict: str = "none"
    noise_floor: float = 0.0
    residual_within_noise: bool = False
    alike: list[dict[str, Any]] = field(default_factory=list)
    unexplained: list[dict[str, Any]] = field(default_factory=list)
    folds: int = 0
    bootstrap: int = 0
    families: list[dict[str, Any]] | None = None
    interface_support: list[dict[str, Any]] | None = None
    causes: list[dict[str, Any]] | None = None
    cause_set: dict[str, Any] | None = None
    campaign: str | None = None
    configuration: str | None = None
    validated: bool | None = None
    effects_in_configuration: list[str] | None = None
    parameters_in_configuration: dict[str, float] | None = None
    values_per_parameter: int | None = None
    simulations: int | None = None
    stored_residual_norm: float | None = None
    simulated_residual_norm: float | None = None
    effects_simulated: list[str] | None = None
    skipped: list[dict[str, Any]] | None = None
    next_step: dict[str, Any] | None = None
    run: dict[str, Any] | None = None
    #: input-side statements (``kind`` "track input" / "contact geometry", ``candidates``,
    #: ``text``): which input of the simulation differs and what data replace it
    #: (:mod:`railval.core.diagnosis.inputs`)
    statements: list[dict[str, Any]] | None = None
    #: a calibrated configuration's diagnosis read against its parent's: ``ancestors`` (every
    #: diagnosed configuration of the lineage, root first) and ``statement``
    #: (:func:`railval.core.diagnosis.lineage.lineage_statement`); filled at every read, not stored
    lineage: dict[str, Any] | None = None
    #: a screened diagnosis (``rank_causes(screen=K)``, docs/diagnosis.md "Screened diagnosis"):
    #: ``applied``, ``kept``, the screen ``sections``, ``screened_out`` (name, kind, shares on the
    #: screen) and the section runs made against a whole diagnosis's; ``None``: not screened
    screen: dict[str, Any] | None = None

    def to_dict(self, with_signatures: bool = False) -> dict[str, Any]:
        """Plain dict; ``with_signatures`` adds the residual's components (``labels``,
        ``values``) and every candidate's fitted signature (for plots of where it acts)."""
        residual: dict[str, Any] = {"norm": math.sqrt(self.residual.norm2()),
                                    "groups": self.residual.group_norms()}
        if with_signatures:
            residual.update(self.residual.to_dict())
        d = {"candidates": [c.to_dict(with_signatures=with_signatures) for c in self.candidates],
             "separable": self.separable, "evidence": list(self.evidence), "note": self.note,
             "residual": residual}
        d.update({key: getattr(self, attr) for attr, key in _TYPED if getattr(self, attr) is not None})
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DiagnosisResult:
        """Inverse of :meth:`to_dict` with ``with_signatures=True`` (a stored run read back);
        keys this version does not know go to ``extra``."""
        own = {"candidates", "separable", "evidence", "note", "residual"} | {key for _, key in _TYPED}
        return cls(residual=Pattern.from_dict(d["residual"]),
                   candidates=[TrustedCandidate.from_dict(c) for c in d["candidates"]],
                   separable=bool(d["separable"]), evidence=list(d["evidence"]), note=d.get("note", ""),
                   extra={k: v for k, v in d.items() if k not in own},
                   **{attr: d[key] for attr, key in _TYPED if key in d})

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{k: v for k, v in c.to_dict().items() if k != "quantities"} for c in self.candidates])
