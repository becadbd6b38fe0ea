"""The interface rule (core/diagnosis/support.py, docs/diagnosis.md "Interface candidates") on
toy per-section evidence whose causes are known by construction: a candidate acting on the
wheel–rail interface whose evidence lies in the guiding forces alone is not claimed as a cause,
does not enter the cause set and the guiding family is named structural; with support outside
the guiding forces it is claimed as before. Masses join the cause set only when identified."""

from __future__ import annotations

from dataclasses import replace

import pytest

from railval.core.diagnosis import CandidateFamily, diagnose_evidence, diagnose_families
from railval.core.diagnosis.causes import cause_set
from railval.core.diagnosis.support import (
    CONTACT_ALIKE,
    apply_interface_rule,
    cause_pool,
    guiding_only,
    outside_support,
)
from tests.test_diagnosis_trust import A, B, _evidence

VALUES = [0.0, 0.5, 1.0, 1.5, 2.0]


def _case(where, interface=True):
    """Residual A on the quantities ``where``; candidate I removes it (v = 1), candidate D an
    unrelated direction B."""
    off = lambda q, z, p: A[(q, z, p)] if q in where else 0.0
    base, *_ = _evidence(off)
    ev_i = [_evidence(lambda q, z, p, v=v: (1 - v) * off(q, z, p), like=base)[0] for v in VALUES]
    ev_d = [_evidence(lambda q, z, p, v=v: off(q, z, p) - v * B[(q, z, p)], like=base)[0] for v in VALUES]
    fams = [CandidateFamily("effect", "I", "x", VALUES, ev_i, (0.0, 2.0), plausible=(0.0, 2.0), interface=interface),
            CandidateFamily("effect", "D", "x", VALUES, ev_d, (0.0, 2.0), plausible=(0.0, 2.0))]
    return base, fams


def _diagnose(base, fams):
    res = diagnose_evidence(base, fams, n_boot=60)
    out = diagnose_families(base, fams, n_boot=60)
    support = outside_support(base, fams, n_boot=60)
    apply_interface_rule(res, out, support, base, strong=0.5)
    return res, {f["name"]: f for f in out}, support


def test_interface_candidate_supported_only_by_the_guiding_forces_is_not_a_cause():
    base, fams = _case(("Y_qst",))
    # without the rule (not an interface candidate) the toy gives a confident cause
    plain = [replace(f, interface=False) for f in fams]
    assert diagnose_evidence(base, plain, n_boot=60).verdict == "cause"
    res, fam, support = _diagnose(base, fams)
    assert guiding_only(support) == {"I"}
    assert res.candidates[0].name == "I" and res.verdict == "uncertain"
    assert CONTACT_ALIKE in res.note and any(CONTACT_ALIKE in f for f in res.candidates[0].flags)
    g = fam["guiding"]
    assert g["verdict"] == "uncertain" and g["structural"]["flag"]
    assert g["structural"]["quantities"] == ["Y_qst"] and g["structural"]["zones"]
    pool, left = cause_pool(fams, res, support, set())
    assert [f.name for f in pool] == ["D"] and left[0]["name"] == "I"
    assert [c["name"] for c in cause_set(base, pool, n_boot=60)["causes"]] == []


def test_interface_candidate_with_support_outside_the_guiding_forces_stays_a_cause():
    base, fams = _case(("Y_qst", "az_rms", "ay_rms", "Q_max"))
    res, fam, support = _diagnose(base, fams)
    assert guiding_only(support) == set() and support["I"].significant_outside
    assert res.candidates[0].name == "I" and res.verdict == "cause"
    assert not fam["guiding"]["structural"]["flag"]
    pool, left = cause_pool(fams, res, support, set())
    assert left == [] and [c["name"] for c in cause_set(base, pool, n_boot=60)["causes"]] == ["I"]


def test_a_mass_that_explains_alike_or_implausibly_does_not_join_the_cause_set():
    base, fams = _case(("Y_qst", "az_rms", "ay_rms", "Q_max"), interface=False)
    # two mass candidates removing the same direction explain alike: neither is identified
    twin = replace(fams[0], name="model.m_b", kind="parameter", parameter="m_b")
    fams = [replace(fams[0], name="model.m_a", kind="parameter", parameter="m_a"), twin]
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.alike and res.verdict == "uncertain"
    pool, left = cause_pool(fams, res, {}, {"m_a", "m_b"})
    assert pool == [] and {x["name"] for x in left} == {"model.m_a", "model.m_b"}
    # not masses: a worn part may join as before
    pool, left = cause_pool(fams, res, {}, set())
    assert len(pool) == 2 and left == []
    # a mass fitted outside its plausible range is not identified either
    one = [replace(fams[0], plausible=(1.5, 2.0))]
    res = diagnose_evidence(base, one, n_boot=60)
    pool, left = cause_pool(one, res, {}, {"m_a"})
    assert pool == [] and "plausible" in left[0]["reason"]


def test_no_interface_candidate_no_support_needed():
    base, fams = _case(("Y_qst",), interface=False)
    assert outside_support(base, fams, n_boot=20) == {}
    with pytest.raises(KeyError):
        _ = outside_support(base, fams, n_boot=20)["I"]
