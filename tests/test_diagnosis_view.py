"""The diagnosis's view model (``railval.app.views.DiagnosisView``) beside ``ValidationView``:
the CLI text and the Diagnose page's state read its typed fields, not string keys of the
result's dicts (an ``ast`` count with a planted violation); the rows carry the values of the
documented JSON fields (docs/diagnosis.md) unchanged."""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import numpy as np
import pytest

from railval.app.views import (
    Ancestor,
    CalibrationOutcome,
    Cause,
    DiagnosisView,
    FamilyRow,
    Named,
    StoredDiagnosis,
    diagnosis_view_of,
)
from railval.core.diagnosis import DiagnosisResult, Pattern, TrustedCandidate

ROOT = Path(__file__).resolve().parent.parent
#: keys of the diagnosis's JSON (docs/diagnosis.md) a reader would subscript
DIAGNOSIS_KEYS = frozenset({
    "candidates", "residual", "effect", "signature", "fitted", "causes", "cause_set",
    "families", "top", "structural", "held_out_share", "held_out_explained", "left_out",
    "passed_over", "ancestors", "statement", "skipped", "unexplained", "next", "lineage",
    "verdict", "components", "explained", "noise_floor", "statements", "flags", "summary",
    "fixes", "worsens"})
#: (file, functions or None for the whole module) that must read the view, not dicts
READERS = (("app/state/diagnose.py", None),
           ("app/cli/cmd_diagnose.py", ("_cmd_diagnose", "_print_causes", "_print_lineage")))
#: the Diagnose page reads the view's fields, the stored runs through ``StoredDiagnosis`` and
#: the last calibration through ``CalibrationOutcome``: no key read is left
PAGE = "app/pages/diagnose.py"
PAGE_CEILING = 0


def key_reads(source: str, functions: tuple[str, ...] | None = None) -> list[str]:
    """``line: expression`` of every ``x["key"]`` and ``x.get("key")`` with a diagnosis key,
    in ``functions`` of the module (every function when None)."""
    tree = ast.parse(source)
    scopes = [tree] if functions is None else [
        n for n in ast.walk(tree)
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) and n.name in functions]
    out = set()
    for scope in scopes:
        for n in ast.walk(scope):
            key = None
            if isinstance(n, ast.Subscript) and isinstance(n.slice, ast.Constant):
                key = n.slice.value
            elif (isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                  and n.func.attr == "get" and n.args and isinstance(n.args[0], ast.Constant)):
                key = n.args[0].value
            if isinstance(key, str) and key in DIAGNOSIS_KEYS:
                out.add(f"{n.lineno}: {ast.unparse(n)}")
    return sorted(out)


@pytest.mark.parametrize(("path", "functions"), READERS)
def test_state_and_cli_read_the_view_not_dict_keys(path, functions):
    found = key_reads((ROOT / path).read_text(encoding="utf-8"), functions)
    assert found == [], f"{path} reads diagnosis dicts by key:\n" + "\n".join(found)


def test_the_page_reads_no_more_keys_than_before():
    found = key_reads((ROOT / PAGE).read_text(encoding="utf-8"))
    assert len(found) <= PAGE_CEILING, "\n".join(found)


def test_the_key_count_finds_a_planted_read(tmp_path):
    planted = textwrap.dedent("""
        def _cmd_diagnose(args):
            res = diagnose(args)
            print(res.to_dict()["verdict"], res.cause_set.get("held_out_explained"))
            for f in res.families:
                print(f["structural"]["flag"])

        def other(d):
            return d["verdict"]  # not a reader of the diagnosis: not counted
        """)
    found = key_reads(planted, ("_cmd_diagnose",))
    assert found == ["4: res.cause_set.get('held_out_explained')", "4: res.to_dict()['verdict']",
                     "6: f['structural']"]


def _result() -> DiagnosisResult:
    pat = Pattern(["Y_qst zone 1 w1L", "Y_qst zone 2 w1L"], ["Y_qst", "Y_qst"], np.array([3.0, 4.0]))
    cand = TrustedCandidate("model.c_secondary_z", 0.6, {"c_secondary_z": 9000.0}, ["Y_qst"], [],
                            "softer", Pattern(pat.labels, pat.groups, np.array([1.0, 2.0])), 0.5,
                            kind="parameter", fitted=9000.0, parameter="c_secondary_z")
    return DiagnosisResult(
        residual=pat, candidates=[cand], separable=True, evidence=[], note="n", verdict="cause",
        noise_floor=0.12, unexplained=[{"component": "Y_qst zone 2 w1L", "residual": -1.5}],
        causes=[{"name": "model.c_secondary_z", "kind": "parameter", "parameter": "c_secondary_z",
                 "fitted": 9000.0, "held_out_share": 0.55}],
        cause_set={"held_out_explained": 0.55, "left_out": [{"name": "conicity", "reason": "alike"}],
                   "passed_over": []},
        families=[{"title": "lateral", "share": 0.7, "verdict": "cause",
                   "top": [{"name": "model.c_secondary_z", "held_out_explained": 0.5}],
                   "structural": {"flag": True, "reason": "every zone", "quantities": ["Y_qst"],
                                  "zones": [2, 3]}},
                  {"title": "vertical", "share": 0.3, "verdict": "none", "top": [],
                   "structural": {"flag": False, "reason": ""}}],
        skipped=[{"name": "measured_irregularities", "kind": "effect", "reason": "no track data"}],
        next_step={"text": "calibrate model.c_secondary_z"},
        statements=[{"kind": "track input", "text": "measured track"}],
        lineage={"configuration": "b+c", "statement": {"text": "left 0.2"},
                 "ancestors": [{"configuration": "b", "diagnosis": 3, "verdict": "cause",
                                "top": "conicity", "held_out_explained": 0.4}]})


def test_the_view_reads_every_part_into_typed_rows():
    view = diagnosis_view_of(_result())
    assert isinstance(view, DiagnosisView) and view.verdict == "cause" and view.noise_floor == 0.12
    assert view.causes == [Cause("model.c_secondary_z", "parameter", "c_secondary_z", 9000.0, 0.55)]
    assert view.cause_set.held_out_explained == 0.55
    assert view.cause_set.left_out == (Named("conicity", "alike"),) and view.cause_set.passed_over == ()
    assert view.families == [
        FamilyRow("lateral", 0.7, "cause", "model.c_secondary_z", 0.5, True, "every zone",
                  ("Y_qst",), (2, 3)),
        FamilyRow("vertical", 0.3, "none", None, None, False, "")]
    assert view.skipped == [Named("measured_irregularities", "no track data", "effect")]
    assert view.unexplained == [("Y_qst zone 2 w1L", -1.5)]
    assert view.statements == [("track input", "measured track")]
    assert view.next_text == "calibrate model.c_secondary_z"
    assert view.has_lineage and view.lineage_configuration == "b+c"
    assert view.ancestors == [Ancestor("b", 3, "cause", "conicity", 0.4)]
    assert view.lineage_statement == "left 0.2"
    assert view.candidate("model.c_secondary_z").fitted == 9000.0 and view.candidate("x") is None
    row = view.residual_row()
    # both components in one group, each weighted 1/√2 (docs/diagnosis.md): √((3² + 4²)/2)
    assert row["norm"] == pytest.approx(np.sqrt(12.5)) and row["values"] == [3.0, 4.0]
    [cand] = view.candidate_rows()
    assert cand["name"] == cand["effect"] == "model.c_secondary_z"  # the JSON keeps both keys
    assert cand["signature"]["values"] == [1.0, 2.0]


def test_an_empty_diagnosis_has_empty_rows_and_a_wrong_object_is_refused():
    res = DiagnosisResult(residual=Pattern(["a"], ["a"], np.zeros(1)), candidates=[],
                          separable=True, evidence=[])
    view = diagnosis_view_of(res)
    assert (view.causes, view.families, view.skipped, view.ancestors) == ([], [], [], [])
    assert view.cause_set.left_out == () and view.next_text == "" and not view.has_lineage
    with pytest.raises(TypeError, match="DiagnosisResult is needed, got dict"):
        diagnosis_view_of({"verdict": "cause"})


def test_stored_runs_and_the_last_calibration_read_into_typed_rows():
    """The Diagnose page's list of stored runs and its summary of the last calibration read
    typed rows; a missing ranking (the shown run's ``run_info``) gives the defaults."""
    listed = StoredDiagnosis.of({"id": 3, "created_at": "2026-11-28T08:00:00", "seconds": 21.6, "reused": True,
                                 "settings": {"values_per_parameter": 3, "effects": ["a", "model.m"]},
                                 "current": False, "top": "friction_damping", "explained": 0.91,
                                 "separable": False, "verdict": "uncertain"})
    assert (listed.values_per_parameter, listed.chosen, listed.current, listed.top, listed.explained,
            listed.separable, listed.verdict) == (3, ("a", "model.m"), False, "friction_damping", 0.91, False,
                                                  "uncertain")
    assert listed.candidates_text == "2 chosen candidates"
    shown = StoredDiagnosis.of({"created_at": "x", "seconds": 1.0, "settings": {"effects": None}})
    assert shown.candidates_text == "every candidate" and shown.current is None and shown.explained is None
    out = CalibrationOutcome.of({
        "kind": "calibration", "configuration": "c2", "parent": "c1", "effect": "friction_damping",
        "parameters": {"friction_damping.force_kN": 2.5}, "units": {"friction_damping.force_kN": "kN"},
        "objective": 0.07, "objective_start": 0.2, "n_evaluations": 11, "held_out_sections": ["S03"],
        "lineage": [{"held_out": {"max_error": 0.8, "parent_max_error": 1.6}}], "flags": ["note: x"],
        "tolerance": {"stopped_by": "xtol", "xtol": 1e-3}, "converged": True})
    assert out.fitted == (("friction_damping.force_kN", 2.5, "kN"),) and out.simulations == 13
    assert out.held_out_max_error == (1.6, 0.8) and out.held_out_sections == ("S03",)
    assert out.tolerance.startswith("tolerance: stopped by xtol") and out.diagnosis_parameters == ()
    resim = CalibrationOutcome.of({"kind": "re-simulation", "configuration": "c3", "parent": "c1", "effect": "e",
                                   "calibration": {"fitted_by": "diagnosis", "parameters": ["e.k"],
                                                   "fit_sections": ["S01", "S02"]}})
    assert (resim.diagnosis_parameters, resim.diagnosis_sections, resim.tolerance) == (("e.k",), 2, "")
