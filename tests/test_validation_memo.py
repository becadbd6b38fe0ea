"""validate with a memo kept across configurations gives the same results as without."""

import json

import numpy as np

from railval.core import validation
from railval.core.definitions import CHOSEN, READINGS
from railval.core.en14363 import SectionValues
from railval.core.quantities import QUANTITY_IDS
from railval.core.types import SectionInfo


def _values(rng, sections, gain, holes=()):
    out = {}
    for s in sections:
        vals = {(q, p): float(gain * (1 + rng.standard_normal()))
                for q in QUANTITY_IDS for p in ("ws1", "ws2")}
        for key in holes:
            if s.id == key[0]:
                vals[key[1]] = float("nan")
        alts = {r.id: {k: v * (1 + 0.01 * rng.standard_normal())
                       for k, v in list(vals.items())[:: 3 + i]}
                for i, r in enumerate(READINGS) if r != CHOSEN}
        out[s.id] = SectionValues(s.id, vals, alternatives=alts)
    return out


def test_memo_equals_fresh_validations():
    rng = np.random.default_rng(3)
    sections = [SectionInfo(f"S{i:02d}", 0, 0, 100, 1 + i % 4, 10.0, 90.0) for i in range(13)]
    measured = _values(rng, sections, 1.0)
    hole = ("S03", (QUANTITY_IDS[2], "ws1"))
    configs = [_values(rng, sections, 0.9), _values(rng, sections, 1.1, holes=[hole]),
               _values(rng, sections, 1.0), _values(rng, sections, 1.2, holes=[hole])]
    veh = {"kind": "passenger", "secondary_suspension": True, "Q0_kN": 80.0}
    memo: dict = {}
    for c in configs:
        fresh = validation.validate(measured, c, sections, veh, n_boot=50, seed=1)
        kept = validation.validate(measured, c, sections, veh, n_boot=50, seed=1, memo=memo)
        assert json.dumps(kept.to_dict(), sort_keys=True) == \
            json.dumps(fresh.to_dict(), sort_keys=True)
        assert kept.pairs.equals(fresh.pairs)
    assert memo
