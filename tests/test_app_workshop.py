"""The Diagnose & model workshop's state against the real services (no browser, no mocks).

A synthetic campaign with a hidden parasitic yaw stiffness of 1500 kN·m/rad (``railval.app.services.
synth``, truth read from the reveal file) is imported once per module into SQLite. The tests
drive :class:`railval.app.state.DiagnoseState` as the page does, with ``background=False``:

* "Add with these parameters & re-simulate": the hidden value typed in by hand → a child
  configuration with exactly those parameters, the error falling along the lineage;
* the diagnosis and calibration settings of the page reach the services: candidate subset,
  scan resolution (the announced simulation count is the one run), parameters to fit (the
  others keep the value set), optimiser budget (the evaluations stay within the announced
  bound).
"""

from __future__ import annotations

import json

import pytest

from railval.app.state import AppState, Backend, DiagnoseState

HIDDEN = "parasitic_yaw_stiffness"


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from railval.app.services.synth import synth
    from railval.db.engine import connect

    folder = tmp_path_factory.mktemp("workshop")
    database = connect(f"sqlite:///{folder / 'workshop.db'}")
    database.init()
    reveal = folder / "truth.json"
    synth(database, name="ws", template="coach", hidden=[f"{HIDDEN}=1500"], seed=3, reveal=reveal)
    yield database, json.loads(reveal.read_text())["hidden_effects"]
    database.dispose()


@pytest.fixture
def workshop(campaign):
    database, truth = campaign
    app = AppState(Backend(database))
    app.configuration = "baseline"
    return app, DiagnoseState(app), truth


def _config(app: AppState, name: str):
    return next(c for c in app.overview.configurations if c.name == name)


def test_manual_parameters_resimulate_child_and_error_falls(workshop):
    app, st, truth = workshop
    st.effect = HIDDEN
    st.new_name = "manual"
    st.parameters = dict(truth[HIDDEN])  # typed in by hand: the hidden value itself
    st.run_calibration(calibrate=False, background=False)
    assert app.status_level != "error", app.status
    assert app.configuration == "manual"  # the new configuration is selected
    conf = _config(app, "manual")
    assert conf.parent == "baseline"
    assert conf.effects[HIDDEN]["k_yaw_kNm_rad"] == pytest.approx(truth[HIDDEN]["k_yaw_kNm_rad"])
    assert st.last_result["kind"] == "re-simulation" and st.last_result["parent"] == "baseline"
    lineage = st.lineage_errors("manual")
    assert [r["configuration"] for r in lineage] == ["baseline", "manual"]
    assert not lineage[0]["validated"]
    assert lineage[1]["max_norm"] < 0.5 * lineage[0]["max_norm"]  # the error falls by half or more


def test_diagnosis_settings_subset_and_scan_resolution(workshop):
    app, st, _ = workshop
    st.refresh_choices()
    assert HIDDEN in st.param.candidate_effects.objects
    st.candidate_effects = [HIDDEN, "conicity"]
    st.values_per_parameter = 2
    announced = st.diagnosis_simulations()
    # the configuration, then 2 scan values + the default per effect; the hidden effect's value 0
    # simulates as the configuration itself (core/sim/effects.py is_neutral): its run is reused
    assert announced == 1 + 2 + 3
    st.run_diagnosis(background=False)
    assert app.status_level != "error", app.status
    assert sorted(c["effect"] for c in st.candidates) == sorted([HIDDEN, "conicity"])
    assert st.candidates[0]["effect"] == HIDDEN
    assert st.effect == HIDDEN  # the top candidate is preselected
    # where it fails: the baseline underestimates ΣY_qst in zone 4 (tight curves); the
    # candidate, fitted, takes most of it away
    where = st.where()
    (q_now, _), (q_after, _) = where["now"], where["after"]
    i, z4 = q_now.rows.index("SumY_qst"), q_now.cols.index("zone 4")
    assert q_now.values[i, z4] < -0.5
    assert abs(q_after.values[i, z4]) < 0.5 * abs(q_now.values[i, z4])
    assert st.where("conicity")["now"][0].values[i, z4] == q_now.values[i, z4]  # same "now" for all
    # what the service reports it ran is what the page announced
    assert st.diagnosis_run == {"simulations": announced, "values_per_parameter": 2,
                                "configuration": "baseline"}


def test_calibration_settings_fit_subset_keep_the_rest(workshop):
    app, st, _ = workshop
    st.effect = "lateral_bumpstop"
    assert st.param.fit_parameters.objects == ["clearance_mm", "stiffness_kN_mm"]
    st.new_name = "bumpstop-fit"
    st.parameters = {"clearance_mm": 30.0, "stiffness_kN_mm": 0.7}  # start / fixed values
    st.fit_parameters = ["clearance_mm"]
    st.popsize, st.maxiter, st.polish_maxfev, st.seed = 3, 1, 4, 7
    bound = st.calibration_simulations()
    assert bound == 5 + 1 + 30 * 2 + 1  # the local fit: scan, start, 30 trust-region steps × (1 + 1 column), stored run
    st.run_calibration(calibrate=True, background=False)
    assert app.status_level != "error", app.status
    res = st.last_result
    assert list(res["parameters"]) == ["lateral_bumpstop.clearance_mm"]  # only the chosen one fitted
    assert res["n_evaluations"] + 1 == res["simulations"] <= bound  # + the stored run
    assert res["simulations_at_most"] == bound  # the service announced what the page showed
    conf = _config(app, "bumpstop-fit")
    assert conf.effects["lateral_bumpstop"]["stiffness_kN_mm"] == pytest.approx(0.7)  # kept as set
    assert conf.effects["lateral_bumpstop"]["clearance_mm"] == pytest.approx(
        res["parameters"]["lateral_bumpstop.clearance_mm"])
    # the page's summary line reads the outcome's typed fields (app.views.CalibrationOutcome)
    from types import SimpleNamespace

    from railval.app.pages.diagnose import DiagnosePage

    text = DiagnosePage._last_result_text(SimpleNamespace(state=st), "bumpstop-fit")
    fitted = res["parameters"]["lateral_bumpstop.clearance_mm"]
    assert text.startswith(f"bumpstop-fit: lateral_bumpstop calibrated from {res['parent']}: "
                           f"clearance_mm = {fitted:.4g} mm. "), text
    assert f"fitted {res['objective']:.3g}" in text and f"{res['simulations']} campaign simulations" in text
    assert "Tolerance: stopped by" in text and text.endswith("Next: diagnose bumpstop-fit — press **Run diagnosis**.")
    assert DiagnosePage._last_result_text(SimpleNamespace(state=st), "other") == ""
