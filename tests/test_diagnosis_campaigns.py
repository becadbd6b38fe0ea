"""Diagnosis on a campaign imported as a new user would, without measured track data
(docs/diagnosis.md "Candidates that cannot apply"): candidates that cannot apply are left
out with a one-line reason (``skipped`` in ``--json``, on the Diagnose page); the diagnosis,
the calibration and the page do not abort for it.

The campaign: a synthetic coach campaign (hidden conicity) written as a campaign folder whose
sections carry no ``layout["irregularities"]`` and whose baseline holds no effect — what a
measured campaign from outside looks like — then imported (SQLite and PostgreSQL)."""

from __future__ import annotations

import json
import re

import pytest

from railval.app.services.diagnosis import diagnose, latest_diagnosis
from railval.core.errors import InvalidParameter
from railval.core.sim.effects import EFFECTS, unmet_requirement

NAME = "plain"


def _write_plain_campaign(folder, hidden=("conicity",), name=NAME):
    from railval.app.services.synth import parse_hidden, write_folder
    from railval.core.sim.synth import build_campaign

    sc = build_campaign(name=name, template="coach", hidden=parse_hidden(list(hidden), "coach"), seed=1,
                        n_sections=12)
    folder = write_folder(sc, folder, ext="csv")
    manifest = json.loads((folder / "campaign.json").read_text())
    for s in manifest["sections"]:
        s["layout"].pop("irregularities")
    for c in manifest["configurations"]:
        c["effects"] = {}
    (folder / "campaign.json").write_text(json.dumps(manifest))
    return folder


@pytest.fixture(scope="module")
def plain_folder(tmp_path_factory):
    return _write_plain_campaign(tmp_path_factory.mktemp("plain") / NAME)


@pytest.fixture(scope="module")
def plain(module_db_url, plain_folder):
    from railval.db.engine import connect
    from railval.db.importer import import_campaign

    db = connect(module_db_url)
    db.init()
    import_campaign(db, plain_folder)
    yield db
    db.dispose()


def test_unmet_requirement_names_the_missing_track_data_and_unmeasured_quantities():
    mi = EFFECTS["measured_irregularities"]
    layouts = {"S01": {"irregularities": {"s": [0.0]}}, "S02": {}, "S03": None}
    assert unmet_requirement(mi, layouts) == ("needs layout['irregularities'] in every section; 2 of 3 sections "
                                              "carry none (S02, S03)")
    assert unmet_requirement(mi, {"S01": {"irregularities": {"s": [0.0]}}}) is None
    # an effect that moves only car body accelerations, on a campaign measuring wheel forces only
    fd = EFFECTS["friction_damping"]
    assert set(fd.quantities) <= {"ay_rms", "az_rms", "ay_max", "az_max"}
    why = unmet_requirement(fd, {"S01": {}}, measured_quantities=["Y_qst", "Q_max"])
    assert why and "none of which the campaign measures" in why
    assert unmet_requirement(fd, {"S01": {}}, measured_quantities=["az_rms"]) is None


def test_default_candidates_leave_out_measured_irregularities_with_a_reason(plain):
    from railval.app.services.campaign_context import load_context
    from railval.app.services.diagnosis_ranking import inapplicable_effects

    with plain.session() as s:
        ctx = load_context(s, NAME)
    out = inapplicable_effects(ctx, {}, None)
    assert [x["name"] for x in out] == ["measured_irregularities"]
    assert out[0]["kind"] == "effect" and "12 of 12 sections carry none" in out[0]["reason"]
    # asked for by name: only those are judged
    assert inapplicable_effects(ctx, {}, ["conicity"]) == []


def test_diagnosis_runs_on_what_the_campaign_holds(plain):
    res = diagnose(plain, NAME, "baseline", effects=["measured_irregularities", "conicity"], workers=2, n_boot=30)
    d = res.to_dict()
    assert [c["name"] for c in d["candidates"]] == ["conicity"]
    assert d["skipped"] == [{"name": "measured_irregularities", "kind": "effect",
                             "reason": "needs layout['irregularities'] in every section; 12 of 12 sections "
                                       "carry none (S01, S02, S03 …)"}]
    assert d["verdict"] in ("cause", "uncertain", "none")
    # the hidden conicity is what this campaign's residual holds: found without the track data,
    # said as the contact geometry (never a single conicity as the cause, docs/diagnosis.md)
    assert d["verdict"] == "uncertain" and d["candidates"][0]["held_out_explained"] > 0.5
    assert [x["kind"] for x in d["statements"]] == ["contact geometry"]
    # the cause set and the per-family results
    assert [c["name"] for c in d["causes"]] == ["conicity"] and d["causes"][0]["held_out_share"] > 0.5
    assert d["cause_set"]["held_out_explained"] == pytest.approx(d["causes"][0]["held_out_share"])
    fams = {f["name"]: f for f in d["families"]}
    assert {"guiding", "wheel", "carbody"} <= set(fams)
    for f in fams.values():
        assert f["verdict"] in ("cause", "uncertain", "none") and set(f["structural"]) == {
            "flag", "quantities", "zones", "reason"}
        assert all(c["name"] == "conicity" for c in f["top"])
    assert sum(f["share"] for f in fams.values()) == pytest.approx(1.0)
    # stored with the run and read back
    with plain.session() as s:
        assert latest_diagnosis(s, NAME, "baseline").to_dict()["skipped"] == d["skipped"]


def test_nothing_applicable_gives_verdict_none_with_the_reasons(plain, capsys):
    from railval.app.cli import main

    rc = main(["--db", plain.url, "diagnose", NAME,
               "--config", "baseline", "--candidates", "measured_irregularities", "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "none" and doc["candidates"] == []
    assert doc["skipped"][0]["name"] == "measured_irregularities"
    assert "left out: measured_irregularities (needs layout['irregularities']" in doc["note"]
    main(["--db", plain.url, "diagnose", NAME, "--config", "baseline", "--candidates",
          "measured_irregularities"])
    out = capsys.readouterr().out
    assert "verdict NONE" in out
    assert "left out: measured_irregularities (effect) — needs layout['irregularities'] in every section" in out


def test_calibrating_an_effect_that_cannot_apply_is_refused_before_anything_is_stored(plain):
    from railval.app.services.calibration import calibrate
    from railval.db import repo

    with pytest.raises(InvalidParameter) as exc:
        calibrate(plain, NAME, "baseline", ["measured_irregularities"], "baseline+mi")
    msg = str(exc.value)
    assert "'measured_irregularities' cannot apply to campaign 'plain'" in msg
    assert "needs layout['irregularities'] in every section" in msg
    with plain.session() as s:
        assert "baseline+mi" not in [c.name for c in repo.list_configurations(s, NAME)]


@pytest.mark.browser
def test_diagnose_page_shows_the_candidates_left_out(tmp_path, plain_folder, page):
    """The Diagnose page of the campaign without track data shows the stored diagnosis: the
    verdict, the ranking of what applies, and the candidate left out with its reason."""
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.browser_support import element_screenshot, nav, open_app, require_browser, served_app

    require_browser()
    db = connect(f"sqlite:///{tmp_path / 'page.db'}")
    db.init()
    import_campaign(db, plain_folder)
    diagnose(db, NAME, "baseline", effects=["measured_irregularities", "conicity"], workers=2, n_boot=30)
    try:
        with served_app(db) as url:
            open_app(page, url)
            nav(page, "Diagnose & model workshop")
            main = page.locator(".rv-main")
            main.locator("h2", has_text="Diagnose & model workshop").wait_for(timeout=120_000)
            left_out = main.get_by_text("Left out (cannot apply to this campaign): measured_irregularities — "
                                        "needs layout['irregularities'] in every section")
            left_out.wait_for(timeout=120_000)
            rows = main.locator(".rv-candidates .tabulator-row")
            rows.first.wait_for(timeout=120_000)
            assert rows.count() == 1
            assert rows.first.locator(".tabulator-cell[tabulator-field='candidate']").inner_text().strip() == "conicity"
            main.get_by_text("Per quantity family").wait_for(timeout=120_000)
            assert main.locator(".rv-families .tabulator-row").count() == 4
            main.get_by_text(re.compile(r"Causes found together \(1; .*conicity \d+ %")).wait_for(timeout=120_000)
            element_screenshot(main, "diagnose-left-out")
    finally:
        db.dispose()


MI_REASON = ("switched on in configuration 'baseline' but cannot apply: needs layout['irregularities'] in every "
             "section; 12 of 12 sections carry none (S01, S02, S03 …); simulated without it")


@pytest.fixture(scope="module")
def mi_folder(plain_folder, tmp_path_factory):
    """A campaign like ``plain`` whose baseline configuration itself has
    measured_irregularities switched on — its sections carry no irregularities."""
    import shutil

    folder = tmp_path_factory.mktemp("mi") / "mi"
    shutil.copytree(plain_folder, folder)
    manifest = json.loads((folder / "campaign.json").read_text())
    manifest["name"] = "mi"
    for c in manifest["configurations"]:
        c["effects"] = {"measured_irregularities": {"scale": 1.0}}
    (folder / "campaign.json").write_text(json.dumps(manifest))
    return folder


@pytest.fixture(scope="module")
def mi(plain, mi_folder):
    from railval.db.importer import import_campaign

    import_campaign(plain, mi_folder)
    return plain


def test_a_configuration_effect_that_cannot_apply_is_left_out_of_the_simulation_with_its_reason(mi):
    res = diagnose(mi, "mi", "baseline", effects=["conicity"], include_parameters=False, measurement=False,
                   workers=2, n_boot=30)
    d = res.to_dict()
    assert d["skipped"] == [{"name": "measured_irregularities", "kind": "configuration", "reason": MI_REASON}]
    assert d["effects_in_configuration"] == ["measured_irregularities"] and d["effects_simulated"] == []
    assert "effect measured_irregularities " + MI_REASON in d["note"]
    # what can run runs: the hidden conicity is found as on the campaign without the effect
    assert [c["name"] for c in d["candidates"]] == ["conicity"]
    assert d["verdict"] == "uncertain" and d["candidates"][0]["held_out_explained"] > 0.5
    assert [x["kind"] for x in d["statements"]] == ["contact geometry"]


def test_nothing_to_run_beside_a_configuration_effect_gives_verdict_none_not_a_traceback(mi, capsys):
    from railval.app.cli import main

    rc = main(["--db", mi.url, "diagnose", "mi", "--config", "baseline", "--candidates",
               "measured_irregularities", "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "none" and doc["candidates"] == []
    assert [(x["name"], x["kind"]) for x in doc["skipped"]] == [("measured_irregularities", "configuration")]
    assert doc["skipped"][0]["reason"] == MI_REASON and MI_REASON in doc["note"]
    main(["--db", mi.url, "diagnose", "mi", "--config", "baseline", "--candidates", "measured_irregularities"])
    out = capsys.readouterr().out
    assert "verdict NONE" in out and "Traceback" not in out
    assert "left out: measured_irregularities (configuration) — " + MI_REASON in out


def test_calibration_runs_without_the_configuration_effect_and_says_so(mi):
    from railval.app.services.calibration import calibrate
    from railval.db import repo

    res = calibrate(mi, "mi", "baseline", ["conicity", "measured_irregularities"], "baseline+conicity",
                    popsize=2, maxiter=1, polish_maxfev=2, workers=2)
    d = res.to_dict()
    assert [(x["name"], x["kind"]) for x in d["skipped"]] == [("measured_irregularities", "configuration"),
                                                             ("measured_irregularities", "effect")]
    assert f"configuration effect measured_irregularities left out: {MI_REASON}" in d["flags"]
    assert set(d["effects"]) == {"conicity"}
    with mi.session() as s:
        child = repo.get_configuration(s, "mi", "baseline+conicity")
        assert set(child.effects) == {"conicity"}
        assert "without measured_irregularities (cannot apply to this campaign)" in child.description


@pytest.mark.browser
def test_diagnose_page_runs_a_configuration_whose_effect_cannot_apply(tmp_path, mi_folder, page):
    """The Diagnose page of the configuration with measured_irregularities switched on and no
    track data (its diagnosis stored by the service the page's Run diagnosis calls): the
    verdict, the ranking, and the effect the configuration was simulated without, with its
    reason — apart from the candidates left out."""
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.browser_support import element_screenshot, nav, open_app, require_browser, served_app

    require_browser()
    db = connect(f"sqlite:///{tmp_path / 'page.db'}")
    db.init()
    import_campaign(db, mi_folder)
    diagnose(db, "mi", "baseline", effects=["conicity"], include_parameters=False, measurement=False,
             workers=2, n_boot=30)
    try:
        with served_app(db) as url:
            open_app(page, url)
            nav(page, "Diagnose & model workshop")
            main = page.locator(".rv-main")
            main.locator("h2", has_text="Diagnose & model workshop").wait_for(timeout=120_000)
            main.get_by_text("Configuration simulated without (cannot apply to this campaign): "
                             "measured_irregularities — " + MI_REASON).wait_for(timeout=120_000)
            rows = main.locator(".rv-candidates .tabulator-row")
            rows.first.wait_for(timeout=120_000)
            assert rows.first.locator(".tabulator-cell[tabulator-field='candidate']").inner_text().strip() == "conicity"
            assert main.get_by_text("Left out (cannot apply").count() == 0
            element_screenshot(main, "diagnose-configuration-effect-left-out")
    finally:
        db.dispose()


def test_gain_candidate_pairs_and_channels():
    from railval.core.diagnosis.measurement import gain_channels, gain_pairs

    pairs = [{"section": "S1", "zone": 1, "quantity": "az_rms", "position": "b1", "M": 0.4, "S": 0.5, "D_norm": 0.0},
             {"section": "S1", "zone": 1, "quantity": "az_rms", "position": "b2", "M": 0.4, "S": 0.5, "D_norm": 0.0},
             {"section": "S1", "zone": 1, "quantity": "Y_qst", "position": "w1L", "M": -10.0, "S": -12.0,
              "D_norm": 0.4},
             {"section": "S1", "zone": 1, "quantity": "YQ_max", "position": "w1L", "M": 0.3, "S": 0.3, "D_norm": 0.0}]
    chans = gain_channels(pairs)
    # az_cb_b1 forms az_rms at b1 alone; Y_w1L also enters Y/Q, so it is no gain candidate
    assert chans == {"az_cb_b1": [("az_rms", "b1")], "az_cb_b2": [("az_rms", "b2")]}
    out = gain_pairs(pairs, chans["az_cb_b1"], 2.0, {"az_rms": 0.1, "Y_qst": 5.0})
    # the channel reads 2× the truth: M' = 0.2, D' = (0.5 − 0.2)·sign(0.2) = 0.3, /0.1
    assert out[0]["M"] == pytest.approx(0.2) and out[0]["D_norm"] == pytest.approx(3.0)
    assert out[1] == pairs[1] and out[2] == pairs[2]


@pytest.fixture(scope="module")
def gain_folder(plain_folder, tmp_path_factory):
    """The campaign without track data whose car body accelerometer az_cb_b1 reads 1.3× too high."""
    import shutil

    import pandas as pd

    folder = tmp_path_factory.mktemp("gain") / "gain"
    shutil.copytree(plain_folder, folder)
    manifest = json.loads((folder / "campaign.json").read_text())
    manifest["name"] = "gain"
    (folder / "campaign.json").write_text(json.dumps(manifest))
    for s in manifest["sections"]:
        path = folder / s["measured"]
        df = pd.read_csv(path)
        df["az_cb_b1"] *= 1.3
        df.to_csv(path, index=False)
    return folder


def test_a_miscalibrated_accelerometer_is_named_beside_the_model_cause(plain, gain_folder):
    from railval.db.importer import import_campaign

    db = plain  # the same database, a second campaign
    import_campaign(db, gain_folder)
    res = diagnose(db, "gain", "baseline", effects=["conicity", "gain az_cb_b1", "gain az_cb_b2", "gain ay_cb_b1"],
                   workers=2, n_boot=30)
    d = res.to_dict()
    kinds = {c["name"]: c["kind"] for c in d["candidates"]}
    assert kinds == {"conicity": "effect", "gain az_cb_b1": "measurement", "gain az_cb_b2": "measurement",
                     "gain ay_cb_b1": "measurement"}
    causes = {c["name"]: c for c in d["causes"]}
    assert set(causes) == {"conicity", "gain az_cb_b1"}
    # the fitted gain also absorbs the model's error common to both car body ends (the synthetic
    # truth's az differs from the baseline's at both ends); the redundant channel at the other
    # end separates the sensor: b1 reads ≈ 1.3 × what b2 implies
    gain = causes["gain az_cb_b1"]
    assert gain["kind"] == "measurement" and gain["held_out_share"] > 0.05
    assert gain["relative_gain"] == pytest.approx(1.3, rel=0.08)
    assert "az_cb_b1 reads ≈" in d["next"]["text"] and "--effect gain" not in d["next"].get("command", "")
    cand = next(c for c in d["candidates"] if c["name"] == "gain az_cb_b1")
    assert "channel az_cb_b1 reads" in cand["summary"] and "(the redundant channel) implies" in cand["summary"]


def test_next_step_calibrates_a_cause_set_together_and_the_cli_accepts_it():
    import argparse

    from railval.app.cli.cmd_diagnose import register
    from railval.app.services.diagnosis_ranking import next_step
    from railval.core.diagnosis import DiagnosisResult, Pattern, TrustedCandidate

    pat = Pattern(["Y_qst zone 1 w1L"], ["Y_qst"], [1.0])
    mk = lambda name, kind, params, fitted, parameter: TrustedCandidate(
        name, 0.5, params, [], [], "", pat, 0.5, kind=kind, fitted=fitted, parameter=parameter)
    cands = [mk("conicity", "effect", {"conicity": 0.45}, 0.45, "conicity"),
             mk("model.c_secondary_z", "parameter", {"c_secondary_z": 9000.0}, 9000.0, "c_secondary_z"),
             mk("gain az_cb_b1", "measurement", {"gain": 1.3}, 1.3, "gain")]
    res = DiagnosisResult(pat, cands, True, [], "", verdict="cause", causes=[
        {"name": c.name, "kind": c.kind, "parameter": c.parameter, "fitted": c.fitted, "held_out_share": 0.3}
        for c in cands])
    nxt = next_step(res, "camp", "baseline")
    assert nxt["candidates"] == ["conicity", "model.c_secondary_z"]
    assert "first check the measurement: az_cb_b1 reads ≈ 1.3 × the true value" in nxt["text"]
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(nxt["command"].split()[1:])
    assert args.effect == ["conicity", "model.c_secondary_z"] and args.new_name == "baseline+conicity+c_secondary_z"
    assert args.start == ["conicity.conicity=0.45", "model.c_secondary_z=9000"]


# ----------------------------------------------------------------------------- offsets
OFFSET_CANDIDATES = ["offset Q_w1L", "offset Q_w1R", "offset Y_w1L", "offset az_cb_b1"]


@pytest.fixture(scope="module")
def offset_folders(plain_folder, tmp_path_factory):
    """Two campaigns whose baseline holds the truth's hidden conicity (the model is right but
    for the section scatter): ``right`` as measured, and ``offset`` whose wheel force channel
    Q_w1L reads 8 kN too high and whose car body accelerometer az_cb_b1 reads 0.3 m/s² too
    high."""
    import shutil

    import pandas as pd

    from railval.core.sim.synth import parse_hidden

    out = {}
    for name, planted in (("right", {}), ("offset", {"Q_w1L": 8.0, "az_cb_b1": 0.3})):
        folder = tmp_path_factory.mktemp(name) / name
        shutil.copytree(plain_folder, folder)
        manifest = json.loads((folder / "campaign.json").read_text())
        manifest["name"] = name
        for c in manifest["configurations"]:
            c["effects"] = parse_hidden(["conicity"], "coach")
        (folder / "campaign.json").write_text(json.dumps(manifest))
        for s in manifest["sections"]:
            df = pd.read_csv(folder / s["measured"])
            for ch, c in planted.items():
                df[ch] += c
            df.to_csv(folder / s["measured"], index=False)
        out[name] = folder
    return out


@pytest.fixture(scope="module")
def offsets(plain, offset_folders):
    from railval.db.importer import import_campaign

    for folder in offset_folders.values():
        import_campaign(plain, folder)
    return plain


def test_offset_measured_shifts_the_quasi_static_force_by_the_offset(offsets):
    from railval.app.services.campaign_context import load_context
    from railval.core.diagnosis.measurement import offset_blind, offset_components, offset_measured
    from railval.db import repo

    with offsets.session() as s:
        ctx = load_context(s, "offset")
        sets = repo.load_signalsets(s, "offset", None)
    pairs = [{"quantity": q, "position": p} for v in ctx.measured_values.values() for q, p in v]
    comps = offset_components(pairs, "Q_w1L")
    assert ("Q_qst", "w1L") in comps and ("Y_qst", "w1L") not in comps
    fixed = offset_measured(sets, ctx.sections, "Q_w1L", 8.0, comps)
    # the low-pass keeps a constant and the median of the sliding mean shifts with it
    for sid, v in ctx.measured_values.items():
        assert fixed[(sid, "Q_qst", "w1L")] == pytest.approx(v[("Q_qst", "w1L")] - 8.0, abs=1e-6)
    # at offset 0 (only the channels the components use re-evaluated) the stored evaluation
    zero = offset_measured(sets, ctx.sections, "Q_w1L", 0.0, comps)
    assert len(zero) == len(comps) * len(ctx.measured_values)
    for (sid, q, p), m in zero.items():
        assert m == pytest.approx(ctx.measured_values[sid][(q, p)], rel=1e-12, abs=1e-12)
    assert offset_blind("Q_w1L") is None and "band-pass 0.4–10 Hz" in offset_blind("az_cb_b1")


def test_a_car_body_accelerometer_offset_changes_nothing_and_is_left_out(offsets):
    """The planted 0.3 m/s² on az_cb_b1 leaves every measured value formed from it as it was
    (the EN band-pass removes a constant): the offset candidate of that channel is left out
    with that reason and nothing is claimed about it."""
    from railval.app.services.campaign_context import load_context

    with offsets.session() as s:
        right, off = load_context(s, "right"), load_context(s, "offset")
    for sid, v in right.measured_values.items():
        for key in [k for k in v if k[1] == "b1" and k[0] in ("az_rms", "az_max")]:
            assert off.measured_values[sid][key] == pytest.approx(v[key], rel=1e-9, abs=1e-12)
    d = diagnose(offsets, "offset", "baseline", effects=["offset az_cb_b1"], workers=2, n_boot=30).to_dict()
    assert d["candidates"] == [] and d["verdict"] == "none"
    assert d["skipped"] == [{"name": "offset az_cb_b1", "kind": "measurement",
                             "reason": "a constant offset is removed by the EN band-pass 0.4–10 Hz of every quantity "
                                       "formed from this channel and by the mean removal of its band powers: it "
                                       "changes nothing the validation sees"}]


def test_a_planted_wheel_force_offset_is_named_and_nothing_is_claimed_without_it(offsets):
    d = diagnose(offsets, "offset", "baseline", effects=OFFSET_CANDIDATES, workers=2, n_boot=30).to_dict()
    best = d["candidates"][0]
    assert best["name"] == "offset Q_w1L" and best["kind"] == "measurement" and best["significant"]
    assert 5.0 < best["fitted"] < 10.0 and best["fitted_ci"][0] <= 8.0 <= best["fitted_ci"][1]
    assert "channel Q_w1L reads the true value +" in best["summary"]
    assert [c["name"] for c in d["causes"]] == ["offset Q_w1L"] and d["causes"][0]["kind"] == "measurement"
    assert all(not c["significant"] for c in d["candidates"][1:])
    assert "Q_w1L reads ≈ the true value +" in d["next"]["text"]
    # the same campaign as measured: nothing claimed
    d = diagnose(offsets, "right", "baseline", effects=OFFSET_CANDIDATES, workers=2, n_boot=30).to_dict()
    assert d["verdict"] == "none" and d["causes"] == []
    assert not any(c["significant"] for c in d["candidates"])


def test_a_wheel_force_gain_named_beside_its_offset(offsets, offset_folders, tmp_path_factory):
    """A wheel force channel enters Y/Q and ΣY with a second one; named, its gain is judged on
    the measurement re-evaluated from the signals. Planted Y_w1L × 1.25: the gain is fitted
    near 1.25 and not outranked by an offset of the same channel."""
    import shutil

    import pandas as pd

    from railval.db.importer import import_campaign

    folder = tmp_path_factory.mktemp("ygain") / "ygain"
    shutil.copytree(offset_folders["right"], folder)
    manifest = json.loads((folder / "campaign.json").read_text())
    manifest["name"] = "ygain"
    (folder / "campaign.json").write_text(json.dumps(manifest))
    for s in manifest["sections"]:
        df = pd.read_csv(folder / s["measured"])
        df["Y_w1L"] *= 1.25
        df.to_csv(folder / s["measured"], index=False)
    import_campaign(offsets, folder)
    d = diagnose(offsets, "ygain", "baseline", effects=["gain Y_w1L", "offset Y_w1L", "gain Q_w1L"], workers=2,
                 n_boot=30).to_dict()
    by = {c["name"]: c for c in d["candidates"]}
    assert set(by) == {"gain Y_w1L", "offset Y_w1L", "gain Q_w1L"} and d["skipped"] == []
    assert d["candidates"][0]["name"] == "gain Y_w1L"
    assert by["gain Y_w1L"]["fitted"] == pytest.approx(1.25, rel=0.1)
    assert by["gain Y_w1L"]["held_out_explained"] > by["offset Y_w1L"]["held_out_explained"]
    # no confident claim of the wrong fault: the offset is neither a cause nor in the cause set
    assert "offset Y_w1L" not in [c["name"] for c in d["causes"]]
    assert not (d["verdict"] == "cause" and d["candidates"][0]["name"] != "gain Y_w1L")
