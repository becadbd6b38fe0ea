"""The diagnosis of a calibrated configuration read against its parent's (docs/diagnosis.md
"Lineage"): the statement logic on plain results (fast), and end to end on a synthetic coach
campaign whose only fault is the car-body mass set 15 % high in the model — diagnose, calibrate
the named cause with ``split``, diagnose the child: the child's result names the parent's
diagnosis, the remaining share, and says the remainder is within the scatter (SQLite and
PostgreSQL)."""

from __future__ import annotations

import json
import shutil

import pytest

from railval.core.diagnosis.lineage import ancestor_entry, lineage_statement, remaining_share


def _result(values, verdict="none", within=False, cands=(), floor=0.05, note=""):
    return {"residual": {"labels": [f"q{i}" for i in range(len(values))], "values": list(values),
                         "norm": sum(v * v for v in values) ** 0.5},
            "verdict": verdict, "residual_within_noise": within, "noise_floor": floor, "note": note,
            "candidates": [dict(c) for c in cands]}


PARENT = _result([3.0, 4.0], verdict="cause",
                 cands=[{"effect": "model.m_carbody", "name": "model.m_carbody", "held_out_explained": 0.9}])


def test_remaining_share_is_the_ratio_of_squared_residual_norms_on_shared_components():
    child = _result([0.0, 1.0, 7.0])  # q2 is not in the parent: not compared
    assert remaining_share(child, PARENT) == pytest.approx(1.0 / 25.0)
    no_labels = {"residual": {"norm": 1.0}}
    assert remaining_share(no_labels, {"residual": {"norm": 2.0}}) == pytest.approx(0.25)
    assert remaining_share(no_labels, {"residual": {"norm": 0.0}}) is None


def test_statement_within_scatter_when_the_calibrated_cause_was_the_only_fault():
    st = lineage_statement(_result([0.6, 0.8], within=True), PARENT, parent_configuration="baseline",
                           parent_run=7, fitted=["model.m_carbody"], fitted_values={"model.m_carbody": 32100.0})
    assert st["status"] == "within scatter" and st["parent_diagnosis"] == 7
    assert st["remaining_share"] == pytest.approx(0.04) and st["expected_remaining"] == pytest.approx(0.1)
    assert st["calibrated"] == ["model.m_carbody"] and st["fitted_parameters"] == {"model.m_carbody": 32100.0}
    assert "diagnosis #7" in st["text"] and "0.04 of the parent's" in st["text"]
    assert "within the section scatter" in st["text"]


def test_statement_names_the_next_cause_or_says_the_library_cannot_fix_the_rest():
    child = _result([1.5, 2.0], verdict="cause",
                    cands=[{"effect": "conicity", "name": "conicity", "held_out_explained": 0.8}])
    st = lineage_statement(child, PARENT, parent_configuration="b", parent_run=1, fitted=["model.m_carbody"])
    assert st["status"] == "explained" and st["candidate"] == "conicity"
    assert "explained by conicity (0.80 on held-out sections)" in st["text"]
    # a large remainder (0.25 of the parent's, the parent expected 0.10) that nothing explains
    st = lineage_statement(_result([1.5, 2.0]), PARENT, parent_configuration="b", parent_run=1,
                           fitted=["model.m_carbody"])
    assert st["status"] == "beyond library"
    assert "beyond what the library can fix" in st["text"]
    # a remainder no larger than what the parent's diagnosis left plus the noise floor: scatter
    st = lineage_statement(_result([0.9, 1.2]), PARENT, parent_configuration="b", parent_run=1,
                           fitted=["model.m_carbody"])
    assert st["status"] == "within scatter"


def test_statement_without_a_parent_diagnosis_says_so():
    st = lineage_statement(_result([1.0]), None, parent_configuration="base", parent_run=None,
                           fitted=["conicity.lambda_eq"])
    assert st["status"] is None and st["remaining_share"] is None
    assert st["calibrated"] == ["conicity"] and "has no stored diagnosis" in st["text"]


def test_ancestor_entry_gives_verdict_and_top_cause():
    assert ancestor_entry("baseline", 3, PARENT) == {
        "configuration": "baseline", "diagnosis": 3, "verdict": "cause", "top": "model.m_carbody",
        "held_out_explained": 0.9, "created_at": ""}
    assert ancestor_entry("x", None, None)["verdict"] is None


CANDS = ["model.m_carbody", "model.c_secondary_z"]


@pytest.fixture(scope="module")
def heavy(module_db_url, tmp_path_factory):
    """The synthetic coach campaign (hidden conicity, no track data), its baseline holding the
    truth's conicity and a car-body mass 15 % above the truth's 32 000 kg."""
    from railval.core.sim.synth import parse_hidden
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.test_diagnosis_campaigns import _write_plain_campaign

    plain = _write_plain_campaign(tmp_path_factory.mktemp("p") / "p", name="heavy")
    folder = tmp_path_factory.mktemp("heavy") / "heavy"
    shutil.copytree(plain, folder)
    manifest = json.loads((folder / "campaign.json").read_text())
    for c in manifest["configurations"]:
        c["effects"] = parse_hidden(["conicity"], "coach")
        c["parameters"] = {"m_carbody": 32000.0 * 1.15}
    (folder / "campaign.json").write_text(json.dumps(manifest))
    db = connect(module_db_url)
    db.init()
    import_campaign(db, folder)
    yield db
    db.dispose()


_DONE: dict[int, tuple] = {}


def _parent_and_child(db):
    """Diagnose the baseline, calibrate its named cause with ``split`` (fit on half the
    sections of each zone, judged on the other half), diagnose the child (once per database)."""
    from railval.app.services.calibration import calibrate
    from railval.app.services.diagnosis import diagnose

    if id(db) not in _DONE:
        parent = diagnose(db, "heavy", "baseline", effects=CANDS)
        calibrate(db, "heavy", "baseline", ["model.m_carbody"], "baseline+mass", split=True)
        _DONE[id(db)] = (parent, diagnose(db, "heavy", "baseline+mass", effects=CANDS))
    return _DONE[id(db)]


def test_child_diagnosis_names_parent_diagnosis_and_remaining_share(heavy, module_db_url, capsys):
    from railval.app.services.diagnosis import latest_diagnosis

    parent, child = _parent_and_child(heavy)
    assert parent.lineage is None  # a root configuration has no lineage
    assert parent.candidates[0].name == "model.m_carbody", parent.note
    lin = child.to_dict()["lineage"]
    st = lin["statement"]
    assert lin["parent"] == "baseline" and st["parent_diagnosis"] == parent.run["id"]
    assert lin["ancestors"][0]["diagnosis"] == parent.run["id"]
    assert lin["ancestors"][0]["top"] == "model.m_carbody"
    assert st["calibrated"] == ["model.m_carbody"]
    assert 0.0 <= st["remaining_share"] < 0.5, st
    assert child.verdict == "none" and st["status"] == "within scatter", (child.note, st)
    assert "remaining residual is" in st["text"] and f"diagnosis #{parent.run['id']}" in st["text"]
    # the same statement when the stored child diagnosis is read back (page, reuse)
    with heavy.session() as s:
        again = latest_diagnosis(s, "heavy", "baseline+mass")
    assert again.lineage["statement"]["remaining_share"] == pytest.approx(st["remaining_share"])
    # the CLI (the stored run reused): the text and --json carry the same statement
    from railval.app.cli import main

    capsys.readouterr()
    assert main(["--db", module_db_url, "diagnose", "heavy", "--config", "baseline+mass",
                 "--candidates", *CANDS]) == 0
    out = capsys.readouterr().out
    assert f"lineage of diagnoses: baseline #{parent.run['id']} " in out and "→ baseline+mass" in out
    assert "after calibration: after calibrating model.m_carbody" in out and "within the section scatter" in out
    assert main(["--db", module_db_url, "diagnose", "heavy", "--config", "baseline+mass", "--json",
                 "--candidates", *CANDS]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["lineage"]["statement"]["parent_diagnosis"] == parent.run["id"]
    print(f"remaining share {st['remaining_share']:.3f}, parent expected {st['expected_remaining']}, "
          f"parent top explains {parent.candidates[0].held_out_explained:.3f}", file=__import__("sys").stderr)


def test_diagnose_page_shows_the_lineage_of_diagnoses(heavy, page):
    """The Diagnose page of the calibrated child: the statement of what is left after the
    calibration and the lineage table (the parent's diagnosis with its top cause, then this one)."""
    import re

    from tests.browser_support import element_screenshot, nav, open_app, require_browser, served_app

    require_browser()
    parent, _ = _parent_and_child(heavy)
    with served_app(heavy) as url:
        open_app(page, url)
        page.locator("select", has=page.locator("option", has_text="baseline+mass")).first.select_option(
            "baseline+mass")
        nav(page, "Diagnose & model workshop")
        main = page.locator(".rv-main")
        main.get_by_text(re.compile(r"After calibration: after calibrating model\.m_carbody \(parent baseline, "
                                    rf"diagnosis #{parent.run['id']}\), the remaining residual is 0\.\d\d of "
                                    r"the parent's")).wait_for(timeout=120_000)
        main.get_by_text("Lineage of diagnoses (root first)").wait_for(timeout=120_000)
        rows = main.locator(".rv-diagnosis-lineage .tabulator-row")
        rows.first.wait_for(timeout=120_000)
        assert rows.count() == 2
        cells = [rows.nth(i).locator(".tabulator-cell[tabulator-field='configuration']").inner_text().strip()
                 for i in range(2)]
        assert cells == ["baseline", "baseline+mass"]
        assert rows.first.locator(".tabulator-cell[tabulator-field='top cause']").inner_text().strip() == \
            "model.m_carbody"
        element_screenshot(main, "diagnose-lineage")
