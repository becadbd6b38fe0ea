"""The per-section evidence built without a per-record label lookup and its pattern values
remembered per weights (docs/diagnosis.md "Diagnosis speed"): results equal to the plain
computation bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from railval.core.diagnosis.evidence import section_evidence, zone_bootstrap, zone_folds


def _pairs(rng, n=400):
    quantities, positions = ("Y_qst", "az_rms", "SumY_max"), ("w1L", "b1", "ws2")
    return [{"section": f"S{int(rng.integers(0, 6))}", "quantity": quantities[int(rng.integers(0, 3))],
             "zone": int(rng.integers(1, 3)), "position": positions[int(rng.integers(0, 3))],
             "norm": float(rng.normal(0, 1.0) * 10.0 ** int(rng.integers(-3, 4)))} for _ in range(n)]


def test_sums_equal_the_plain_loop_in_record_order():
    """Independent expectation: the sums and counts accumulated record by record with ``+=``
    (the same order, so equal bit for bit, not only to rounding); a record of a section not
    in the campaign or with a NaN value is left out."""
    rng = np.random.default_rng(5)
    pairs = _pairs(rng) + [{"section": "S9", "quantity": "Y_qst", "zone": 1, "position": "w1L", "norm": 1.0},
                           {"section": "S1", "quantity": "Y_qst", "zone": 1, "position": "w1L", "norm": float("nan")}]
    sections = [(f"S{k}", 1 + k % 2) for k in range(6)]
    ev = section_evidence(pairs, {}, {}, sections)
    want_s, want_c = np.zeros_like(ev.sums), np.zeros_like(ev.counts)
    col = {lab: j for j, lab in enumerate(ev.labels[:ev.n_pair])}
    for r in pairs:
        if r["section"] in dict(sections) and np.isfinite(r["norm"]):
            i = int(r["section"][1:])
            j = col[f"{r['quantity']} zone {r['zone']} {r['position']}"]
            want_s[i, j] += r["norm"]
            want_c[i, j] += 1
    assert np.array_equal(ev.sums, want_s) and np.array_equal(ev.counts, want_c)
    assert ev.counts.sum() == len(pairs) - 2


def test_remembered_values_equal_fresh_ones_and_cannot_be_changed():
    rng = np.random.default_rng(6)
    sections = [(f"S{k}", 1 + k % 2) for k in range(6)]
    ev = section_evidence(_pairs(rng), {}, {}, sections)
    for w in [None, *zone_folds(ev.zones, 3), zone_bootstrap(ev.zones, 50, seed=2)]:
        first, again = ev.values(w), ev.values(None if w is None else np.array(w))
        fresh = ev._values(np.ones(6) if w is None else np.asarray(w, float))
        assert np.array_equal(first, again) and np.array_equal(first, fresh)
        with pytest.raises(ValueError):
            first[...] = 0.0
    scaled = replace(ev, sums=ev.sums * 2.0)  # a new evidence: its own values, not the remembered ones
    assert np.allclose(scaled.values(), 2.0 * ev.values())
