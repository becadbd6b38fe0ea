"""DynoTRAIN validation (core.validation): eq. (4) sign rule, statistics by hand, coverage
shortfall messages, verdict, bootstrap CIs, drill-down and the JSON contract of docs/design.md §8."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railval.core.en14363 import evaluate_section
from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITY_IDS, pairs_for_channels
from railval.core.types import WHEEL_POSITIONS, SectionInfo, SignalSet
from railval.core.validation import Vehicle, difference, validate

ALL_CHANNELS = [f"{k}_{p}" for k in "YQ" for p in WHEEL_POSITIONS] + [
    f"{k}_cb_{b}" for k in ("ay", "az") for b in ("b1", "b2")]
KEYS = pairs_for_channels(ALL_CHANNELS)
VEH = Vehicle("passenger", True, 80.0)


def _sections(zones):
    return [SectionInfo(f"S{i:02d}", 0.0, 0.0, 100.0, z, 0.0, 100.0) for i, z in enumerate(zones)]


def _values(secs, fn, keys=KEYS):
    return {s.id: {k: fn(s, k) for k in keys} for s in secs}


FULL = _sections([1, 2, 3, 4] * 3)


# ---------------------------------------------------------------- eq. (4)
@pytest.mark.parametrize("S,M,D", [
    (12.0, 10.0, 2.0),     # overshoot, M > 0
    (8.0, 10.0, -2.0),     # undershoot, M > 0
    (-12.0, -10.0, 2.0),   # M < 0: larger magnitude → positive
    (-8.0, -10.0, -2.0),   # M < 0: smaller magnitude → negative
    (3.0, -1.0, -4.0),     # opposite sign to M < 0: (3 − (−1))·(−1)
    (-3.0, 0.0, -3.0),     # M = 0 → D = S
    (0.5, 0.0, 0.5),
])
def test_difference_sign_rule(S, M, D):
    assert difference(S, M) == pytest.approx(D)
    assert difference([S, S], [M, M]).tolist() == pytest.approx([D, D])


# ---------------------------------------------------------------- statistics by hand
def test_statistics_by_hand():
    # Y_qst differences over 12 sections × 2 wheels: +1 on w1L, −1 on w1R except S00 w1L = +3
    def fn(s, k):
        q, p = k
        if q != "Y_qst":
            return 1.0
        if (s.id, p) == ("S00", "w1L"):
            return 13.0
        return {"w1L": 11.0, "w1R": 9.0}.get(p, 10.0)

    measured = _values(FULL, lambda s, k: 10.0 if k[0] == "Y_qst" else 1.0)
    simulated = _values(FULL, fn)
    res = validate(measured, simulated, FULL, VEH, n_boot=200)
    y = res.quantities["Y_qst"]
    d = np.array([3.0] + [1.0] * 11 + [-1.0] * 12 + [0.0] * 72)  # w1L, w1R, other wheels
    assert y.n == 96 and y.n_positions == 8 and y.n_sections == 12
    assert y.mean == pytest.approx(d.sum() / 96)
    assert y.std == pytest.approx(np.sqrt(((d - d.mean()) ** 2).sum() / 95))  # ddof = 1
    assert (y.mean_limit, y.std_limit) == (pytest.approx(10 / 3), 5.0)
    assert y.mean_norm == pytest.approx(y.mean / (10 / 3))
    assert y.std_norm == pytest.approx(y.std / 5.0)
    assert y.passed
    top = y.drilldown[0]
    assert (top["section"], top["position"], top["D"]) == ("S00", "w1L", 3.0)
    assert top["D_norm"] == pytest.approx(3.0 / 5.0)
    assert top["share_of_sum_of_squares"] == pytest.approx(9.0 / (9 + 11 + 12))
    assert res.validated


def test_failing_quantity_fails_verdict_and_drilldown_shares_sum_to_one():
    rng = np.random.default_rng(0)
    measured = _values(FULL, lambda s, k: 1.0 + rng.random())
    simulated = {s: {k: v + (0.5 if k[0] == "ay_rms" else 0.0) for k, v in vals.items()}
                 for s, vals in measured.items()}
    simulated["S03"][("ay_rms", "b2")] += 0.3
    res = validate(measured, simulated, FULL, VEH, n_boot=100, top=1000)
    ay = res.quantities["ay_rms"]
    assert ay.mean == pytest.approx((24 * 0.5 + 0.3) / 24)
    assert not ay.passed and ay.mean_norm > 1
    assert not res.validated and res.coverage.ok
    assert sum(p["share_of_sum_of_squares"] for p in ay.drilldown) == pytest.approx(1.0)
    assert ay.drilldown[0]["section"] == "S03"
    assert all(res.quantities[q].passed for q in QUANTITY_IDS if q != "ay_rms")


def test_freight_doubles_acceleration_limits():
    m = _values(FULL, lambda s, k: 1.0)
    s = _values(FULL, lambda s, k: 1.0 + (0.15 if k[0] == "az_rms" else 0.0))
    assert not validate(m, s, FULL, VEH, n_boot=0).quantities["az_rms"].passed  # 0.15 > 0.1
    res = validate(m, s, FULL, {"kind": "freight", "Q0_kN": 80.0}, n_boot=0)
    assert res.quantities["az_rms"].mean_limit == pytest.approx(0.2)
    assert res.quantities["az_rms"].passed


# ---------------------------------------------------------------- coverage
def test_coverage_sections_and_zones():
    secs = _sections([1, 1, 1, 2, 2, 2, 3, 3, 4, 4, 4])
    res = validate(_values(secs, lambda s, k: 1.0), _values(secs, lambda s, k: 1.0), secs, VEH,
                   n_boot=0)
    assert not res.validated
    sf = res.coverage.shortfalls
    assert "11 sections have comparisons, needs 12" in sf
    assert "zone 3 has 2 sections, needs 3" in sf
    assert not any(m.startswith("zone 1") for m in sf)
    assert "quantity ay_rms has 22 values, needs 24" in sf


def test_coverage_missing_zone_and_signals():
    secs = _sections([1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3])
    keys = [k for k in KEYS if not (k[0].startswith("az") and k[1] == "b2")]
    res = validate(_values(secs, lambda s, k: 1.0, keys), _values(secs, lambda s, k: 1.0, keys),
                   secs, VEH, n_boot=0)
    sf = res.coverage.shortfalls
    assert "zone 4 has 0 sections, needs 3" in sf
    assert "quantity az_rms has 1 signal, needs 2" in sf
    assert "quantity az_max has 12 values, needs 24" in sf
    assert res.coverage.to_dict()["zones"] == {"1": 4, "2": 4, "3": 4, "4": 0}
    assert not res.validated
    # every quantity itself passes (D = 0): the verdict fails on coverage alone
    assert all(q.passed for q in res.quantities.values())


def test_missing_quantity_reported_and_json_has_no_nan():
    keys = [k for k in KEYS if k[0] != "SumY_max"]
    res = validate(_values(FULL, lambda s, k: 2.0, keys), _values(FULL, lambda s, k: 2.5, keys),
                   FULL, VEH, n_boot=50)
    assert "quantity SumY_max has 0 signals, needs 2" in res.coverage.shortfalls
    doc = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    sumy = next(q for q in doc["quantities"] if q["quantity"] == "SumY_max")
    assert sumy["n"] == 0 and sumy["mean"] is None and sumy["pass"] is False


# ---------------------------------------------------------------- JSON contract, pairs
def test_to_dict_contract_and_pairs_table():
    rng = np.random.default_rng(1)
    m = _values(FULL, lambda s, k: rng.normal(5, 2))
    s = {sid: {k: v + rng.normal(0, 0.01) for k, v in vals.items()} for sid, vals in m.items()}
    res = validate(m, s, FULL, VEH, n_boot=300, seed=7)
    doc = res.to_dict()
    assert {"validated", "coverage", "quantities", "std_ddof"} <= set(doc)
    assert doc["std_ddof"] == 1 and "n − 1" in doc["std_definition"]
    assert [q["quantity"] for q in doc["quantities"]] == list(QUANTITY_IDS)
    for q in doc["quantities"]:
        assert {"quantity", "n", "mean", "std", "mean_limit", "std_limit", "mean_norm",
                "std_norm", "pass", "mean_norm_ci", "std_norm_ci", "std_ddof",
                "drilldown"} <= set(q)
        lo, hi = q["std_norm_ci"]
        assert lo <= q["std_norm"] <= hi
    json.dumps(doc, allow_nan=False)
    pairs = res.pairs
    assert list(pairs.columns) == ["quantity", "section", "zone", "position", "M", "S", "D",
                                   "D_norm"]
    assert len(pairs) == 12 * len(KEYS)
    row = pairs[(pairs.quantity == "Q_max") & (pairs.section == "S05") & (pairs.position == "w2R")]
    m_v, s_v = m["S05"][("Q_max", "w2R")], s["S05"][("Q_max", "w2R")]
    assert row.D.item() == pytest.approx(difference(s_v, m_v))
    assert row.D_norm.item() == pytest.approx(difference(s_v, m_v) / (6 * 1.8))
    assert row.zone.item() == 2
    table = res.to_pandas()
    assert table.loc["Y_qst", "n"] == 96 and "std_norm_ci_high" in table.columns


def test_bootstrap_is_seeded_and_vectorised():
    rng = np.random.default_rng(2)
    m = _values(FULL, lambda s, k: rng.normal(5, 2))
    s = {sid: {k: v + rng.normal(0.1, 0.3) for k, v in vals.items()} for sid, vals in m.items()}
    a = validate(m, s, FULL, VEH, n_boot=400, seed=3).quantities["Y_max"]
    b = validate(m, s, FULL, VEH, n_boot=400, seed=3).quantities["Y_max"]
    c = validate(m, s, FULL, VEH, n_boot=400, seed=4).quantities["Y_max"]
    assert a.mean_norm_ci == b.mean_norm_ci and a.mean_norm_ci != c.mean_norm_ci
    lo, hi = a.mean_norm_ci
    assert lo < a.mean_norm < hi
    # the CI half-width of the mean ≈ 1.96·s/√n (normal theory) within bootstrap noise
    half = (hi - lo) / 2 * a.mean_limit
    assert half == pytest.approx(1.96 * a.std / np.sqrt(a.n), rel=0.2)


def test_invalid_arguments():
    with pytest.raises(InvalidParameter, match="n_boot"):
        validate({}, {}, FULL, VEH, n_boot=-1)
    with pytest.raises(InvalidParameter, match="vehicle kind"):
        validate({}, {}, FULL, {"kind": "tram", "Q0_kN": 80})
    with pytest.raises(InvalidParameter, match="no SectionInfo"):
        validate({"X": {}}, {"X": {}}, FULL, VEH)


# ---------------------------------------------------------------- properties
@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=len(KEYS), max_size=len(KEYS)),
       st.integers(0, 2**31 - 1))
def test_identical_values_give_zero_differences(vals, seed):
    m = {s.id: dict(zip(KEYS, np.roll(vals, i))) for i, s in enumerate(FULL)}
    res = validate(m, {k: dict(v) for k, v in m.items()}, FULL, VEH, n_boot=20, seed=seed)
    assert (res.pairs.D == 0).all()
    assert all(q.mean == 0 and q.std == 0 and q.passed for q in res.quantities.values())
    assert res.validated


def test_identical_signals_through_the_chain_give_zero_differences():
    rng = np.random.default_rng(9)
    n, fs = 4000, 200.0
    t = np.arange(n) / fs
    ch = {c: (75.0 if c.startswith("Q") else 0.0) + rng.standard_normal(n) for c in ALL_CHANNELS}
    ss = SignalSet(fs, t, 20.0 * t, ch)
    values = {s.id: evaluate_section(ss, SectionInfo(s.id, 0, 0, 72, s.zone, 150.0, 250.0))
              for s in FULL}
    res = validate(values, values, FULL, VEH, n_boot=10)
    assert res.validated and (res.pairs.D == 0).all() and len(res.pairs) == 12 * len(KEYS)
