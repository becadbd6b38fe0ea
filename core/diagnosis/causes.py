"""Several causes at once (docs/diagnosis.md "Cause set"): when the best candidate leaves a
residual beyond the section scatter, what remains is diagnosed too — greedy forward
selection with a joint refit of the chosen set — and every cause is reported with the share
of the residual it adds on held-out sections.

Superposition: the pattern of the configuration with candidates i ∈ C at values v_i is taken
as r + Σ_i (P_i(v_i) − r) (each candidate's change to the residual adds; first order in the
changes, exact when they act on different components), so a set is scored without new
simulations. The set's values are fitted JOINTLY: block coordinate descent on the fine grid
of every candidate (each value refitted with the others fixed, until none moves) gives the
start, then a bounded nonlinear least-squares fit of all values at once
(``scipy.optimize.least_squares``, trust-region reflective) on the piecewise-linear pattern
curves, in u = value or log(value). Held-out: k-fold over sections stratified by zone; the set
is fitted on the training sections and scored on the test sections, 1 − Σ_f ‖P_C,f‖² / Σ_f ‖r_f‖².

Greedy: start from the empty set; rank the candidates not yet chosen by the held-out share of
the set with each added; take the first whose gain is at least ``min_gain``, whose jointly
fitted value is inside its search range (not at a bound) and, for an effect or a measurement
candidate, inside its plausible range (a model parameter beyond it is a worn part). A
candidate at a bound or implausible is reported in ``passed_over`` with its reason and the
search carries on with the next one — an implausible candidate ahead of a plausible cause
does not hide it. Stop when the residual left is within the section scatter (95th percentile
of the bootstrap deviation), when no candidate adds ``min_gain``, or at ``max_causes``.

References: Hastie, Tibshirani & Friedman 2009 §3.3.2 (forward stepwise selection) and §7.10
(k-fold cross-validation); Bertsekas 1999 §2.7 (block coordinate descent); Branch, Coleman &
Li 1999, SIAM J. Sci. Comput. 21(1) (the trust-region reflective method of
``least_squares``).
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
#: a jointly fitted value within this fraction of its search span from an end lies at the bound
EDGE = 1e-3


def _at(curve: _Curve, P: np.ndarray, u: float) -> np.ndarray:
    """The pattern of one candidate at u (value or log value), linear between the simulated
    nodes ``P`` (K, n) in family order and extrapolated beyond them as the curve does."""
    Po = P[curve.order]
    j = int(np.clip(np.searchsorted(curve.u, u, side="right") - 1, 0, curve.u.size - 2))
    t = (u - curve.u[j]) / (curve.u[j + 1] - curve.u[j])
    return Po[j] * (1.0 - t) + Po[j + 1] * t


def _combined(curves: Sequence[_Curve], nodes: Sequence[np.ndarray], r: np.ndarray, us: Sequence[float]) -> np.ndarray:
    return r + sum((_at(c, P, u) - r for c, P, u in zip(curves, nodes, us, strict=True)), np.zeros_like(r))


def _joint_fit(curves: Sequence[_Curve], nodes: Sequence[np.ndarray], r: np.ndarray, w: np.ndarray,
               iters: int = 20) -> tuple[list[float], np.ndarray]:
    """The jointly fitted u of every candidate (module docstring: coordinate descent on the fine
    grids, then ``least_squares`` on all at once) and the combined pattern (superposition)."""
    from scipy.optimize import least_squares

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
    u0 = np.array([float(c.fine[k]) for c, k in zip(curves, ks, strict=True)])
    lo = np.array([float(c.fine[0]) for c in curves])
    hi = np.array([float(c.fine[-1]) for c in curves])
    if len(curves) > 1:
        fit = least_squares(lambda u: w * _combined(curves, nodes, r, u), np.clip(u0, lo, hi), bounds=(lo, hi),
                            method="trf", x_scale=np.maximum(hi - lo, 1e-12), max_nfev=200)
        c0 = float(np.sum((w * _combined(curves, nodes, r, u0)) ** 2))
        if float(np.sum(fit.fun ** 2)) <= c0:
            u0 = fit.x
    return [float(u) for u in u0], _combined(curves, nodes, r, u0)


def _value(curve: _Curve, u: float) -> float:
    v = float(np.exp(u)) if curve.log else float(u)
    return float(min(max(v, curve.range[0]), curve.range[1]))


def _at_edge(curve: _Curve, u: float) -> bool:
    lo, hi = float(curve.fine[0]), float(curve.fine[-1])
    return bool(min(u - lo, hi - u) <= EDGE * (hi - lo))


def _held_out(base: SectionEvidence, fams: Sequence[CandidateFamily], curves: Sequence[_Curve],
              masks: Sequence[np.ndarray], w: np.ndarray) -> float:
    if not fams:
        return 0.0
    num = den = 0.0
    for m in masks:
        r_tr, r_te = base.values(1.0 - m), base.values(m)
        us, _ = _joint_fit(curves, [np.stack([e.values(1.0 - m) for e in f.evidence]) for f in fams], r_tr, w)
        comb = _combined(curves, [np.stack([e.values(m) for e in f.evidence]) for f in fams], r_te, us)
        num += float(np.sum((w * comb) ** 2))
        den += float(np.sum((w * r_te) ** 2))
    return float(np.clip(1 - num / den, 0.0, 1.0)) if den > 0 else 0.0


def _refusal(f: CandidateFamily, curve: _Curve, u: float) -> str:
    """Why a candidate cannot join the set at its jointly fitted u ("" when it can)."""
    v = _value(curve, u)
    if _at_edge(curve, u):
        return f"{f.parameter} = {v:.4g} at a bound of its search range"
    # a model parameter outside the range of serviceable parts is a worn or failed part: a cause
    if f.kind != "parameter" and f.plausible is not None and not (f.plausible[0] <= v <= f.plausible[1]):
        return (f"{f.parameter} = {v:.4g} outside its plausible range "
                f"[{f.plausible[0]:.4g}, {f.plausible[1]:.4g}]")
    return ""


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
        ``held_out_explained``, ``remaining_within_noise``, ``stopped`` (why no further cause),
        ``passed_over`` (``name``, ``reason``: candidates that would have added enough but sat
        at a bound or outside their plausible range)."""
    r = base.values()
    w = base.pattern().weights()
    masks = zone_folds(base.zones, folds)
    noise_level = 0.0
    if n_boot:
        R = base.values(zone_bootstrap(base.zones, n_boot, seed))
        noise_level = float(np.percentile(np.sum(((R - r[None, :]) * w) ** 2, axis=1), 95))
    curves = {f.name: _Curve(f) for f in families}
    nodes = {f.name: np.stack([e.values() for e in f.evidence]) for f in families}
    chosen: list[CandidateFamily] = []
    shares: list[float] = []
    passed: list[dict[str, str]] = []
    refused: set[str] = set()
    current = 0.0
    stopped = "no candidate left"
    remaining = r
    while len(chosen) < max_causes:
        if float(np.sum((w * remaining) ** 2)) <= noise_level:
            stopped = "the residual left is within the section-to-section scatter"
            break
        pick, stopped = _next_cause(base, families, chosen, refused, passed, later, curves, nodes, masks, w, r,
                                    current, min_gain)
        if pick is None:
            break
        held, f = pick
        chosen.append(f)
        shares.append(held - current)
        current = held
        _, remaining = _joint_fit([curves[x.name] for x in chosen], [nodes[x.name] for x in chosen], r, w)
    stopped = stopped or f"the set holds the most causes ({max_causes})"
    causes = []
    if chosen:
        us, remaining = _joint_fit([curves[x.name] for x in chosen], [nodes[x.name] for x in chosen], r, w)
        for f, u, s in zip(chosen, us, shares, strict=True):
            causes.append({"name": f.name, "kind": f.kind, "parameter": f.parameter,
                           "fitted": _value(curves[f.name], u), "held_out_share": s})
    return {"causes": causes, "held_out_explained": current,
            "remaining_within_noise": bool(float(np.sum((w * remaining) ** 2)) <= noise_level),
            "stopped": stopped, "passed_over": passed}


def _next_cause(base: SectionEvidence, families: Sequence[CandidateFamily], chosen: list[CandidateFamily],
                refused: set[str], passed: list[dict[str, str]], later: Sequence[str] | None,
                curves: dict, nodes: dict, masks: Sequence[np.ndarray], w: np.ndarray, r: np.ndarray,
                current: float, min_gain: float) -> tuple[tuple[float, CandidateFamily] | None, str]:
    """One greedy step: the candidates ranked by the held-out share of the set with each added;
    the first that adds ``min_gain`` and is neither at a bound nor implausible (those go to
    ``passed``/``refused`` and the search carries on); (held-out share, candidate) or None, and
    why the search stops there."""
    ranked = []
    for f in families:
        if any(f is x for x in chosen) or f.name in refused or (chosen and later is not None and f.name not in later):
            continue
        trial = [*chosen, f]
        ranked.append((_held_out(base, trial, [curves[x.name] for x in trial], masks, w), f))
    ranked.sort(key=lambda x: -x[0])
    for held, f in ranked:
        if held - current < min_gain:
            return None, (f"the next candidate ({f.name}) adds {held - current:.2f} on held-out sections, "
                          f"less than {min_gain:.2f}")
        trial = [*chosen, f]
        us, _ = _joint_fit([curves[x.name] for x in trial], [nodes[x.name] for x in trial], r, w)
        why = _refusal(f, curves[f.name], us[-1])
        if why:  # reported and skipped: the search carries on with the next candidate
            passed.append({"name": f.name, "reason": f"would need {why}"})
            refused.add(f.name)
            continue
        return (held, f), ""
    return None, "no candidate left" if not passed else "every further candidate is passed over (passed_over)"
