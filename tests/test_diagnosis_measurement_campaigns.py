"""Sign, position swap and time shift candidates on imported campaigns (docs/diagnosis.md
"Sign, position swap and time shift"): each fault planted in the recorded signals of a
synthetic coach campaign (hidden conicity, no track data, the baseline holding the truth's
conicity so that only the section scatter remains) is named, with ``kind: "measurement"``;
without a planted fault, and for a model fault (the model's secondary vertical dampers 3× the
truth's), none of these candidates is claimed. SQLite and PostgreSQL."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from railval.app.services.diagnosis import diagnose
from tests.test_diagnosis_campaigns import _write_plain_campaign

DISCRETE = ("sign", "swap", "shift")
MODEL = ["model.c_secondary_z", "model.m_carbody"]


def _late(df, n):
    """Every channel of the section recorded ``n`` samples late (the first value held)."""
    out = df.copy()
    for c in df.columns:
        if c.startswith(("Y_", "Q_", "ay_", "az_")):
            x = df[c].to_numpy()
            out[c] = np.concatenate([np.full(n, x[0]), x[:-n]])
    return out


PLANTS = {
    "right": lambda df, i: df,
    "sign": lambda df, i: df.assign(Y_w1L=-df["Y_w1L"]),
    "swap": lambda df, i: df.assign(Y_w1L=df["Y_w1R"], Y_w1R=df["Y_w1L"], Q_w1L=df["Q_w1R"], Q_w1R=df["Q_w1L"]),
    "swapcb": lambda df, i: df.assign(az_cb_b1=df["az_cb_b2"], az_cb_b2=df["az_cb_b1"], ay_cb_b1=df["ay_cb_b2"],
                                      ay_cb_b2=df["ay_cb_b1"]),
    "late": lambda df, i: _late(df, 200) if i == 2 else df,  # S03, 1.0 s at 200 Hz
    "worn": lambda df, i: df,
}


@pytest.fixture(scope="module")
def planted_folders(tmp_path_factory):
    """One campaign folder per entry of :data:`PLANTS` (the baseline holds the truth's conicity;
    ``worn``: the model's secondary vertical dampers 3× the truth's)."""
    import pandas as pd

    from railval.core.sim.synth import parse_hidden

    plain = _write_plain_campaign(tmp_path_factory.mktemp("m") / "m", name="m")
    out = {}
    for name, plant in PLANTS.items():
        folder = tmp_path_factory.mktemp(name) / name
        shutil.copytree(plain, folder)
        manifest = json.loads((folder / "campaign.json").read_text())
        manifest["name"] = name
        for c in manifest["configurations"]:
            c["effects"] = parse_hidden(["conicity"], "coach")
            if name == "worn":
                c["parameters"] = {"c_secondary_z": 60000.0}  # the truth's 20 000 N·s/m: its dampers "worn"
        (folder / "campaign.json").write_text(json.dumps(manifest))
        for i, s in enumerate(manifest["sections"]):
            df = pd.read_csv(folder / s["measured"])
            plant(df, i).to_csv(folder / s["measured"], index=False)
        out[name] = folder
    return out


@pytest.fixture(scope="module")
def planted(module_db_url, planted_folders):
    from railval.db.engine import connect
    from railval.db.importer import import_campaign

    db = connect(module_db_url)
    db.init()
    for folder in planted_folders.values():
        import_campaign(db, folder)
    yield db
    db.dispose()


def _run(db, name, **kw):
    return diagnose(db, name, "baseline", effects=MODEL, measurement=True, workers=2, n_boot=30, **kw).to_dict()


def _discrete(d):
    return {c["name"]: c for c in d["candidates"] if c["parameter"] in DISCRETE}


def test_a_reversed_guiding_force_is_named_first(planted):
    d = _run(planted, "sign")
    best = d["candidates"][0]
    assert best["name"] == "sign Y_w1L" and best["kind"] == "measurement" and best["significant"]
    assert best["fitted"] == pytest.approx(-1.0) and not best["at_bound"] and best["plausible"]
    assert best["held_out_explained"] > 0.7 and d["verdict"] == "cause"
    assert [c["name"] for c in d["causes"]] == ["sign Y_w1L"] and d["causes"][0]["kind"] == "measurement"
    assert d["next"]["action"] == "check measurement" and "Y_w1L reads with reversed sign" in d["next"]["text"]
    assert "command" not in d["next"]


def test_the_two_wheels_of_a_wheelset_swapped_are_named_first(planted):
    d = _run(planted, "swap")
    best = d["candidates"][0]
    assert best["name"] == "swap w1L w1R" and best["kind"] == "measurement" and best["significant"]
    assert best["held_out_explained"] > 0.7 and d["verdict"] == "cause"
    assert "Q_w1L↔Q_w1R, Y_w1L↔Y_w1R" in best["summary"]
    assert [c["name"] for c in d["causes"]] == ["swap w1L w1R"]


def test_the_car_body_ends_swapped_join_the_causes_without_a_confident_wrong_claim(planted):
    """Both ends of the coach ride alike: the swap explains a part only (the campaign's
    section scatter lets a car body gain explain about as much), so it is no confident claim."""
    d = _run(planted, "swapcb")
    cand = _discrete(d)["swap b1 b2"]
    assert cand["significant"] and cand["held_out_explained"] > 0.1
    assert "swap b1 b2" in [c["name"] for c in d["causes"]]
    assert d["verdict"] != "cause" or d["candidates"][0]["name"] == "swap b1 b2"


def test_a_section_recorded_late_is_fitted_but_not_claimed_when_the_validation_cannot_see_it(planted):
    """S03 recorded 1.0 s late: the lag is fitted from the signals (all channels agree), but the
    EN quantities of the section's constant-curvature range hardly change, so the candidate
    explains nothing and nothing is claimed."""
    d = diagnose(planted, "late", "baseline", effects=MODEL + [f"shift S{k:02d}" for k in range(1, 13)],
                 workers=2, n_boot=30).to_dict()
    disc = _discrete(d)
    shifts = [n for n in disc if n.startswith("shift ")]
    assert shifts == ["shift S03"]  # the other sections' channels do not agree on a lag of ≥ 1 sample
    c = disc["shift S03"]
    assert c["kind"] == "measurement" and c["parameter"] == "shift"
    assert c["fitted"] == pytest.approx(1.0, abs=0.05) and c["fitted_ci"][0] < 1.0 < c["fitted_ci"][1] + 0.05
    assert c["explained"] < 0.05 and not c["significant"]
    assert not [x for x in d["causes"] if x["parameter"] in DISCRETE]
    assert {s["name"] for s in d["skipped"]} == {f"shift S{k:02d}" for k in range(1, 13)} - {"shift S03"}
    # not in the default set
    assert not [n for n in _discrete(_run(planted, "late")) if n.startswith("shift ")]
    # named for a section without a lag: left out with the reason
    d = diagnose(planted, "late", "baseline", effects=["shift S05", "shift S99"], workers=2, n_boot=30).to_dict()
    why = {s["name"]: s["reason"] for s in d["skipped"]}
    assert "lags disagree" in why["shift S05"] or "less than one sample" in why["shift S05"]
    assert "not a section of this campaign" in why["shift S99"]


@pytest.mark.parametrize("name", ["right", "worn"])
def test_no_sign_swap_or_shift_is_claimed_without_such_a_fault(planted, name):
    """Unplanted, and with a model fault (the model's dampers 3× the truth's): none of these
    candidates is significant or joins the cause set; the model fault stays the model's."""
    d = _run(planted, name)
    disc = _discrete(d)
    assert len(disc) == 21  # signs of 16 wheel forces, swaps of 4 wheelsets and of the ends
    assert not [n for n, c in disc.items() if c["significant"]]
    assert not [x for x in d["causes"] if x["parameter"] in DISCRETE]
    assert max(c["held_out_explained"] for c in disc.values()) < d["noise_floor"] + 0.05
    if name == "worn":
        assert d["candidates"][0]["name"] == "model.c_secondary_z"
    # the defaults that do not apply are left out silently (no line per section without a lag)
    assert not [s for s in d["skipped"] if s["kind"] == "measurement"]


def test_named_candidates_that_cannot_apply_are_left_out_with_their_reasons(planted, capsys):
    from railval.app.cli import main

    rc = main(["--db", planted.url, "diagnose", "sign", "--config", "baseline", "--candidates", "sign Y_w1L",
               "sign az_cb_b1", "swap az_cb_b1 ay_cb_b2", "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert [c["name"] for c in doc["candidates"]] == ["sign Y_w1L"]
    c = doc["candidates"][0]
    assert c["kind"] == "measurement" and c["fitted"] == pytest.approx(-1.0) and len(c["fitted_ci"]) == 2
    why = {s["name"]: s for s in doc["skipped"]}
    assert why["sign az_cb_b1"]["kind"] == "measurement" and "invisible" in why["sign az_cb_b1"]["reason"]
    assert "not two channels" in why["swap az_cb_b1 ay_cb_b2"]["reason"]


@pytest.mark.browser
def test_diagnose_page_shows_the_sign_swap_and_shift_candidates(tmp_path, planted_folders, page):
    """The Diagnose page shows a sign candidate like the gain candidates: ranked first with its
    verdict and cause, its fitted value and interval, and the named candidate left out."""
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.browser_support import element_screenshot, nav, open_app, require_browser, served_app

    require_browser()
    db = connect(f"sqlite:///{tmp_path / 'page.db'}")
    db.init()
    import_campaign(db, planted_folders["sign"])
    diagnose(db, "sign", "baseline", effects=["sign Y_w1L", "swap w1L w1R", "sign az_cb_b1", "gain az_cb_b1"],
             workers=2, n_boot=30)
    try:
        with served_app(db) as url:
            open_app(page, url)
            nav(page, "Diagnose & model workshop")
            main = page.locator(".rv-main")
            main.locator("h2", has_text="Diagnose & model workshop").wait_for(timeout=120_000)
            main.get_by_text("Left out (cannot apply to this campaign): sign az_cb_b1").wait_for(timeout=120_000)
            rows = main.locator(".rv-candidates .tabulator-row")
            rows.first.wait_for(timeout=120_000)
            assert rows.count() == 3
            first = rows.first.locator(".tabulator-cell[tabulator-field='candidate']").inner_text().strip()
            assert first == "sign Y_w1L"
            main.get_by_text(re.compile(r"Causes found together \(1; .*sign Y_w1L \d+ %")).wait_for(timeout=120_000)
            main.get_by_text(re.compile(r"Fitted value -1 \(interval")).wait_for(timeout=120_000)
            element_screenshot(main, "diagnose-sign-candidate")
    finally:
        db.dispose()
