"""The vectorised aggregation of :func:`railval.core.validation.validate` gives the same
result as the per-pair reference below (the code it replaced: one Python tuple per pair, one
``value_under`` call per pair and reading, one DataFrame per quantity): ``to_dict()`` and the
``pairs`` table equal, on synthetic values with gaps, NaN, alternatives and an empty quantity,
and on the demo campaign. A test also checks the reference against hand-computed values and
that a wrong pairing would be caught."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from railval.core import validation as v
from railval.core.coverage import coverage
from railval.core.definitions import CHOSEN, READINGS, alternatives_for
from railval.core.en14363 import SectionValues
from railval.core.quantities import QUANTITIES, QUANTITY_IDS
from railval.core.types import SectionInfo

# -- reference: the per-pair implementation -----------------------------------------------


def _ref_pairs(mv_all, sv_all, secs, common):
    recs = {q: [] for q in QUANTITY_IDS}
    for sid in common:
        zone = int(secs[sid].zone)
        for key, m in mv_all[sid].items():
            s = sv_all[sid].get(key)
            if s is None or not (np.isfinite(m) and np.isfinite(s)):
                continue
            recs[key[0]].append((sid, zone, key[1], float(m), float(s)))
    return recs


def _ref_quantity(qid, rec, veh, rng, n_boot, top=5):
    q = QUANTITIES[qid]
    ml = q.mean_limit(veh.Q0_kN, veh.kind, veh.secondary_suspension)
    sl = q.std_limit(veh.Q0_kN, veh.kind, veh.secondary_suspension)
    m = np.array([r[3] for r in rec], dtype=np.float64)
    s = np.array([r[4] for r in rec], dtype=np.float64)
    d = v.difference(s, m)
    n = d.size
    mean = float(d.mean()) if n else float("nan")
    std = float(d.std(ddof=1)) if n >= 2 else float("nan")
    mci, sci = v.bootstrap_norm_ci(d, ml, sl, n_boot=n_boot, rng=rng)
    dn = d / sl
    ss = float(np.sum(d * d))
    drill = [{"section": rec[i][0], "zone": rec[i][1], "position": rec[i][2], "M": rec[i][3],
              "S": rec[i][4], "D": float(d[i]), "D_norm": float(dn[i]),
              "share_of_sum_of_squares": float(d[i] ** 2 / ss) if ss > 0 else 0.0}
             for i in np.argsort(-np.abs(dn), kind="stable")[:top]]
    res = v.QuantityResult(qid, q.unit, n, len({r[2] for r in rec}), len({r[0] for r in rec}),
                           mean, std, ml, sl, mci, sci, drill)
    frame = {"quantity": qid, "section": [r[0] for r in rec], "zone": [r[1] for r in rec],
             "position": [r[2] for r in rec], "M": m, "S": s, "D": d, "D_norm": dn}
    return res, frame


def _ref_alternatives(qid, res, rec, mv_all, sv_all):
    out = []
    for reading in alternatives_for(QUANTITIES[qid]):
        m = np.array([mv_all[r[0]].value_under(reading.id, (qid, r[2])) for r in rec])
        s = np.array([sv_all[r[0]].value_under(reading.id, (qid, r[2])) for r in rec])
        changed = int(np.sum((m != np.array([r[3] for r in rec]))
                             | (s != np.array([r[4] for r in rec]))))
        d = v.difference(s, m)
        defined = bool(np.all(np.isfinite(d)))
        mean = float(d.mean()) if d.size and defined else float("nan")
        std = float(d.std(ddof=1)) if d.size >= 2 and defined else float("nan")
        passed = v.judge(d.size, mean, std, res.mean_limit, res.std_limit) if defined else None
        sm = QUANTITIES[qid].sliding_mean
        out.append({"reading": reading.to_dict(), "differs_in": reading.differs_from_chosen(sm),
                    "description": reading.describe(sm), "label": reading.short(sm),
                    "values_changed": changed, "mean": v._none_if_nan(mean),
                    "std": v._none_if_nan(std),
                    "mean_norm": v._none_if_nan(mean / res.mean_limit),
                    "std_norm": v._none_if_nan(std / res.std_limit), "pass": passed,
                    "flips": passed is not None and passed != res.passed})
    return out


def reference_validate(mv_all, sv_all, sections, vehicle, *, n_boot=1000, seed=0):
    veh = v.Vehicle.from_any(vehicle)
    secs = {s.id: s for s in sections}
    common = sorted(set(mv_all) & set(sv_all))
    recs = _ref_pairs(mv_all, sv_all, secs, common)
    results, frames = {}, []
    for qi, qid in enumerate(QUANTITY_IDS):
        results[qid], frame = _ref_quantity(qid, recs[qid], veh,
                                            np.random.default_rng([seed, qi]), n_boot)
        frames.append(pd.DataFrame(frame))
    zone_of = {sid: int(info.zone) for sid, info in secs.items()}
    cov = coverage({q: {r[0] for r in recs[q]} for q in QUANTITY_IDS},
                   {q: {r[2] for r in recs[q]} for q in QUANTITY_IDS},
                   {q: len(recs[q]) for q in QUANTITY_IDS}, zone_of)
    under = {}
    if common and all(hasattr(mv_all[s], "value_under") for s in common):
        for qid, res in results.items():
            res.alternatives = _ref_alternatives(qid, res, recs[qid], mv_all, sv_all)
        for reading in READINGS:
            if reading != CHOSEN:
                ok = []
                for res in results.values():
                    alt = next((a for a in res.alternatives
                                if a["reading"]["id"] == reading.id), None)
                    ok.append(res.passed if alt is None or alt["pass"] is None else alt["pass"])
                under[reading.id] = bool(cov.ok and all(ok))
    validated = cov.ok and all(r.passed for r in results.values())
    return v.ValidationResult(validated, cov, results, veh, n_boot, seed, 0.95,
                              pd.concat(frames, ignore_index=True), [],
                              supplementary=v._supplementary(mv_all, sv_all, common, zone_of),
                              validated_under=under)


# -- data ---------------------------------------------------------------------------------

POSITIONS = ["w1L", "w1R", "w2L", "w2R", "cb1", "cb2", "ws1", "ws2"]


def _synthetic(seed: int, n_sections: int = 14, gaps: bool = True, empty: str | None = None):
    """Both sides' SectionValues: every quantity at a few positions, alternatives on part of
    the keys (NaN on one), a few NaN / missing values; ``empty`` a quantity left out."""
    rng = np.random.default_rng(seed)
    sections = [SectionInfo(f"S{i:02d}", 0.0, 0.0, 90.0, 1 + i % 4, 0.0, 100.0)
                for i in range(n_sections)]
    sides = []
    for side in range(2):
        out = {}
        for sec in sections:
            vals = {}
            for q in QUANTITY_IDS:
                if q == empty:
                    continue
                for p in POSITIONS[: 2 + (len(q) % 3)]:
                    x = rng.normal(1.0, 0.3) * QUANTITIES[q].std_limit(80.0, "passenger", True)
                    vals[(q, p)] = 0.0 if rng.random() < 0.03 else x
            keys = list(vals)
            if gaps:
                for k in rng.choice(len(keys), 3, replace=False):
                    if side:
                        vals[keys[k]] = float("nan")
                    else:
                        vals.pop(keys[k])
            alts = {}
            for r in READINGS:
                if r != CHOSEN and rng.random() < 0.8:
                    alts[r.id] = {k: x * (1 + 0.05 * rng.standard_normal())
                                  for k, x in vals.items() if rng.random() < 0.5}
            if side and gaps and alts:
                rid = next(iter(alts))
                if alts[rid]:
                    alts[rid][next(iter(alts[rid]))] = float("nan")
            out[sec.id] = SectionValues(sec.id, vals, alternatives=alts)
        sides.append(out)
    return sides[0], sides[1], sections


def _same(new, ref):
    a, b = new.to_dict(), ref.to_dict()
    assert a == b
    pd.testing.assert_frame_equal(new.pairs, ref.pairs)


# -- tests --------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_vectorised_equals_reference_synthetic(seed):
    mv, sv, secs = _synthetic(seed)
    veh = {"kind": "passenger", "secondary_suspension": True, "Q0_kN": 80.0}
    _same(v.validate(mv, sv, secs, veh, n_boot=300, seed=seed),
          reference_validate(mv, sv, secs, veh, n_boot=300, seed=seed))


def test_vectorised_equals_reference_with_an_empty_quantity_and_plain_dicts():
    mv, sv, secs = _synthetic(5, empty=QUANTITY_IDS[3])
    veh = v.Vehicle("freight", False, 100.0)
    _same(v.validate(mv, sv, secs, veh, n_boot=50), reference_validate(mv, sv, secs, veh, n_boot=50))
    plain_m = {k: dict(x) for k, x in mv.items()}
    plain_s = {k: dict(x) for k, x in sv.items()}
    new = v.validate(plain_m, plain_s, secs, veh, n_boot=50)
    _same(new, reference_validate(plain_m, plain_s, secs, veh, n_boot=50))
    assert new.validated_under == {}


def test_reference_matches_hand_computation_and_catches_wrong_pairs():
    """Independent check of eq. (4) statistics on two sections, and a pairing mistake
    (simulated values shifted by one pair) changes the result."""
    mv, sv, secs = _synthetic(7, gaps=False)
    res = v.validate(mv, sv, secs, v.Vehicle(), n_boot=0)
    q = QUANTITY_IDS[0]
    ms, ss = [], []
    for sid in sorted(mv):
        for key, m in mv[sid].items():
            if key[0] == q:
                ms.append(m)
                ss.append(sv[sid][key])
    d = [(s - m) * (1 if m > 0 else -1) if m != 0 else s for m, s in zip(ms, ss, strict=True)]
    mean = sum(d) / len(d)
    var = sum((x - mean) ** 2 for x in d) / (len(d) - 1)
    assert res.quantities[q].mean == pytest.approx(mean, rel=1e-12)
    assert res.quantities[q].std == pytest.approx(var ** 0.5, rel=1e-12)
    shifted = {sid: SectionValues(sid, dict(zip(x, list(x.values())[1:] + list(x.values())[:1],
                                                strict=True)), alternatives=x.alternatives)
               for sid, x in sv.items()}
    assert v.validate(mv, shifted, secs, v.Vehicle(), n_boot=0).to_dict() != res.to_dict()


def test_vectorised_equals_reference_on_the_demo_campaign(sqlite_database, tmp_path):
    from railval.app.services.validation import source_values
    from railval.db import repo
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    with sqlite_database.write_session(deferred=True) as s:
        secs = repo.section_infos(s, "demo")
        veh = repo.vehicle_info(s, "demo")
        mv = source_values(s, "demo", None, secs)
        for cname in ("baseline", "variant1"):
            sv = source_values(s, "demo", cname, secs)
            new = v.validate(mv, sv, secs, veh, n_boot=200, seed=4)
            _same(new, reference_validate(mv, sv, secs, veh, n_boot=200, seed=4))
            assert new.supplementary and new.validated_under
