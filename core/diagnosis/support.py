"""Cross-family support: when a candidate's evidence lies in the guiding forces alone, it may be
absorbing a difference no candidate models (docs/diagnosis.md "Interface candidates").

A candidate that acts on the wheel–rail interface (``CandidateFamily.interface``: track
flexibility, wheel–rail friction, conicity, the bogie's yaw resistance, the wheelset guidance
stiffnesses) changes above all the guiding forces and Y/Q (Y, Y/Q, ΣY). A wheel–rail contact
that differs in kind from the model's — a softer flange contact, another creep law, other creep
coefficients, another profile shape — changes the same quantities, and no candidate models it.
On the trust bench such a contact difference was claimed as ``cause: track_flexibility`` and a
profile shape as ``cause: wheel_rail_friction``.

The criterion is held-out support outside that family: the candidate is scored again on the
components of every other family (wheel forces, car body accelerations, bogie and PSD results)
with the same held-out folds, bootstrap and noise floor as the whole diagnosis
(:func:`railval.core.diagnosis.engine.diagnose_evidence`). An interface candidate that is not
significant there is *supported only by the guiding family*: it explains alike with a contact
difference no candidate models. Then

* the verdict is at most ``uncertain`` (overall and in the guiding family), with the note
  "explains alike with a contact difference no candidate models";
* it does not enter the cause set, neither first nor later;
* the guiding family is flagged structural when its best candidate is such a one: the residual
  stays in the guiding family and nothing outside supports the parameter that would remove it.

A mass or inertia candidate enters the cause set only when it is identifiable — not flagged
"explains alike" with another candidate — and its fitted value is plausible and inside the
search range: a mass does not wear, so a mass outside the range real vehicles have is not a
worn part (as a damper at 30 % may be), and two masses that explain alike (a car body and a
bogie mass absorbing a wheelset mass, which no candidate models) cannot be told apart.

References: Hastie, Tibshirani & Friedman 2009 §7.10 (held-out scoring); Efron & Tibshirani
1993 §8.2 (stratified bootstrap, noise floor); Polach & Böttcher 2014 §5 (a model error that no
parameter value removes); docs/diagnosis.md.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence
from railval.core.diagnosis.families import family_of, restrict, structural_where
from railval.core.diagnosis.fit import CandidateFamily

#: the quantity family interface candidates act on (core/diagnosis/families.py)
GUIDING = "guiding"

#: the answer for a candidate supported only by the guiding family
CONTACT_ALIKE = "explains alike with a contact difference no candidate models"


@dataclass(frozen=True)
class Support:
    """Held-out support of one candidate outside the guiding family."""

    name: str
    held_out_outside: float
    significant_outside: bool
    noise_floor_outside: float

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "held_out_outside": self.held_out_outside,
                "significant_outside": self.significant_outside, "noise_floor_outside": self.noise_floor_outside}


def outside_support(base: SectionEvidence, families: Sequence[CandidateFamily], *, n_boot: int = 100,
                    folds: int = 3, seed: int = 0) -> dict[str, Support]:
    """The support of every interface candidate of ``families`` outside the guiding family
    (module docstring): ``{name: Support}``; empty when no candidate is an interface one."""
    from railval.core.diagnosis.engine import diagnose_evidence

    names = [f.name for f in families if f.interface and not f.floor_only]
    if not names:
        return {}
    keep = np.array([family_of(g) != GUIDING for g in base.groups], bool)
    none = {n: Support(n, 0.0, False, 0.0) for n in names}
    if not keep.any() or keep.all():
        return none if not keep.any() else {}
    sub = restrict(base, keep)
    sub_r = sub.values()
    if not float(np.sum((sub.pattern().weights() * sub_r) ** 2)) > 0:
        return none
    subfams = [replace(f, evidence=[restrict(e, keep) for e in f.evidence]) for f in families]
    res = diagnose_evidence(sub, subfams, n_boot=n_boot, folds=folds, seed=seed)
    floor = float(res.noise_floor)
    by = {c.name: c for c in res.candidates}
    return {n: Support(n, by[n].held_out_explained, bool(by[n].significant), floor) if n in by else none[n]
            for n in names}


def guiding_only(support: Mapping[str, Support]) -> set[str]:
    """Names of the interface candidates supported only by the guiding family."""
    return {n for n, s in support.items() if not s.significant_outside}


def _alike_flag(s: Support) -> str:
    return (f"{CONTACT_ALIKE}: its evidence lies in the guiding forces and Y/Q only (held-out "
            f"{s.held_out_outside:.2f} on the other quantities, noise floor {s.noise_floor_outside:.2f}) — a softer "
            "flange contact, another creep law or profile shape changes the same quantities")


def apply_interface_rule(res: Any, families_out: list[dict[str, Any]], support: Mapping[str, Support],
                         base: SectionEvidence, *, strong: float) -> None:
    """Flag the candidates supported only by the guiding family, make a ``cause`` verdict on one
    of them ``uncertain`` (overall and in the guiding family) and name the guiding family's
    structural difference (module docstring). Changes ``res`` and ``families_out`` in place."""
    only = guiding_only(support)
    for c in res.candidates:
        if c.name in only:
            c.flags.append(_alike_flag(support[c.name]))
    best = res.candidates[0] if res.candidates else None
    if best is not None and best.name in only and res.verdict == "cause":
        res.verdict = "uncertain"
        res.note = f"uncertain: {best.name} {_alike_flag(support[best.name])}"
    for fam in families_out:
        if fam["name"] != GUIDING or not fam["top"]:
            continue
        top = fam["top"][0]
        if top["name"] not in only or not top["significant"] or top["held_out_explained"] < strong:
            continue
        if fam["verdict"] == "cause":
            fam["verdict"] = "uncertain"
        if not fam["structural"]["flag"]:
            quantities, zones = structural_where(base, GUIDING)
            reason = (f"the {fam['title']} residual ({', '.join(quantities)}; zones "
                      f"{', '.join(map(str, zones)) or '-'}) is explained best by {top['name']}, which "
                      f"{CONTACT_ALIKE} (no support outside this family): the wheel–rail contact (flange "
                      "contact, creep law, profile shape) may differ from the model's in kind")
            fam["structural"] = {"flag": True, "quantities": quantities, "zones": zones, "reason": reason}
            fam["note"] = reason


def cause_pool(pool: Iterable[CandidateFamily], res: Any, support: Mapping[str, Support],
               masses: Iterable[str]) -> tuple[list[CandidateFamily], list[dict[str, str]]]:
    """The candidates that may enter the cause set and those left out with a reason: interface
    candidates supported only by the guiding family; mass or inertia parameters (``masses``:
    template parameter names) that explain alike with another candidate, or whose fitted value
    is implausible or at a bound (module docstring)."""
    only = guiding_only(support)
    masses = set(masses)
    by = {c.name: c for c in res.candidates}
    alike = {n for pair in res.alike for n in pair["candidates"]}
    keep, out = [], []
    for f in pool:
        c = by.get(f.name)
        if f.name in only:
            out.append({"name": f.name, "reason": CONTACT_ALIKE + " (supported only by the guiding forces and Y/Q)"})
        elif f.kind == "parameter" and f.parameter in masses and c is not None and (
                f.name in alike or not c.plausible or c.at_bound):
            why = ("explains alike with another candidate" if f.name in alike else
                   "fitted at a bound of its search range" if c.at_bound else "fitted outside its plausible range")
            out.append({"name": f.name, "reason": f"a mass or inertia that {why} is not identified "
                                                  "(a mass does not wear)"})
        else:
            keep.append(f)
    return keep, out
