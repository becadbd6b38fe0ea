"""Which verdicts are in-sample, decided in one place
(:func:`railval.app.services.validation.calibration_provenance`) and shown the same way
everywhere: a configuration made on the Diagnose page with "Add with these parameters &
re-simulate" from the values a diagnosis fitted on every section is in-sample like a
calibration on all sections — in ``railval validate --json`` (``in_sample`` and the added
``in_sample_provenance``), the dashboard's verdict box, the report and the sign-off summary —
with the note that no held-out check is possible and how to get one. Values set by hand are
not. Both database backends; a real synthetic campaign, a real stored diagnosis, real
simulations."""

from __future__ import annotations

import json

import pytest

from railval.app.cli import main
from railval.app.services.diagnosis import diagnose
from railval.app.services.synth import DEMO_HIDDEN, synth
from railval.app.state import Backend
from railval.app.views import view_of

EFFECT = "parasitic_yaw_stiffness"


@pytest.fixture(scope="module")
def diagnosed(module_db_url):
    """A 12-section synthetic coach campaign with the demo's hidden effect, its baseline
    diagnosed on that one candidate (two values per parameter: four simulations) and two
    children of the baseline made as the Diagnose page makes them: ``fitted`` with the
    values the diagnosis fitted, ``by-hand`` with another value."""
    from railval.db.engine import connect

    db = connect(module_db_url)
    db.init()
    synth(db, name="ins", hidden=DEMO_HIDDEN, seed=2026, n_sections=12)
    res = diagnose(db, "ins", "baseline", effects=[EFFECT], values_per_parameter=2, workers=1)
    cand = next(c for c in res.to_dict()["candidates"] if c["effect"] == EFFECT)
    fitted = dict(cand["parameters"])
    backend = Backend(db)
    backend.simulate("ins", "baseline", {EFFECT: fitted}, "fitted")
    backend.simulate("ins", "baseline", {EFFECT: {k: 0.5 * v for k, v in fitted.items()}}, "by-hand")
    yield db, backend, fitted
    db.dispose()


def _validate_json(db, capsys, config: str) -> dict:
    capsys.readouterr()
    assert main(["--db", db.url, "validate", "ins", "--config", config, "--boot", "20", "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_values_fitted_by_a_diagnosis_make_the_verdict_in_sample(diagnosed):
    db, backend, fitted = diagnosed
    from railval.app.services.validation import calibration_provenance
    from railval.db import repo

    with db.session() as s:
        prov = calibration_provenance(s, "ins", "fitted")
        conf = repo.get_configuration(s, "ins", "fitted")
        n_sections = len(repo.section_infos(s, repo.get_campaign(s, "ins")))
        assert conf.calibration["fitted_by"] == "diagnosis"
        assert conf.calibration["parameters"] == sorted(f"{EFFECT}.{k}" for k in fitted)
        hand = calibration_provenance(s, "ins", "by-hand")
        base = calibration_provenance(s, "ins", "baseline")
    assert prov["in_sample"] and prov["fitted_by"] == {"fitted": "diagnosis"}
    assert len(prov["fit_sections"]) == n_sections == 12 and prov["held_out_sections"] == []
    assert prov["held_out_check"].startswith("no held-out check is possible for this configuration")
    assert f"railval calibrate ins --config baseline --effect {EFFECT} --as NEW --split" in prov["held_out_check"]
    # values set by hand, and the parent, are not in-sample
    assert not hand["in_sample"] and hand["held_out_check"] == ""
    assert not base["in_sample"]


def test_validate_json_names_the_fit_on_both_backends(diagnosed, capsys):
    db, _, _ = diagnosed
    doc = _validate_json(db, capsys, "fitted")
    assert doc["in_sample"] is True  # the existing field is kept
    prov = doc["in_sample_provenance"]
    assert prov["fitted_in"] == ["fitted"] and prov["fitted_by"] == {"fitted": "diagnosis"}
    assert len(prov["fit_sections"]) == 12 and prov["held_out_sections"] == []
    assert prov["note"] == "fitted's parameters were fitted by a diagnosis on 12 of these sections"
    assert prov["held_out_check"].startswith("no held-out check is possible")
    hand = _validate_json(db, capsys, "by-hand")
    assert hand["in_sample"] is False and hand["in_sample_provenance"] is None
    # the text output says it too
    capsys.readouterr()
    assert main(["--db", db.url, "validate", "ins", "--config", "fitted", "--boot", "20"]) == 0
    out = capsys.readouterr().out
    assert "in-sample: fitted's parameters were fitted by a diagnosis" in out
    assert "no held-out check is possible" in out


def test_dashboard_report_and_signoff_summary_label_it_the_same_way(diagnosed):
    db, backend, _ = diagnosed
    from railval.app.pages.dashboard import verdict_panel
    from railval.app.report import build_report
    from railval.app.services.signoff import signing_summary

    view = view_of(backend.validation("ins", "fitted"))
    box = verdict_panel(view, "fitted").object
    assert "(in-sample: fitted&#x27;s parameters were fitted by a diagnosis on 12 of these sections)" in box
    assert "No held-out check is possible for this configuration" in box
    assert verdict_panel(view, "fitted").alert_type in ("warning", "danger")  # never the plain green
    hand = verdict_panel(view_of(backend.validation("ins", "by-hand")), "by-hand").object
    assert "in-sample" not in hand and "held-out" not in hand
    html = build_report(backend, "ins", "fitted", worst_cases=1).html
    assert "In-sample" in html and "fitted by a diagnosis on 12 of these sections" in html
    assert "No held-out check is possible" in html
    assert "In-sample" not in build_report(backend, "ins", "by-hand", worst_cases=1).html
    with db.write_session(deferred=True) as s:
        o = signing_summary(s, "ins", "fitted")["objective"]
        oh = signing_summary(s, "ins", "by-hand")["objective"]
    assert o["in_sample"] and o["in_sample_note"].startswith("fitted's parameters were fitted by a diagnosis")
    assert o["held_out_check"].startswith("no held-out check is possible")
    assert not oh["in_sample"] and oh["held_out_check"] == ""


def test_a_calibration_with_held_out_sections_names_them(diagnosed):
    """A calibrated configuration with a split (the record ``railval calibrate --split``
    stores) points to its held-out verdict instead."""
    db, _, _ = diagnosed
    from railval.app.services.validation import calibration_provenance
    from railval.db import repo

    with db.session(write=True) as s:
        camp = repo.get_campaign(s, "ins")
        sets = repo.load_signalsets(s, camp, "fitted")
        conf = repo.get_configuration(s, camp, "fitted")
        ids = sorted(sets)
        repo.store_configuration(s, camp, "split", parent="baseline", effects=dict(conf.effects),
                                 parameters=dict(conf.parameters or {}), description="split",
                                 signalsets=sets,
                                 calibration={"fit_sections": ids[:8], "held_out_sections": ids[8:],
                                              "parameters": [f"{EFFECT}.k_yaw_kNm_rad"]})
    with db.session() as s:
        prov = calibration_provenance(s, "ins", "split")
    assert prov["in_sample"] and prov["fitted_by"] == {"split": "calibration"}
    assert prov["held_out_sections"] == ids[8:]
    assert prov["held_out_check"].startswith(f"held-out check: sections {', '.join(ids[8:])}")


def test_signing_refusals_follow_the_in_sample_decision_and_read_in_the_page_words(diagnosed):
    """The sign-off rules take the same in-sample decision: accepting the in-sample
    configuration (or the NOT VALIDATED baseline) without a justification is refused, and the
    page words the server's refusal without the CLI flag; nothing is stored."""
    db, backend, _ = diagnosed
    from railval.app.pages.signoff import refusal_text
    from railval.app.services.signoff import SignoffRefused, sign
    from railval.db import signoff as db_signoff
    from railval.db import users

    with db.session(write=True) as s:
        users.create_user(s, "rev39", display_name="Rita Thirty-Nine", password="reviewer pw 39",
                          roles=["reviewer"])
    view = view_of(backend.validation("ins", "fitted"))
    for config in ("baseline", "fitted"):
        with pytest.raises(SignoffRefused) as err:
            sign(db, "rev39", "reviewer pw 39", "ins", config, decision="validated")
        raw = str(err.value)
        assert "(--justification TEXT)" in raw  # the CLI's wording
        text = refusal_text(raw)
        assert text.startswith("A decision contrary to the objective verdict needs a justification: ")
        assert "--" not in text and "Justification box" in text
        if config == "fitted" and view.validated:
            assert "in-sample" in text  # contrary because the verdict is in-sample
    assert refusal_text("sign-off refused: decision '': choose one of validated, restricted, "
                        "not-validated").startswith("Choose a decision")
    with db.session() as s:
        assert db_signoff.list_signoffs(s) == []
