"""The diagnosis per quantity family (docs/diagnosis.md "Per family"): the residual of each
family — guiding forces and Y/Q; wheel forces; car body accelerations; bogie and PSD
supplementary results — explained on its own, so that a structural difference in one family
(explained only at an implausible value or at a search bound) is named and does not hide an
independent cause in another.

Each family's pattern is the campaign pattern restricted to its components (the weights of
its quantities unchanged: each quantity's total weight 1); the candidates' simulated evidence
is restricted likewise and :func:`railval.core.diagnosis.engine.diagnose_evidence` ranks them
with the same held-out, noise-floor and plausibility rules. A family is *structural* when
its residual is beyond the section scatter and every candidate that explains at least
``strong`` of it on held-out sections does so only at a search bound or, for an effect or a
measurement candidate, at a clearly implausible value (a model parameter outside the range of
serviceable parts is a worn or failed part, a cause): the model's behaviour there differs in
kind, not in a parameter value. The quantities
and EN 14363 test zones where its residual lies are named (zones whose residual RMS is at
least half the largest).

References: Polach & Böttcher 2014 §5 (quantities, zones; a model error that no parameter
value removes); EN 14363:2016 Table 2 (the quantities); docs/diagnosis.md.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from railval.core.diagnosis.engine import STRONG, diagnose_evidence
from railval.core.diagnosis.evidence import SectionEvidence
from railval.core.diagnosis.fit import CandidateFamily
from railval.core.errors import InvalidParameter, InvalidSignal

#: family → (title, EN 14363 signal kinds of :class:`railval.core.quantities.Quantity` ``signal``,
#: pattern groups beyond the EN quantities)
QUANTITY_FAMILIES: dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]] = {
    "guiding": ("guiding forces and Y/Q", ("Y", "YQ", "SumY"), ()),
    "wheel": ("wheel forces", ("Q",), ()),
    "carbody": ("car body accelerations", ("ay", "az"), ()),
    "supplementary": ("bogie and PSD supplementary results", (), ("psd ay", "psd az", "bogie ay", "bogie az")),
}


def family_of(group: str) -> str | None:
    """The family of a pattern group (an EN quantity id, ``"psd ay"``, ``"bogie az"`` …)."""
    from railval.core.quantities import QUANTITIES

    q = QUANTITIES.get(group)
    for name, (_, signals, groups) in QUANTITY_FAMILIES.items():
        if (q is not None and q.signal in signals) or group in groups:
            return name
    return None


def restrict(ev: SectionEvidence, keep: Sequence[bool]) -> SectionEvidence:
    """The evidence of the components marked in ``keep`` only."""
    keep = np.asarray(keep, bool)
    kp, kb = keep[:ev.n_pair], keep[ev.n_pair:]
    idx = np.flatnonzero(keep)
    return SectionEvidence(list(ev.sections), list(ev.zones), [ev.labels[i] for i in idx],
                           [ev.groups[i] for i in idx], int(kp.sum()), ev.sums[:, kp], ev.counts[:, kp],
                           ev.sim_power[:, kb], ev.meas_power[:, kb],
                           None if ev.components is None else [ev.components[i] for i in idx])


def _where(ev: SectionEvidence) -> tuple[list[str], list[int]]:
    """Quantities (groups) and zones where a family's residual lies: groups whose RMS is at
    least half the largest, zones (pair components) likewise."""
    pat = ev.pattern()
    norms = pat.group_norms()
    top = max(norms.values(), default=0.0)
    quantities = [g for g, v in sorted(norms.items(), key=lambda x: -x[1]) if top > 0 and v >= 0.5 * top]
    acc: dict[int, list[float]] = defaultdict(list)
    for lab, x in zip(pat.labels[:ev.n_pair], pat.values[:ev.n_pair], strict=True):
        words = lab.split()
        if len(words) >= 3 and words[1] == "zone":
            acc[int(words[2])].append(float(x) ** 2)
    rms = {z: math.sqrt(float(np.mean(v))) for z, v in acc.items()}
    ztop = max(rms.values(), default=0.0)
    zones = sorted(z for z, v in rms.items() if ztop > 0 and v >= 0.5 * ztop)
    return quantities, zones


def structural_where(base: SectionEvidence, family: str) -> tuple[list[str], list[int]]:
    """Quantities and zones where the residual of ``family`` lies (as :func:`_where`)."""
    keep = [family_of(g) == family for g in base.groups]
    return _where(restrict(base, keep)) if any(keep) else ([], [])


def _top(c: Any) -> dict[str, Any]:
    return {"name": c.name, "kind": c.kind, "held_out_explained": c.held_out_explained, "explained": c.explained,
            "parameter": c.parameter, "fitted": c.fitted, "fitted_ci": list(c.fitted_ci), "plausible": c.plausible,
            "clearly_implausible": c.clearly_implausible, "at_bound": c.at_bound, "significant": c.significant,
            "summary": c.summary}


def diagnose_families(base: SectionEvidence, families: Sequence[CandidateFamily], *, validated: bool = False,
                      n_boot: int = 100, folds: int = 3, seed: int = 0, strong: float = STRONG,
                      n_top: int = 3, names: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Per quantity family present in ``base``: ``name``, ``title``, ``quantities`` (its
    groups), ``share`` (its part of the weighted residual ‖r‖²), ``verdict`` and ``note`` of
    :func:`diagnose_evidence` on its components, ``top`` (the ``n_top`` best candidates:
    name, kind, held-out and in-sample shares, fitted value and interval, plausibility) and
    ``structural`` (``flag``, ``quantities``, ``zones``, ``reason``; module docstring).
    ``names``: only these quantity families (in :data:`QUANTITY_FAMILIES` order); each family
    is judged on its own components alone, so the families can be judged apart (on separate
    workers) and put together in that order with the same result."""
    unknown = sorted(set(names or ()) - set(QUANTITY_FAMILIES))
    if unknown:
        raise InvalidParameter(f"diagnose_families: unknown quantity families {unknown}; known: {list(QUANTITY_FAMILIES)}")
    only = None if names is None else set(names)
    groups = list(base.groups)
    fam_of = [family_of(g) for g in groups]
    r = base.values()
    w = base.pattern().weights()
    total = float(np.sum((w * r) ** 2))
    out = []
    for name, (title, _, _) in QUANTITY_FAMILIES.items():
        keep = [f == name for f in fam_of]
        if not any(keep) or (only is not None and name not in only):
            continue
        sub = restrict(base, keep)
        subfams = [replace(f, evidence=[restrict(e, keep) for e in f.evidence]) for f in families]
        sub_r = sub.values()
        sub_w = sub.pattern().weights()
        share = float(np.sum((w[np.asarray(keep)] * r[np.asarray(keep)]) ** 2)) / total if total > 0 else 0.0
        item: dict[str, Any] = {"name": name, "title": title,
                                "quantities": sorted({g for g, k in zip(groups, keep, strict=True) if k}),
                                "share": share}
        quantities, zones = _where(sub)
        if not float(np.sum((sub_w * sub_r) ** 2)) > 0:
            out.append({**item, "verdict": "none", "note": "nothing to explain in this family", "top": [],
                        "structural": {"flag": False, "quantities": [], "zones": [], "reason": ""}})
            continue
        try:
            res = diagnose_evidence(sub, subfams, validated=validated, n_boot=n_boot, folds=folds, seed=seed,
                                    strong=strong)
        except InvalidSignal as exc:  # pragma: no cover - guarded above
            out.append({**item, "verdict": "none", "note": str(exc), "top": [],
                        "structural": {"flag": False, "quantities": [], "zones": [], "reason": ""}})
            continue
        strong_ones = [c for c in res.candidates if c.held_out_explained >= strong and c.significant]
        # a parameter outside the range of serviceable parts is a worn or failed part, not structure
        structural = bool(not res.residual_within_noise and strong_ones
                          and all(c.at_bound or (c.clearly_implausible and c.kind != "parameter")
                                  for c in strong_ones))
        reason = ""
        if structural:
            names = ", ".join(f"{c.name} at {c.fitted:.4g}" for c in strong_ones[:3])
            reason = (f"the {title} residual ({', '.join(quantities)}; zones {', '.join(map(str, zones)) or '-'}) is "
                      f"explained only at implausible values or search bounds ({names}): the model's behaviour "
                      "in this family differs structurally, not by a parameter value")
        verdict = "uncertain" if structural and res.verdict == "cause" else res.verdict
        out.append({**item, "verdict": verdict, "note": reason or res.note,
                    "noise_floor": res.noise_floor,
                    "top": [_top(c) for c in res.candidates[:n_top]],
                    "structural": {"flag": structural, "quantities": quantities if structural else [],
                                   "zones": zones if structural else [], "reason": reason}})
    return out
