"""The diagnosis scoring computed for all candidates at once (the bootstrap minimisations of
every candidate stacked, the folds' fits in one array operation: core/diagnosis/engine.py,
core/diagnosis/fit.py) gives bit for bit what the former per-candidate code gave. The former
code is kept here as the reference (``_ref_*``: one candidate, one fold, one bootstrap set at
a time); a planted error in the stacked code (the rows of two candidates mixed up) is caught."""

from __future__ import annotations

import numpy as np
import pytest

from railval.core.diagnosis import CandidateFamily, SectionEvidence, diagnose_evidence, engine, fit
from railval.core.diagnosis.evidence import zone_bootstrap, zone_folds
from railval.core.diagnosis.fit import _Curve
from railval.core.diagnosis.patterns import Component


# ----------------------------------------------------------------- the former per-candidate code
def _ref_min_cost(curve, P, w, argmin=False):
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


def _ref_fit(curve, P, w):
    Pf = curve.patterns(P)
    cost = np.sum((Pf * w) ** 2, axis=1)
    k = int(np.argmin(cost))
    return k, float(cost[k]), Pf[k]


def _ref_candidate(fam, base, w, masks, Wb):
    """(explained, held-out, fold values, bootstrap shares, value interval, noise shares) of one
    candidate, as the former ``_score``/``_held_out``/``_bootstrap`` computed them."""
    curve = _Curve(fam)
    r_full = base.values()
    r2 = float(np.sum((w * r_full) ** 2))
    P_full = np.stack([e.values() for e in fam.evidence])
    k, cost, _ = _ref_fit(curve, P_full, w)
    v = curve.value(k)
    num = den = 0.0
    folds = []
    for m in masks:
        kt, _, _ = _ref_fit(curve, np.stack([e.values(1.0 - m) for e in fam.evidence]), w)
        folds.append(curve.value(kt))
        P_te = curve.patterns(np.stack([e.values(m) for e in fam.evidence]))[kt]
        num += float(np.sum((w * P_te) ** 2))
        den += float(np.sum((w * base.values(m)) ** 2))
    held = float(np.clip(1 - num / den, 0.0, 1.0)) if den > 0 else 0.0
    R_boot = base.values(Wb)
    noise = R_boot - r_full[None, :]
    noise2 = np.sum((noise * w) ** 2, axis=1)
    P_boot = np.stack([e.values(Wb) for e in fam.evidence], axis=1)
    rb2 = np.sum((w * R_boot) ** 2, axis=1)
    cb, vb = _ref_min_cost(curve, P_boot, w, argmin=True)
    boot = [1 - c / d if d > 0 else 0.0 for c, d in zip(cb, rb2, strict=True)]
    v_ci = (float(np.percentile(vb, 5)), float(np.percentile(vb, 95)))
    cn = _ref_min_cost(curve, P_full[None, :, :] - r_full[None, None, :] + noise[:, None, :], w)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.maximum(np.where(noise2 > 0, 1 - cn / noise2, 0.0), 0.0)
    return float(np.clip(1 - cost / r2, 0.0, 1.0)), held, folds, boot, v_ci, share, v


# ----------------------------------------------------------------- a campaign's evidence, made up
QUANTITIES = ["Y_qst", "Q_qst", "ay_cb", "az_cb", "Ysum_qst"]
POSITIONS = ["w1L", "w1R", "b1"]


def _evidence(rng, zones, labels, groups, n_pair, comps, scale=1.0, like=None):
    S = len(zones)
    counts = rng.integers(0, 4, size=(S, n_pair)).astype(float) if like is None else like.counts
    sums = counts * rng.normal(0.3, scale, size=(S, n_pair))
    nb = len(labels) - n_pair
    sim = rng.uniform(0.5, 2.0, size=(S, nb)) * (1.0 if like is None else 1 + 0.2 * scale)
    meas = rng.uniform(0.5, 2.0, size=(S, nb)) if like is None else like.meas_power
    return SectionEvidence([f"S{i:02d}" for i in range(S)], list(zones), labels, groups, n_pair, sums, counts,
                           sim, meas, comps)


def _campaign(seed=3):
    rng = np.random.default_rng(seed)
    zones = [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4]
    comps = [Component.pair(q, z, p) for q in QUANTITIES for z in (1, 2, 3, 4) for p in POSITIONS]
    n_pair = len(comps)
    comps += [Component.psd(ch, b) for ch in ("ay_cb_b1", "az_cb_b1") for b in ((0.5, 2.0), (2.0, 8.0))]
    labels, groups = [c.label for c in comps], [c.group for c in comps]
    base = _evidence(rng, zones, labels, groups, n_pair, comps)
    fams = []
    # effects (4 values, log and linear), parameters (2 and 3 values, extrapolated in log),
    # measurement-like families (8 values), and one that moves nothing (a flat cost curve)
    for i, (kind, values, log, extrap) in enumerate([
            ("effect", [0.1, 0.3, 1.0, 3.0], True, False), ("effect", [0.0, 1.5, 3.0, 6.0], False, False),
            ("parameter", [1.0, 0.5], True, True), ("parameter", [2.0, 2.4], True, True),
            ("parameter", [1.0, 0.5, 0.7], True, True), ("effect", [5.0, 8.0, 10.5, 16.0], False, False),
            ("measurement", list(np.linspace(0.8, 1.2, 8)), False, False),
            ("measurement", list(np.linspace(0.7, 1.3, 8)), False, False)]):
        ev = [base if (kind == "parameter" and k == 0) else
              _evidence(rng, zones, labels, groups, n_pair, comps, scale=0.2 * (k + 1), like=base)
              for k in range(len(values))]
        bounds = (min(values) / 4, max(values) * 4) if extrap else (min(values), max(values))
        fams.append(CandidateFamily(kind, f"cand{i}", "p", values, ev, bounds, log=log, extrapolate=extrap,
                                    reference=values[0] if kind == "parameter" else None))
    fams.append(CandidateFamily("effect", "flat", "p", [1.0, 2.0, 3.0], [base, base, base], (1.0, 3.0)))
    # a range that starts beyond the first segment (that segment is left out of the minimum)
    ev = [_evidence(rng, zones, labels, groups, n_pair, comps, scale=0.3 * (k + 1), like=base) for k in range(4)]
    fams.append(CandidateFamily("parameter", "narrow", "p", [1.0, 2.0, 4.0, 8.0], ev, (3.0, 8.0), log=True,
                                extrapolate=True, reference=1.0))
    return base, fams


def _compare(base, fams, n_boot=60, folds=3, seed=5):
    res = diagnose_evidence(base, fams, n_boot=n_boot, folds=folds, seed=seed)
    w = base.pattern().weights()
    masks = zone_folds(base.zones, folds)
    Wb = zone_bootstrap(base.zones, n_boot, seed)
    by = {c.name: c for c in res.candidates}
    shares = []
    for fam in fams:
        explained, held, fold_values, boot, v_ci, share, v = _ref_candidate(fam, base, w, masks, Wb)
        c = by[fam.name]
        ci = (float(np.clip(np.percentile(boot, 5), 0, 1)), float(np.clip(np.percentile(boot, 95), 0, 1)))
        assert c.explained == explained and c.fitted == v, fam.name
        assert c.held_out_explained == held and c.fold_values == fold_values, fam.name
        assert c.explained_ci == ci, fam.name
        assert c.fitted_ci_bootstrap == (min(v_ci[0], v), max(v_ci[1], v)), fam.name
        shares.append(share)
    assert res.noise_floor == float(np.percentile(np.stack(shares).max(axis=0), 95))
    return res


def test_stacked_scoring_equals_the_per_candidate_code_bit_for_bit():
    base, fams = _campaign()
    _compare(base, fams)


def test_stacked_scoring_in_small_chunks_equals_it_too(monkeypatch):
    base, fams = _campaign(seed=11)
    monkeypatch.setattr(engine, "_CHUNK", 1)  # one candidate per stacked minimisation
    _compare(base, fams, n_boot=40, folds=2)


def test_min_cost_of_one_curve_equals_the_former_code():
    base, fams = _campaign(seed=2)
    Wb = zone_bootstrap(base.zones, 30, 1)
    w = base.pattern().weights()
    for fam in fams:
        curve = _Curve(fam)
        P = np.stack([e.values(Wb) for e in fam.evidence], axis=1)
        new_c, new_v = fit._min_cost(curve, P, w, argmin=True)
        old_c, old_v = _ref_min_cost(curve, P, w, argmin=True)
        assert np.array_equal(new_c, old_c) and np.array_equal(new_v, old_v), fam.name


def test_a_planted_row_mix_up_is_caught(monkeypatch):
    """The stacked rows handed back to the wrong candidate (a slicing error) must fail."""
    base, fams = _campaign()
    real = engine._min_cost_rows

    def mixed(X, U, lo, hi):
        best, where = real(X, U, lo, hi)
        return np.roll(best, X.shape[0] // 3), where

    monkeypatch.setattr(engine, "_min_cost_rows", mixed)
    with pytest.raises(AssertionError):
        _compare(base, fams)
