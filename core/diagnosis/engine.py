"""The diagnosis: rank candidate causes of a configuration's residual with the evidence needed
to trust the answer — explained share in-sample and on held-out sections, bootstrap intervals,
noise floor, plausibility, identifiability — and a verdict (docs/design.md §7, docs/diagnosis.md).

A candidate *fixes* a quantity whose weighted residual falls by more than ``change`` (default
20 %) and *worsens* one whose residual grows by more than that.

References: Efron & Tibshirani 1993 ch. 6/§8.2 (bootstrap, stratified); Hastie, Tibshirani &
Friedman 2009 §7.10 (k-fold cross-validation); Polach & Böttcher 2014 §5 (D_v, limits, zones).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence, zone_bootstrap, zone_folds
from railval.core.diagnosis.fit import (
    CandidateFamily,
    _Curve,
    _fit_costs,
    _fit_folds,
    _min_cost_rows,
)
from railval.core.diagnosis.patterns import Pattern, component_parts
from railval.core.diagnosis.plausibility import plausibility_flags, separating_evidence
from railval.core.diagnosis.result import DiagnosisResult, TrustedCandidate
from railval.core.errors import InvalidSignal

#: Verdict thresholds: a cause must explain at least ``STRONG`` of the residual on held-out
#: sections; two candidates "explain alike" when their held-out shares differ by less than
#: ``ALIKE_MARGIN`` and their signatures correlate above ``ALIKE_CORRELATION``.
STRONG = 0.5
ALIKE_MARGIN = 0.15
ALIKE_CORRELATION = 0.8


def _family_summary(fam: CandidateFamily, value: float) -> str:
    if fam.kind == "measurement" and fam.parameter == "offset":
        return f"{fam.title or fam.name} the true value {value:+.3g} {fam.unit} (offset of the measurement)"
    if fam.kind == "measurement" and fam.parameter in ("sign", "swap", "shift"):  # discrete (measurement.py)
        return f"{fam.title or fam.name} ({fam.parameter} of the measurement)"
    if fam.kind == "measurement":
        return f"{fam.title or fam.name} {value:.3g} × the true value ({fam.parameter} of the measurement)"
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

    * explained share on all sections (:mod:`railval.core.diagnosis.fit`) and its stratified
      bootstrap interval (refit on every resample of the sections, :func:`zone_bootstrap`);
    * held-out share: k-fold over sections stratified by zone (:func:`zone_folds`); the
      fitted value of the training sections scored on the test sections,
      1 − Σ_f ‖P_f(v*_f)‖² / Σ_f ‖r_f‖²; candidates are ranked by it;
    * noise floor: the share of pure section scatter n_b = r(w_b) − r (bootstrap deviation of
      the residual) that the best candidate can explain, 95th percentile over the resamples —
      what the candidates "explain" when there is nothing but scatter; a candidate is
      significant when the lower end (5 %) of its bootstrap interval exceeds it; families
      marked ``floor_only`` (a screened diagnosis's stand-ins) count here and nowhere else;
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

    Parameters
    ----------
    base : SectionEvidence
        The configuration's residual pattern per section.
    families : sequence of CandidateFamily
        Candidates with their evidence along one parameter each.
    validated : bool
        The configuration passes the validation (then ``none`` unless a strong cause).
    n_boot, folds, seed : int
        Bootstrap resamples, held-out folds, random seed.
    change : float
        Relative residual change for *fixes*/*worsens* (default 20 %).
    strong, alike_margin, alike_correlation : float
        The verdict thresholds :data:`STRONG`, :data:`ALIKE_MARGIN`, :data:`ALIKE_CORRELATION`.

    Returns
    -------
    DiagnosisResult
        Ranked candidates, noise floor, identifiability evidence and verdict.
    """
    setup = _Setup(base, n_boot, folds, seed)
    fits = [_Fit(fam, setup) for fam in families]
    _bootstrap_all(fits, setup)
    cands: list[TrustedCandidate] = []
    noise_share = np.zeros((len(families), n_boot))
    for fi, fit in enumerate(fits):
        if fit.fam.floor_only:  # a screened-out candidate's stand-in: its share of scatter only
            noise_share[fi] = fit.noise_share
            continue
        cand, noise_share[fi] = _score(fit, setup, change)
        cands.append(cand)
    noise_floor = float(np.percentile(noise_share.max(axis=0), 95)) if n_boot and families else 0.0
    within_noise = bool(n_boot and setup.r2 <= float(np.percentile(setup.noise2, 95)))
    _significance(cands, noise_floor)
    cands.sort(key=lambda c: (-c.held_out_explained, -c.explained))
    evidence, alike = _identifiability(cands, setup.residual, setup.w, alike_margin, alike_correlation)
    best = cands[0] if cands else None
    verdict, why = _verdict(best, alike, within_noise=within_noise, noise_floor=noise_floor, validated=validated,
                            strong=strong)
    note = {"none": "no candidate explains the residual: " + why, "uncertain": "uncertain: " + why}.get(verdict, why)
    return DiagnosisResult(setup.residual, list(cands), not alike, evidence, note, verdict=verdict,
                           noise_floor=noise_floor, residual_within_noise=within_noise, alike=alike,
                           unexplained=_unexplained(setup.residual, best), folds=len(setup.masks), bootstrap=n_boot)


class _Setup:
    """What every candidate is scored against: the residual r (all sections), its weights, the
    zone-stratified folds, the bootstrap resamples and the pure-scatter deviations n_b."""

    def __init__(self, base: SectionEvidence, n_boot: int, folds: int, seed: int):
        self.base = base
        self.r_full = base.values()
        self.residual = base.pattern()
        self.w = self.residual.weights()
        self.r2 = float(np.sum((self.w * self.r_full) ** 2))
        if not self.r2 > 0:
            raise InvalidSignal("the residual pattern is zero: nothing to diagnose")
        S = len(base.sections)
        self.n_boot = n_boot
        self.Wb = zone_bootstrap(base.zones, n_boot, seed) if n_boot > 0 else np.zeros((0, S))
        self.masks = zone_folds(base.zones, folds)
        self.R_boot = base.values(self.Wb) if n_boot > 0 else np.zeros((0, self.r_full.size))
        self.noise = self.R_boot - self.r_full[None, :]
        self.noise2 = np.sum((self.noise * self.w) ** 2, axis=1)
        self.before = self.residual.group_norms()
        self.rb2 = np.sum((self.w * self.R_boot) ** 2, axis=1)
        self.train = [1.0 - m for m in self.masks]
        self.test_den = [float(np.sum((self.w * base.values(m)) ** 2)) for m in self.masks]


class _Fit:
    """One candidate against a :class:`_Setup`: its curve, the fit on all sections (best fine-grid
    index ``k``, cost, pattern ``Pk``, the cost at every fine-grid point), the held-out share
    and fold values; :func:`_bootstrap_all` adds the bootstrap (``boot``, ``v_ci``,
    ``noise_share``). A ``floor_only`` family needs its curve and patterns alone (its share of
    scatter comes from the bootstrap)."""

    def __init__(self, fam: CandidateFamily, st: _Setup):
        self.fam = fam
        self.curve = curve = _Curve(fam)
        self.P_full = np.stack([e.values() for e in fam.evidence])
        self.boot: list[float] = []
        self.noise_share = np.zeros(0)
        if fam.floor_only:
            return
        self.k, self.costs, self.Pk = _fit_costs(curve, self.P_full, st.w)
        self.cost = float(self.costs[self.k])
        self.v = curve.value(self.k)
        self.held, self.fold_values = _held_out(curve, fam, st)
        self.v_ci = (self.v, self.v)


def _held_out(curve: _Curve, fam: CandidateFamily, st: _Setup) -> tuple[float, list[float]]:
    """Held-out share (value fitted on the training sections of each fold, scored on its test
    sections; Hastie, Tibshirani & Friedman 2009 §7.10) and the value fitted in each fold:
    1 − Σ_f ‖w·P_f(v*_f)‖² / Σ_f ‖w·r_f‖², the folds' fits in one array operation."""
    if not st.masks:
        return 0.0, []
    P_tr = np.stack([np.stack([e.values(tr) for e in fam.evidence]) for tr in st.train])
    kts = _fit_folds(curve, P_tr, st.w)
    num = den = 0.0
    fold_values: list[float] = []
    for i, m in enumerate(st.masks):
        kt = int(kts[i])
        fold_values.append(curve.value(kt))
        P_te = curve.pattern_at(np.stack([e.values(m) for e in fam.evidence]), kt)
        num += float(np.sum((st.w * P_te) ** 2))
        den += st.test_den[i]
    return (float(np.clip(1 - num / den, 0.0, 1.0)) if den > 0 else 0.0), fold_values


#: rows × nodes × components of one stacked minimisation in :func:`_bootstrap_all` (memory bound)
_CHUNK = 1 << 22


def _bootstrap_all(fits: Sequence[_Fit], st: _Setup) -> None:
    """Refit every candidate on every resample of the sections (Efron & Tibshirani 1993 §8.2):
    explained shares, the 5–95 % interval of the fitted value, and the share of pure scatter
    n_b the candidate's change P(v) − r explains on each resample (its contribution to the
    noise floor). The minimisations of all candidates with the same number of simulated values
    run stacked in one :func:`railval.core.diagnosis.fit._min_cost_rows` call (per chunk), each
    candidate's rows computed exactly as alone."""
    B = st.n_boot
    if not B:
        return
    by_k: dict[int, list[_Fit]] = {}
    for f in fits:
        by_k.setdefault(f.curve.u.size, []).append(f)
    for K, group in by_k.items():
        per = max(1, _CHUNK // (2 * B * K * st.r_full.size))
        for c0 in range(0, len(group), per):
            chunk = group[c0:c0 + per]
            rows = [B if f.fam.floor_only else 2 * B for f in chunk]  # a stand-in: its scatter rows only
            X = np.concatenate([_nodes(f, st) for f in chunk])
            U = np.repeat(np.stack([f.curve.u for f in chunk]), rows, axis=0)
            lo = np.repeat([float(f.curve.fine[0]) for f in chunk], rows)
            hi = np.repeat([float(f.curve.fine[-1]) for f in chunk], rows)
            best, where = _min_cost_rows(X, U, lo, hi)
            s = 0
            for f, n in zip(chunk, rows, strict=True):
                if f.fam.floor_only:
                    _scatter_share(f, st, best[s:s + B])
                else:
                    _bootstrap_finish(f, st, best[s:s + B], np.array(where[s:s + B]), best[s + B:s + 2 * B])
                s += n


def _nodes(f: _Fit, st: _Setup) -> np.ndarray:
    """The weighted nodes (2B, K, n) in curve order of one candidate's bootstrap minimisations:
    its patterns on every resample, then its change P_k − r added to pure scatter n_b (a
    ``floor_only`` family: the latter (B, K, n) alone)."""
    noise = f.P_full[None, :, :] - st.r_full[None, None, :] + st.noise[:, None, :]
    order = f.curve.order
    if f.fam.floor_only:
        return noise[:, order, :] * st.w
    P_boot = np.stack([e.values(st.Wb) for e in f.fam.evidence], axis=1)  # (B, K, n), family order
    return np.concatenate([P_boot[:, order, :] * st.w, noise[:, order, :] * st.w])


def _bootstrap_finish(f: _Fit, st: _Setup, cb: np.ndarray, where_b: np.ndarray, cn: np.ndarray) -> None:
    vb = f.curve.values_at(where_b)
    f.boot = [1 - c / d if d > 0 else 0.0 for c, d in zip(cb, st.rb2, strict=True)]
    f.v_ci = (float(np.percentile(vb, 5)), float(np.percentile(vb, 95)))
    _scatter_share(f, st, cn)


def _scatter_share(f: _Fit, st: _Setup, cn: np.ndarray) -> None:
    """The share of pure scatter n_b the candidate explains on each resample, 1 − cost / ‖w·n_b‖²
    (0 where there is no scatter; never below 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(st.noise2 > 0, 1 - cn / st.noise2, 0.0)
    f.noise_share = np.maximum(share, 0.0)


def _score(fit: _Fit, st: _Setup, change: float) -> tuple[TrustedCandidate, np.ndarray]:
    """One candidate: the fit on all sections, held-out share, bootstrap, plausibility; and its
    share of pure scatter per resample."""
    fam, curve, k, cost, Pk, v = fit.fam, fit.curve, fit.k, fit.cost, fit.Pk, fit.v
    explained = float(np.clip(1 - cost / st.r2, 0.0, 1.0))
    held, fold_values = fit.held, fit.fold_values
    boot, v_ci, noise_share = fit.boot, fit.v_ci, fit.noise_share
    ci = (float(np.clip(np.percentile(boot, 5), 0, 1)), float(np.clip(np.percentile(boot, 95), 0, 1))) \
        if boot else (explained, explained)
    before, residual = st.before, st.residual
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
    expl = summary + (": " + fam.explanation if fam.explanation and fam.kind in ("effect", "measurement") else
                      ("; a model parameter error, not a missing effect" if fam.kind == "parameter" else ""))
    cand = TrustedCandidate(
        fam.name, explained, params, sorted(fixes, key=lambda g: after[g] - before[g]),
        sorted(worsens, key=lambda g: before[g] - after[g]), expl,
        Pattern(residual.labels, residual.groups, st.r_full - Pk, residual.components), math.sqrt(cost),
        {g: (before[g], after[g]) for g in before}, kind=fam.kind,
        held_out_explained=held, explained_ci=ci, plausible=ok, at_bound=at_edge, flags=flags,
        summary=summary, reference=fam.reference, fitted=v, parameter=fam.parameter,
        fitted_ci=_widened(lo_ci, hi_ci, fold_values, _lack_of_fit_range(curve, fit.costs, k, cost, residual)),
        fitted_ci_bootstrap=(lo_ci, hi_ci),
        fold_values=fold_values, clearly_implausible=bool(clearly))
    return cand, noise_share


def _significance(cands: Sequence[TrustedCandidate], noise_floor: float) -> None:
    """Significant: the 5 % end of the bootstrap interval and the held-out share both exceed
    the noise floor; flags for the others and for a fit that does not hold out."""
    for c in cands:
        c.significant = c.explained_ci[0] > noise_floor and c.held_out_explained > noise_floor
        if not c.significant:
            c.flags.append(f"explains no more than the section-to-section scatter alone can produce "
                           f"(noise floor {noise_floor:.2f}; explained {c.explained_ci[0]:.2f}–"
                           f"{c.explained_ci[1]:.2f}, held-out {c.held_out_explained:.2f})")
        if c.explained - c.held_out_explained > 0.25:
            c.flags.append(f"explains {c.explained:.2f} of the residual on the sections it was fitted to but "
                           f"only {c.held_out_explained:.2f} on held-out sections")


def _identifiability(cands: Sequence[TrustedCandidate], residual: Pattern, w: np.ndarray, alike_margin: float,
                     alike_correlation: float) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The components separating the two best (``evidence``) and the pairs that explain alike
    (held-out shares within ``alike_margin``, signatures correlating above ``alike_correlation``)."""
    evidence: list[dict[str, Any]] = []
    alike: list[dict[str, Any]] = []
    if len(cands) < 2:
        return evidence, alike
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
    return evidence, alike


def _verdict(best: TrustedCandidate | None, alike: Sequence[dict[str, Any]], *, within_noise: bool,
             noise_floor: float, validated: bool, strong: float) -> tuple[str, str]:
    """``none`` | ``uncertain`` | ``cause`` and why (docs/diagnosis.md "Verdict")."""
    if best is None:
        return "none", "no candidate applies"
    if within_noise:
        return "none", "the residual is within the section-to-section scatter"
    if not best.significant:
        return "none", f"no candidate explains more than the noise floor ({noise_floor:.2f})"
    if validated and best.held_out_explained < strong:
        return "none", (f"the configuration passes and no candidate explains ≥ {strong:.1f} of the "
                        f"rest on held-out sections (best {best.name} {best.held_out_explained:.2f})")
    if best.held_out_explained < strong or best.explained < strong:
        return "uncertain", (f"the best candidate {best.name} explains only {best.held_out_explained:.2f} "
                             f"on held-out sections ({best.explained:.2f} in-sample)")
    if alike:
        return "uncertain", "; ".join(x["advice"] for x in alike)
    if not best.plausible and best.clearly_implausible:
        return "uncertain", "; ".join(best.flags[:1])
    if best.explained - best.held_out_explained > 0.25:
        return "uncertain", f"{best.name} does not hold on held-out sections"
    return "cause", (f"{best.summary} explains {best.held_out_explained:.2f} of the residual on "
                     f"held-out sections ({best.explained:.2f} in-sample; noise floor {noise_floor:.2f})")


def _lack_of_fit_range(curve: _Curve, c: np.ndarray, k: int, cost: float, residual: Pattern,
                       level: float = 0.90) -> tuple[float, float]:
    """Values whose remaining residual is within the lack-of-fit region of the best fit:
    ‖P(v)‖²_W ≤ ‖P(v*)‖²_W·(1 + F_{1, n−1}(level)/(n − 1)) with n the number of quantity
    groups (the components of one group are strongly correlated; each group carries weight 1,
    so n is taken as the effective number of observations — an assumption). The region grows
    with what the candidate leaves unexplained, so it reflects model error, not only section
    scatter (Bates & Watts 1988 §6.1, likelihood region of a nonlinear least-squares fit).
    ``c``: the cost ‖w·P(v)‖² at every fine-grid point (the fit's)."""
    n = len(set(residual.groups))
    if n < 3:
        return curve.value(k), curve.value(k)
    limit = cost * (1.0 + _f_ppf(level, n - 1) / (n - 1))
    lo = k
    while lo > 0 and c[lo - 1] <= limit:
        lo -= 1
    hi = k
    while hi < c.size - 1 and c[hi + 1] <= limit:
        hi += 1
    return curve.value(lo), curve.value(hi)


@lru_cache(maxsize=64)
def _f_ppf(level: float, dof: int) -> float:
    """F_{1, dof}(level), the quantile of the F distribution, remembered per degree of freedom:
    ``scipy.special.fdtri``, the inverse of the F distribution function that ``scipy.stats.f.ppf``
    itself calls (tests/test_diagnosis_trust.py checks them equal), without importing
    scipy.stats (≈ 0.4 s, on the screened diagnosis's critical path in a fresh process)."""
    from scipy.special import fdtri

    return float(fdtri(1, dof, level))


def _widened(lo: float, hi: float, folds: Sequence[float], lack: tuple[float, float]) -> tuple[float, float]:
    """The fitted value's interval: bootstrap ∪ fold fits ∪ lack-of-fit region."""
    return min(lo, *folds, lack[0]), max(hi, *folds, lack[1])


def _unexplained(residual: Pattern, best: TrustedCandidate | None, n: int = 6) -> list[dict[str, Any]]:
    """The largest components left after the best candidate (or of the residual): quantity,
    zone, position or PSD band with value before/after."""
    w = residual.weights()
    after = residual.values if best is None else best.remaining(residual)
    out = []
    for k in np.argsort(-np.abs(after * w))[:n]:
        if after[k] == 0:
            break
        out.append({"component": residual.labels[k], **component_parts(residual.labels[k], residual.groups[k]),
                    "residual": float(residual.values[k]), "after_best": float(after[k])})
    return out


# ----------------------------------------------------------------------------- grids
