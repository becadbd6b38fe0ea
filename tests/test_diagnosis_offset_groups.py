"""Offset candidates per wheel-force group (docs/diagnosis.md "Model or measurement?"): a
wheelset whose two Q channels read 8 kN too high is named ``offset Q_w1`` (kind
``measurement``), fitted near 8 kN; the same 8 kN on every Q channel is not called a sensor
fault (the redundancy rule of the gains, with reference 0). Synthetic coach campaign (hidden
conicity, the baseline holding the truth's conicity: only the section scatter remains),
re-evaluated from the recorded signals; SQLite and PostgreSQL."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from railval.app.services.diagnosis import diagnose
from railval.app.services.diagnosis_measurement import not_sensor_faults
from railval.core.diagnosis import DiagnosisResult, TrustedCandidate
from railval.core.diagnosis.patterns import Pattern
from tests.test_diagnosis_campaigns import _write_plain_campaign

WHEELS = [f"Q_w{n}{s}" for n in range(1, 5) for s in "LR"]
PLANTS = {"ws": ("Q_w1L", "Q_w1R"), "every": tuple(WHEELS)}


@pytest.fixture(scope="module")
def planted(module_db_url, tmp_path_factory):
    import pandas as pd

    from railval.core.sim.synth import parse_hidden
    from railval.db.engine import connect
    from railval.db.importer import import_campaign

    plain = _write_plain_campaign(tmp_path_factory.mktemp("og") / "og", name="og")
    db = connect(module_db_url)
    db.init()
    for name, chans in PLANTS.items():
        folder = tmp_path_factory.mktemp(name) / name
        shutil.copytree(plain, folder)
        manifest = json.loads((folder / "campaign.json").read_text())
        manifest["name"] = name
        for c in manifest["configurations"]:
            c["effects"] = parse_hidden(["conicity"], "coach")
        (folder / "campaign.json").write_text(json.dumps(manifest))
        for s in manifest["sections"]:
            df = pd.read_csv(folder / s["measured"])
            for ch in chans:
                df[ch] += 8.0  # kN
            df.to_csv(folder / s["measured"], index=False)
        import_campaign(db, folder)
    yield db
    db.dispose()


def test_a_wheelset_offset_is_named_and_labelled_measurement(planted):
    cands = ["offset Q_w1", "offset Q_w3", "offset Q_w1L", "offset Q_bogie1", "offset Q_L"]
    d = diagnose(planted, "ws", "baseline", effects=cands, workers=2, n_boot=30).to_dict()
    best = d["candidates"][0]
    assert best["name"] == "offset Q_w1" and best["kind"] == "measurement" and best["significant"], d["note"]
    assert 5.0 < best["fitted"] < 10.0, best["fitted"]
    assert "the channels Q_w1L, Q_w1R read the true value + c" in best["explanation"], best["explanation"]
    assert not any(f.startswith("not a sensor fault") for f in best["flags"]), best["flags"]
    assert d["causes"] and d["causes"][0]["name"] == "offset Q_w1"
    # a name that is neither a channel nor a group: left out with the reason
    d = diagnose(planted, "ws", "baseline", effects=["offset Q_w9"], workers=2, n_boot=30).to_dict()
    assert d["skipped"] == [{"name": "offset Q_w9", "kind": "measurement", "reason": "not a channel (nor a "
                             "wheel-force group) of this campaign that a measured quantity is formed from"}]


def test_a_common_offset_on_every_channel_is_not_a_sensor_fault(planted):
    cands = [f"offset {c}" for c in WHEELS] + ["offset Q_w1"]
    d = diagnose(planted, "every", "baseline", effects=cands, workers=2, n_boot=30).to_dict()
    offsets = [c for c in d["candidates"] if c["name"].startswith("offset ")]
    assert offsets and all(any(f.startswith("not a sensor fault") for f in c["flags"]) for c in offsets), \
        [(c["name"], c["fitted"], c["flags"]) for c in offsets]
    assert not any(c["name"].startswith("offset ") for c in d["causes"] or [])
    assert d["verdict"] != "cause"
    assert any(("of the 8 Q channels want an offset above 0" in f or "every Q channel wants the same offset" in f)
               for f in offsets[0]["flags"]), offsets[0]["flags"]


def _cand(name: str, fitted: float, ci: tuple[float, float]) -> TrustedCandidate:
    return TrustedCandidate(name=name, explained=0.5, parameters={}, fixes=[], worsens=[], explanation="",
                            signature=Pattern(labels=["a"], groups=["a"], values=np.zeros(1)), residual_after=0.0,
                            kind="measurement", parameter="offset", fitted=fitted,
                            fitted_ci=ci, fitted_ci_bootstrap=ci)


def _res(cands):
    return DiagnosisResult(residual=Pattern(labels=["a"], groups=["a"], values=np.ones(1)), candidates=cands,
                           separable=True, evidence=[])


def test_offset_redundancy_rule_interval_other_bogie_and_every_channel():
    # an interval containing 0: the sensor may read right
    out = not_sensor_faults(_res([_cand("offset Q_w1", 3.0, (-0.5, 6.0))]))
    assert "contains 0" in out["offset Q_w1"]
    # one wheelset alone, away from 0: a sensor fault (nothing said)
    assert not_sensor_faults(_res([_cand("offset Q_w1", 8.0, (6.0, 10.0)),
                                   _cand("offset Q_w3", 0.2, (-1.0, 1.5))])) == {"offset Q_w3":
        "its bootstrap interval of fitted offsets -1–1.5 contains 0: the sensor may read right"}
    # the same group on the other bogie wants an offset alike
    out = not_sensor_faults(_res([_cand("offset Q_w1", 8.0, (6.0, 10.0)), _cand("offset Q_w3", 7.0, (5.0, 9.0))]))
    assert out["offset Q_w1"].startswith("Q_w3 of the other bogie wants an offset alike (7 against 8)")
    # every wheel the same offset
    out = not_sensor_faults(_res([_cand(f"offset {w}", 8.0, (6.0, 10.0)) for w in WHEELS[:4]]))
    assert set(out) == {f"offset {w}" for w in WHEELS[:4]}
    assert all("every Q channel wants the same offset" in v for v in out.values())
