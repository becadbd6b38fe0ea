"""Input-side candidates of the diagnosis (docs/diagnosis.md "Track input", "Contact geometry"):
the generated track's level per direction in the simulator, the rule that skips it where
measured geometry exists, and the statements that replace a vehicle parameter or a conicity
value as the ``cause`` (core/diagnosis/inputs.py)."""

from __future__ import annotations

import numpy as np
import pytest
from railval.core.diagnosis import CandidateFamily, diagnose_evidence
from railval.core.diagnosis.inputs import CONTACT_TEXT, TRACK_TEXT, contact_statement, scatter_level, track_statement
from railval.core.sim.effects import EFFECTS, unmet_requirement
from railval.core.sim.model import VehicleModel, simulate_section
from railval.core.sim.track import TrackSection, generate_irregularities

from tests.test_diagnosis_trust import A, B, _evidence

SEC = dict(speed_kmh=160.0, radius_m=0.0, cant_mm=0.0, straight_in_m=300.0, transition_in_m=0.0, curve_m=0.0,
           transition_out_m=0.0, straight_out_m=0.0, irregularity_level="low", seed=4)


def test_track_level_scales_the_generated_irregularities_per_direction():
    """The vertical dynamics are linear in the vertical input: the car body's vertical
    acceleration scales exactly with the vertical level factor and not with the lateral one."""
    veh, sec = VehicleModel("coach"), TrackSection("S", **SEC)
    a = simulate_section(veh, sec, {})
    v = simulate_section(veh, sec, {"track_level_vertical": {"factor": 2.0}})
    lat = simulate_section(veh, sec, {"track_level_lateral": {"factor": 2.0}})
    sd = lambda s, ch: float(np.std(s.channels[ch]))
    assert sd(v, "az_cb_b1") / sd(a, "az_cb_b1") == pytest.approx(2.0, rel=1e-3)
    assert sd(lat, "az_cb_b1") / sd(a, "az_cb_b1") == pytest.approx(1.0, abs=0.01)
    assert sd(lat, "ay_cb_b1") / sd(a, "ay_cb_b1") > 1.5


def test_track_level_does_nothing_on_measured_geometry_and_is_skipped_there():
    veh = VehicleModel("coach")
    irr = generate_irregularities(600.0, seed=9, s0=-150.0)
    sec = TrackSection("M", **{**SEC, "irregularities": irr})
    on = {"measured_irregularities": {}}
    a = simulate_section(veh, sec, on)
    b = simulate_section(veh, sec, {**on, "track_level_vertical": {"factor": 3.0}})
    np.testing.assert_array_equal(a.channels["az_cb_b1"], b.channels["az_cb_b1"])
    layouts = {"S1": {"irregularities": {"ds_m": 0.25}}, "S2": {"irregularities": {"ds_m": 0.25}}}
    why = unmet_requirement(EFFECTS["track_level_vertical"], layouts)
    assert why and "measured track geometry" in why
    assert unmet_requirement(EFFECTS["track_level_lateral"], {"S1": {}, "S2": {"irregularities": {}}}) is None
    assert unmet_requirement(EFFECTS["measured_irregularities"], {"S1": {}}) is not None


def _families(names_kinds, offs, values=(0.0, 0.5, 1.0, 1.5, 2.0), plausible=(0.0, 2.0), bounds=(0.0, 2.0)):
    """Residual Σ offs; family i at v removes v·(its direction)."""
    off = lambda q, z, p: sum(a * d[(q, z, p)] for a, d in offs)
    base, *_ = _evidence(off)
    fams = []
    for (name, kind), d in names_kinds:
        ev = [_evidence(lambda q, z, p, v=v, d=d: off(q, z, p) - v * d[(q, z, p)], like=base)[0] for v in values]
        fams.append(CandidateFamily(kind, name, "x", list(values), ev, bounds, plausible=plausible))
    return base, fams


def test_track_input_replaces_a_vehicle_parameter_as_the_cause():
    """A vehicle parameter and the track level explain the same direction alike: the verdict is
    not ``cause`` with the parameter, and the statement says to supply measured geometry."""
    base, fams = _families([(("model.c_secondary_z", "parameter"), A), (("track_level_vertical", "effect"), A)],
                           [(1.0, A)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.candidates[0].held_out_explained > 0.8
    st = track_statement(res, ["track_level_vertical", "track_level_lateral"])
    assert st is not None and st["candidates"] == ["track_level_vertical"] and st["text"].startswith(TRACK_TEXT)
    assert not (res.verdict == "cause" and res.candidates[0].kind == "parameter")
    # a vehicle parameter that the track level cannot mimic stays the cause
    base, fams = _families([(("model.c_secondary_z", "parameter"), A), (("track_level_vertical", "effect"), B)],
                           [(1.0, A)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.verdict == "cause" and track_statement(res, ["track_level_vertical"]) is None
    assert res.verdict == "cause"


def test_conicity_that_explains_only_part_is_a_contact_geometry_statement():
    """conicity removes A but the residual also holds B (no candidate): not ``cause`` conicity
    but the contact-geometry statement; conicity explaining everything gets the statement too
    (a profile difference is never answered by a single conicity as the cause, issue 40)."""
    base, fams = _families([(("conicity", "effect"), A)], [(1.0, A), (0.6, B)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.candidates[0].name == "conicity"
    st = contact_statement(res, base, scatter_level(base, 60))
    assert st is not None and st["text"].startswith(CONTACT_TEXT) and "only part" in st["text"]
    assert res.verdict != "cause"
    base, fams = _families([(("conicity", "effect"), A)], [(1.0, A)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.verdict == "cause" and res.candidates[0].held_out_explained > 0.9
    st = contact_statement(res, base, scatter_level(base, 60))
    assert st is not None and st["text"].startswith(CONTACT_TEXT) and "one amplitude only" in st["text"]
    assert res.verdict == "uncertain" and res.note.startswith("uncertain: " + CONTACT_TEXT)
    # another best candidate: no contact statement, the verdict stays
    base, fams = _families([(("model.c_secondary_z", "parameter"), A), (("conicity", "effect"), B)], [(1.0, A)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.verdict == "cause" and contact_statement(res, base, scatter_level(base, 60)) is None
    assert res.verdict == "cause"
    # at a bound of its search range: the statement too
    base, fams = _families([(("conicity", "effect"), A)], [(1.9, A)], bounds=(0.0, 1.2),
                           values=(0.0, 0.4, 0.8, 1.2))
    res = diagnose_evidence(base, fams, n_boot=60)
    st = contact_statement(res, base, scatter_level(base, 60))
    assert st is not None and "bound" in st["text"] and res.verdict != "cause"


def test_an_interface_candidate_on_top_with_a_conicity_alike_gets_the_contact_statement():
    """An interface candidate leads but is not the cause (the interface rule made the verdict
    ``uncertain``) and the conicity explains alike: the contact-geometry statement names both;
    not when the interface candidate is the cause, nor when the conicity explains something else."""
    base, fams = _families([(("track_flexibility", "effect"), A), (("conicity", "effect"), A)], [(1.0, A)])
    res = diagnose_evidence(base, fams, n_boot=60)
    top = res.candidates[0].name
    assert {c.name for c in res.candidates[:2]} == {"track_flexibility", "conicity"}
    if top == "conicity":  # equal evidence: the order is the engine's; make the interface one lead
        res.candidates[0], res.candidates[1] = res.candidates[1], res.candidates[0]
    res.verdict = "cause"  # (as if it had support outside the guiding forces)
    assert contact_statement(res, base, scatter_level(base, 60), interface={"track_flexibility"}) is None
    res.verdict, res.note = "uncertain", "uncertain: track_flexibility is supported by the guiding forces only"
    st = contact_statement(res, base, scatter_level(base, 60), interface={"track_flexibility"})
    assert st is not None and st["candidates"] == ["conicity", "track_flexibility"]
    assert st["text"].startswith(CONTACT_TEXT) and "explain alike" in st["text"] and res.verdict == "uncertain"
    assert res.note.endswith(st["text"])
    # the conicity explains another direction: no statement
    base, fams = _families([(("track_flexibility", "effect"), A), (("conicity", "effect"), B)], [(1.0, A), (0.2, B)])
    res = diagnose_evidence(base, fams, n_boot=60)
    assert res.candidates[0].name == "track_flexibility"
    res.verdict = "uncertain"
    assert contact_statement(res, base, scatter_level(base, 60), interface={"track_flexibility"}) is None
