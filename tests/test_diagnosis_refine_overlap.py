"""The diagnosis's refinement overlapped with the pool (issue 41): the workers take the
parameter candidates' runs first; once they are in, the calling thread picks the refinement
from the parameter candidates alone and hands its runs to the workers behind the effects'
runs. The pick must be the one a first ranking of every candidate makes, and the whole result
must equal the serial diagnosis (every run in the calling thread, in task order)."""

from __future__ import annotations

import json
import math

import pytest

from railval.app.services import diagnosis_ranking as ranking
from railval.app.services.batch import BatchExecutor
from railval.core.diagnosis import diagnose_evidence

PARAMETERS = ["model.c_secondary_z", "model.k_secondary_z", "model.m_carbody", "model.c_yaw_damper",
              "model.k_primary_y"]
KW = {"effects": ["conicity", "friction_damping"], "parameters": PARAMETERS, "values_per_parameter": 2,
      "measurement": False, "n_boot": 20, "refine": 2}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from railval.app.services.synth import synth
    from railval.db.engine import connect

    db = connect(f"sqlite:///{tmp_path_factory.mktemp('refine') / 'refine.db'}")
    db.init()
    synth(db, name="demo", template="coach", hidden=["friction_damping"], seed=5, n_sections=12)
    yield db
    db.dispose()


def _doc(res) -> str:
    d = res.to_dict()
    d.pop("run", None)
    return json.dumps(d, sort_keys=True, default=str)


def _full_ranking_pick(base, fams, validated: bool, count: int) -> list[tuple[str, float]]:
    """The refinement as a first ranking of EVERY candidate picks it (effects included): the
    best parameter candidates, in ranking order, whose fitted value is > 10 % from a simulated
    one."""
    first = diagnose_evidence(base, fams, validated=validated, n_boot=0, folds=3, seed=0)
    out = []
    for c in first.candidates:
        if c.kind != "parameter" or len(out) >= count:
            continue
        fam = next(f for f in fams if f.name == c.name)
        if min(abs(math.log(c.fitted / x)) for x in fam.values[:2]) > math.log(1.1):
            out.append((fam.parameter, c.fitted))
    return out


def test_the_pick_among_parameters_is_the_pick_among_all_candidates(campaign, monkeypatch):
    seen = {}
    real_refine = ranking._refine

    def spy(req, base, fams, redo, refined):
        seen.update(base=base, redo=list(redo), n=len(refined))
        # before the refinement is added: every family as the full first ranking saw it
        seen["pick"] = _full_ranking_pick(base, fams, False, KW["refine"])
        return real_refine(req, base, fams, redo, refined)
    monkeypatch.setattr(ranking, "_refine", spy)
    ranking.rank_causes(campaign, "demo", "baseline", workers=2, **KW)
    assert seen["redo"], "the campaign must need a refinement, or the test shows nothing"
    assert seen["redo"] == seen["pick"]
    assert seen["n"] == len(seen["redo"])


def test_overlapped_refinement_equals_the_serial_diagnosis(campaign):
    pooled = ranking.rank_causes(campaign, "demo", "baseline", workers=2, **KW)
    serial = ranking.rank_causes(campaign, "demo", "baseline", workers=1, **KW)
    assert pooled.simulations == serial.simulations
    assert _doc(pooled) == _doc(serial)


def test_parameter_runs_go_first_and_the_refinement_last(campaign, monkeypatch):
    """The workers receive the parameter candidates' runs before the effects' runs, and the
    refinement's runs in a later hand-over (behind them)."""
    handed: list[list[dict]] = []
    real = BatchExecutor.submit

    def spy(self, func, items, *, shared=None):
        items = list(items)
        if func is ranking._evaluate_sections:
            handed.append([params for _effects, params in items])
        return real(self, func, items, shared=shared)
    monkeypatch.setattr(BatchExecutor, "submit", spy)
    ranking.rank_causes(campaign, "demo", "baseline", workers=2, **KW)
    first, refinement = handed
    model = first[-1]  # an effect's run: the configuration's own template parameters
    changed = [{k for k in set(p) | set(model) if p.get(k) != model.get(k)} for p in first]
    n_par = len(PARAMETERS)
    assert all(len(c) == 1 for c in changed[:n_par])  # one perturbed template parameter each
    assert not any(changed[n_par:])  # then the effects' runs, at the model's values
    assert 1 <= len(refinement) <= KW["refine"]


def test_the_workers_records_are_pandas_records():
    """The validation table of a campaign run leaves a worker as records
    (``diagnosis_ranking._records``): the same keys, values and Python types as pandas'
    ``to_dict("records")``, NaN included."""
    import numpy as np
    import pandas as pd

    frame = pd.DataFrame({"section": ["S01", "S02", "S03"], "zone": [1, 2, 4], "quantity": ["Y", "Q", "ay"],
                          "position": ["w1L", "w2R", "cb1"], "D_norm": [0.25, np.nan, -1.5e-7],
                          "M": [1.0, 2.0, np.inf], "S": [3.0, np.nan, 0.0], "extra": [9, 9, 9]})
    cols = ("section", "zone", "quantity", "position", "D_norm", "M", "S")
    ours = ranking._records(frame, cols)
    theirs = frame[list(cols)].to_dict("records")
    assert [list(r) for r in ours] == [list(r) for r in theirs]
    assert repr(ours) == repr(theirs)
    assert [[type(v) for v in r.values()] for r in ours] == [[type(v) for v in r.values()] for r in theirs]
