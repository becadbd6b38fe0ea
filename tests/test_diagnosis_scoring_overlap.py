"""The diagnosis's scoring overlapped with the pool (issue 41): with a process pool the
quantity families are judged on the workers (``FAMILY_SPLIT``) while the calling thread ranks
the candidates and their support outside the guiding forces. The result must equal the serial
scoring whole — ranking, shares, intervals, families in their registry order, cause set."""

from __future__ import annotations

import json

import pytest

from railval.app.services import diagnosis_ranking as ranking
from railval.core.diagnosis import QUANTITY_FAMILIES, diagnose_families
from railval.core.errors import InvalidParameter

KW = {"effects": ["conicity", "friction_damping"], "values_per_parameter": 2, "include_parameters": False,
      "measurement": False, "n_boot": 30, "workers": 2}


@pytest.fixture
def synth_small(sqlite_database):
    from railval.app.services.synth import synth

    synth(sqlite_database, name="demo", template="coach", hidden=["conicity"], seed=3, n_sections=12)
    return sqlite_database


def _doc(res) -> str:
    d = res.to_dict()
    d.pop("run", None)
    return json.dumps(d, sort_keys=True, default=str)


def test_overlapped_scoring_equals_the_serial_scoring(synth_small, monkeypatch):
    seen = []
    real = ranking._ranked

    def spy(ex, *a, **k):
        seen.append(ex.backend)
        return real(ex, *a, **k)
    monkeypatch.setattr(ranking, "_ranked", spy)
    overlapped = ranking.rank_causes(synth_small, "demo", "baseline", **KW)
    monkeypatch.setattr(ranking, "_ranked", lambda ex, *a, **k: real(None, *a, **k))
    serial = ranking.rank_causes(synth_small, "demo", "baseline", **KW)
    assert seen == ["process"]
    assert [f["name"] for f in overlapped.families] == [n for n in QUANTITY_FAMILIES
                                                        if n in {f["name"] for f in serial.families}]
    assert len(overlapped.families) >= 3
    assert _doc(overlapped) == _doc(serial)


def test_families_judged_apart_equal_the_families_judged_together(synth_small, monkeypatch):
    """``diagnose_families(names=…)`` of each part of the split, put in registry order, is the
    whole; a name that is no quantity family is refused by name."""
    captured = {}
    real = ranking._ranked

    def keep(ex, base, fams, validated, **k):
        captured.update(base=base, fams=fams, validated=validated)
        return real(None, base, fams, validated, **k)
    monkeypatch.setattr(ranking, "_ranked", keep)
    ranking.rank_causes(synth_small, "demo", "baseline", **{**KW, "workers": 1})
    base, fams, validated = captured["base"], captured["fams"], captured["validated"]
    kw = {"validated": validated, "n_boot": 30, "folds": 3, "seed": 0}
    whole = diagnose_families(base, fams, **kw)
    parts = [f for names in ranking.FAMILY_SPLIT for f in diagnose_families(base, fams, names=names, **kw)]
    assert [f["name"] for f in parts] != [f["name"] for f in whole]  # the split reorders them
    order = list(QUANTITY_FAMILIES)
    assert json.dumps(sorted(parts, key=lambda f: order.index(f["name"])), default=str) == \
        json.dumps(whole, default=str)
    with pytest.raises(InvalidParameter, match="unknown quantity families.*'forces'"):
        diagnose_families(base, fams, names=["forces"], **kw)


def test_every_quantity_family_is_judged_on_a_worker():
    """A family added to the registry but not to ``FAMILY_SPLIT`` goes with the last part (the
    split is checked against the registry)."""
    listed = {n for part in ranking.FAMILY_SPLIT for n in part}
    assert listed == set(QUANTITY_FAMILIES)
