"""Calibration that starts where the diagnosis left it (issue 41): without a start given,
``calibrate`` starts from the values the newest stored diagnosis of the parent that has the
candidate fitted and says which diagnosis; the one cost estimate shared by the CLI and the
Diagnose page; the tolerance reached in the CLI text, the JSON and the page's summary."""

from __future__ import annotations

import json

import pytest

from railval.app.services.calibration_plan import (
    calibration_simulations,
    diagnosis_start,
    start_text,
    tolerance_text,
)
from railval.core.calibration import max_evaluations
from railval.core.errors import InvalidParameter


def test_one_estimate_local_by_hand_and_global_from_its_bound():
    # local: scan 5 (4n+1 for n ≥ 2) + start 1 + 30 trust-region evaluations × (1 + n Jacobian columns) + stored run
    assert calibration_simulations(1) == 5 + 1 + 30 * 2 + 1
    assert calibration_simulations(3) == 13 + 1 + 30 * 4 + 1
    # global: start + max(5, popsize·n)·(maxiter + 1) + polish + stored run
    assert calibration_simulations(2, "global", popsize=3, maxiter=1, polish_maxfev=4) == 1 + 6 * 2 + 4 + 1
    assert calibration_simulations(2, "global", popsize=3, maxiter=1, polish_maxfev=4) == \
        max_evaluations(2, 3, 1, 4) + 1
    with pytest.raises(InvalidParameter, match="'local' or 'global'"):
        calibration_simulations(1, "newton")


def test_page_estimate_is_the_local_fit_estimate(tmp_path):
    from railval.app.state import AppState, Backend, DiagnoseState
    from tests.browser_support import demo_database

    db = demo_database(tmp_path)
    st = DiagnoseState(AppState(Backend(db)))
    st.effect = "lateral_bumpstop"
    assert st.param.fit_parameters.objects == ["clearance_mm", "stiffness_kN_mm"]
    assert st.calibration_simulations() == calibration_simulations(2)
    st.fit_parameters = ["clearance_mm"]
    st.popsize, st.maxiter = 40, 200  # the global search's settings do not change the local fit's cost
    assert st.calibration_simulations() == calibration_simulations(1) == 67
    # the page's "Global search" box: the estimate becomes differential evolution's with the
    # page's settings, and the calibration asks the service for that method
    st.global_search = True
    st.popsize, st.maxiter, st.polish_maxfev = 3, 2, 4
    assert st.calibration_simulations() == calibration_simulations(
        1, "global", popsize=3, maxiter=2, polish_maxfev=4) == 1 + 5 * 3 + 4 + 1
    # (start, a population of max(5, 3·1) initially and for 2 generations, polish, stored run)
    seen = {}
    st.app.backend.calibrate = lambda *a, **kw: seen.update(kw)
    st.run_calibration(calibrate=True, background=False)
    assert seen["method"] == "global" and seen["popsize"] == 3, seen
    st.global_search = False
    st.run_calibration(calibrate=True, background=False)
    assert seen["method"] == "local"
    db.dispose()


def _store_diagnosis(session, camp, conf, created, candidates):
    import datetime as dt

    from railval.db import runs

    row = runs.store_run(session, campaign_id=camp.id, configuration_id=conf.id, kind="diagnosis",
                         inputs_sha256=f"x{created}", settings={}, result={"candidates": candidates})
    row.created_at = dt.datetime(2026, 11, created, 12, 0, 0)
    session.flush()
    return row.id


def test_start_comes_from_the_newest_diagnosis_that_has_the_candidate(tmp_path):
    from railval.db import repo
    from tests.browser_support import demo_database

    db = demo_database(tmp_path)
    with db.session(write=True) as s:
        campaign = repo.list_campaigns(s)[0].name
        camp, conf = repo.resolve(s, campaign, "baseline")
        older = _store_diagnosis(s, camp, conf, 1, [
            {"effect": "friction_damping", "name": "friction_damping", "parameters": {"force_kN": 2.3}},
            {"effect": "model", "name": "model.c_secondary_z", "fitted": 41.5}])
        newer = _store_diagnosis(s, camp, conf, 2, [
            {"effect": "lateral_bumpstop", "name": "lateral_bumpstop",
             "parameters": {"clearance_mm": 31.0, "stiffness_kN_mm": 0.8}}])
        values, src = diagnosis_start(s, conf, ["friction_damping", "lateral_bumpstop", "model.c_secondary_z",
                                                "yaw_damper_blowoff"], {})
        assert values == {"friction_damping": {"force_kN": 2.3}, "model": {"c_secondary_z": 41.5},
                          "lateral_bumpstop": {"clearance_mm": 31.0, "stiffness_kN_mm": 0.8}}
        assert {x["candidate"]: x["diagnosis"] for x in src["diagnoses"]} == {
            "friction_damping": older, "model.c_secondary_z": older, "lateral_bumpstop": newer}
        assert src["defaults"] == ["yaw_damper_blowoff"] and src["given"] == []
        # a start the user gives wins; the diagnosis fills the others
        values, src = diagnosis_start(s, conf, ["friction_damping", "model.c_secondary_z"],
                                      {"friction_damping": {"force_kN": 1.0}})
        assert values == {"friction_damping": {"force_kN": 1.0}, "model": {"c_secondary_z": 41.5}}
        assert src["given"] == ["friction_damping"]
        text = start_text({"parent": "baseline", "start_source": {**src, "started_from": "start"}})
        assert f"model.c_secondary_z from diagnosis #{older} of baseline (2026-11-01T12:00:00)" in text
        assert "c_secondary_z = 41.5" in text and "friction_damping as given" in text
        s.rollback()
    db.dispose()


def test_tolerance_text_names_the_criterion_and_the_announced_bound():
    d = {"tolerance": {"ftol": 1e-3, "xtol": 1e-3, "gtol": 1e-6, "stopped_by": "xtol"}, "converged": True,
         "simulations": 12, "simulations_at_most": 67}
    assert tolerance_text(d) == ("tolerance: stopped by xtol (ftol 0.001, xtol 0.001, gtol 1e-06), converged; "
                                 "12 campaign simulations (at most 67 announced)")


def test_cli_calibrate_starts_from_the_stored_diagnosis(tmp_path, capsys):
    """A real diagnosis of the hidden friction stored, then calibrate without --start: the
    JSON names that diagnosis and its fitted value as the start, the objective at the start
    equals that of the same value given with --start, and the text states start and tolerance."""
    from railval.app.cli import main
    from tests.test_hidden_effect import make_campaign

    database, _truth = make_campaign(tmp_path, ["friction_damping"])
    url = database.url
    capsys.readouterr()
    assert main(["--db", url, "diagnose", "hidden", "--config", "baseline", "--candidates", "friction_damping",
                 "--no-parameters", "--values", "2", "--json"]) == 0
    diag = json.loads(capsys.readouterr().out)
    cand = next(c for c in diag["candidates"] if c["effect"] == "friction_damping")
    fitted = cand["parameters"]["force_kN"]
    argv = ["--db", url, "calibrate", "hidden", "--config", "baseline", "--effect", "friction_damping",
            "--params", "friction_damping.force_kN", "--split"]
    assert main([*argv, "--as", "auto", "--json"]) == 0
    auto = json.loads(capsys.readouterr().out)
    (src,) = auto["start_source"]["diagnoses"]
    assert src["candidate"] == "friction_damping" and src["diagnosis"] == diag["run"]["id"]
    assert src["values"]["force_kN"] == pytest.approx(fitted)
    assert auto["simulations_at_most"] == 67 and auto["simulations"] == auto["n_evaluations"] + 1 <= 67
    assert auto["tolerance"]["stopped_by"] and "converged" in auto
    assert main([*argv, "--as", "given", "--start", f"friction_damping.force_kN={fitted!r}", "--json"]) == 0
    given = json.loads(capsys.readouterr().out)
    assert given["start_source"]["given"] == ["friction_damping"]
    assert auto["objective_start"] == pytest.approx(given["objective_start"], rel=1e-9)
    assert main([*argv, "--as", "text"]) == 0
    out = capsys.readouterr().out
    assert f"start: friction_damping from diagnosis #{diag['run']['id']} of baseline" in out
    assert "tolerance: stopped by " in out and "at most 67 announced" in out
    database.dispose()
