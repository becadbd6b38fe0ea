"""Several causes at once (docs/diagnosis.md "Cause set"): when the best candidate leaves a
residual beyond the section scatter, what remains is diagnosed too — greedy forward
selection with a joint refit of the chosen set — and every cause is reported with the share
of the residual it adds on held-out sections.

Superposition: the pattern of the configuration with candidates i ∈ C at values v_i is taken
as r + Σ_i (P_i(v_i) − r) (each candidate's change to the residual adds; first order in the
changes, exact when they act on different components), so a set is scored without new
simulations. The set's values are fitted jointly by coordinate descent (each value refitted
with the others fixed, until none moves; each step does not increase the cost, so it
converges). Held-out: k-fold over sections stratified by zone; the set is fitted on the
training sections and scored on the test sections, 1 − Σ_f ‖P_C,f‖² / Σ_f ‖r_f‖².

Greedy: start from the empty set; add the candidate whose joint refit raises the held-out
share most; keep it only when the gain is at least ``min_gain``, its jointly fitted value is
inside its search range (not at a bound) and, for an effect or a measurement candidate,
inside its plausible range (a model parameter beyond it is a worn part), and the residual left
before adding it is beyond the section scatter (95th percentile of the bootstrap deviation).
At most ``max_causes``.

References: Hastie, Tibshirani & Friedman 2009 §3.3.2 (forward stepwise selection) and §7.10
(k-fold cross-validation); Bertsekas 1999 §2.7 (block coordinate descent).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence, zone_bootstrap, zone_folds
from railval.core.diagnosis.fit import CandidateFamily, _Curve

#: least gain in held-out share for a further cause, and at most this many causes
MIN_GAIN = 0.05
MAX_CAUSES = 3


def _joint_fit(curves: Sequence[_Curve], nodes: Sequence[np.ndarray], r: np.ndarray, w: np.ndarray,
               iters: int = 20) -> tuple[list[int], np.ndarray]:
    """Fine-grid indices of the jointly fitted values and the combined pattern (superposition)."""
    fine = [c.patterns(P) for c, P in zip(curves, nodes, strict=True)]  # (F, n) each
    ks = [int(np.argmin(np.sum((F * w) ** 2, axis=1))) for F in fine]
    for _ in range(iters):
        moved = False
        for i, F in enumerate(fine):
            others = sum((fine[j][ks[j]] - r for j in range(len(fine)) if j != i), np.zeros_like(r))
            k = int(np.argmin(np.sum(((F + others) * w) ** 2, axis=1)))
            moved |= k != ks[i]
            ks[i] = k
        if not moved:
            break
    combined = r + sum((fine[i][ks[i]] - r for i in range(len(fine))), np.zeros_like(r))
    return ks, combined


def _held_out(base: SectionEvidence, fams: Sequence[CandidateFamily], curves: Sequence[_Curve],
              masks: Sequence[np.ndarray], w: np.ndarray) -> float:
    if not fams:
        return 0.0
    num = den = 0.0
    for m in masks:
        r_tr, r_te = base.values(1.0 - m), base.values(m)
        ks, _ = _joint_fit(curves, [np.stack([e.values(1.0 - m) for e in f.evidence]) for f in fams], r_tr, w)
        comb = r_te + sum((c.patterns(np.stack([e.values(m) for e in f.evidence]))[k] - r_te
                           for c, f, k in zip(curves, fams, ks, strict=True)), np.zeros_like(r_te))
        num += float(np.sum((w * comb) ** 2))
        den += float(np.sum((w * r_te) ** 2))
    return float(np.clip(1 - num / den, 0.0, 1.0)) if den > 0 else 0.0


def cause_set(base: SectionEvidence, families: Sequence[CandidateFamily], *, folds: int = 3, n_boot: int = 100,
              seed: int = 0, min_gain: float = MIN_GAIN, max_causes: int = MAX_CAUSES,
              later: Sequence[str] | None = None) -> dict[str, Any]:
    """The greedy cause set (module docstring).

    Parameters
    ----------
    base, families : SectionEvidence, sequence of CandidateFamily
    folds, n_boot, seed, min_gain, max_causes : int, int, int, float, int
        Held-out folds, bootstrap size and seed, least held-out gain, most causes.
    later : sequence of str or None
        Names that may join after the first (the best of each quantity family: a further cause
        must explain some family best, not only soak up a remainder).

    Returns
    -------
    dict
        ``causes`` (``name``, ``kind``, ``parameter``, ``fitted``, ``held_out_share``),
        ``held_out_explained``, ``remaining_within_noise``, ``stopped`` (why no further cause)."""
    r = base.values()
    w = base.pattern().weights()
    masks = zone_folds(base.zones, folds)
    noise_level = 0.0
    if n_boot:
        R = base.values(zone_bootstrap(base.zones, n_boot, seed))
        noise_level = float(np.percentile(np.sum(((R - r[None, :]) * w) ** 2, axis=1), 95))
    curves = {f.name: _Curve(f) for f in families}
    chosen: list[CandidateFamily] = []
    shares: list[float] = []
    current = 0.0
    stopped = "no candidate left"
    remaining = r
    while len(chosen) < max_causes:
        if float(np.sum((w * remaining) ** 2)) <= noise_level:
            stopped = "the residual left is within the section-to-section scatter"
            break
        best = None
        for f in families:
            if any(f is x for x in chosen) or (chosen and later is not None and f.name not in later):
                continue
            trial = [*chosen, f]
            held = _held_out(base, trial, [curves[x.name] for x in trial], masks, w)
            if best is None or held > best[1]:
                best = (f, held)
        if best is None:
            break
        f, held = best
        trial = [*chosen, f]
        ks, _ = _joint_fit([curves[x.name] for x in trial], [np.stack([e.values() for e in x.evidence]) for x in trial],
                           r, w)
        c = curves[f.name]
        k = ks[-1]
        v = c.value(k)
        at_edge = k in (0, c.fine.size - 1)
        # a model parameter outside the range of serviceable parts is a worn or failed part: a cause
        implausible = (f.kind != "parameter" and f.plausible is not None
                       and not (f.plausible[0] <= v <= f.plausible[1]))
        if held - current < min_gain:
            stopped = (f"the next candidate ({f.name}) adds {held - current:.2f} on held-out sections, "
                       f"less than {min_gain:.2f}")
            break
        if at_edge or implausible:
            stopped = (f"the next candidate ({f.name}) would need {f.parameter} = {v:.4g}"
                       + (" at a bound of its search range" if at_edge else " outside its plausible range"))
            break
        chosen.append(f)
        shares.append(held - current)
        current = held
        _, remaining = _joint_fit([curves[x.name] for x in chosen],
                                  [np.stack([e.values() for e in x.evidence]) for x in chosen], r, w)
    causes = []
    if chosen:
        ks, remaining = _joint_fit([curves[x.name] for x in chosen],
                                   [np.stack([e.values() for e in x.evidence]) for x in chosen], r, w)
        for f, k, s in zip(chosen, ks, shares, strict=True):
            causes.append({"name": f.name, "kind": f.kind, "parameter": f.parameter,
                           "fitted": curves[f.name].value(k), "held_out_share": s})
    return {"causes": causes, "held_out_explained": current,
            "remaining_within_noise": bool(float(np.sum((w * remaining) ** 2)) <= noise_level),
            "stopped": stopped}
