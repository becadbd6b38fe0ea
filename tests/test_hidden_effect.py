"""THE end-to-end test of docs/design.md §7: a synthetic campaign with a hidden effect (sensor noise,
gain errors, time offsets and speed scatter on) → the baseline fails validation → diagnosis
ranks the hidden effect first among all candidates (effects and template parameters
``model.*``) → calibrating it passes every quantity (or halves the largest normalised error)
and recovers the hidden value within 20 % (read from ``--reveal``).

CI runs the fast variant (one effect, diagnosis among four candidate effects). The full sweep —
every effect of the library on the coach, every wagon-applicable effect on the wagon, two effects
hidden at once, and a baseline with mis-set parameters — is marked slow::

    pytest -m slow tests/test_hidden_effect.py

Each story runs at the explicit value of :data:`STORY_VALUES`: the plausible hidden default
where it fails the baseline; where no plausible value does (the simulator's corrections of
this round: exact Maxwell update, realistic true track per speed band, …) a measured failing
value labelled "outside the plausible range — an identifiability check only". Where no value
inside the search bounds fails (:data:`BASELINE_PASSES`) the slow test asserts that the
baseline passes, the documented claim. Measured results: docs/diagnosis.md; the scan of
values: docs/simulator.md "Synthetic campaigns".
"""

from __future__ import annotations

import json

import pytest

from railval.app.services.calibration import calibrate
from railval.app.services.diagnosis import diagnose
from railval.app.services.synth import synth
from railval.app.services.validation import validate_configuration
from railval.core.sim.effects import EFFECTS
from railval.core.sim.synth import MAIN_PARAMETER
from railval.db.engine import connect

COACH_EFFECTS = [e for e in EFFECTS if "coach" in EFFECTS[e].templates]
WAGON_EFFECTS = [e for e in EFFECTS if "wagon" in EFFECTS[e].templates]


def make_campaign(tmp_path, hidden: list[str], *, template: str = "coach", seed: int = 1):
    """Synthesise and import a campaign; return (database, truth from the reveal file)."""
    database = connect(f"sqlite:///{tmp_path / 'hidden.db'}")
    database.init()
    reveal = tmp_path / "truth.json"
    synth(database, name="hidden", template=template, hidden=hidden, seed=seed, reveal=reveal)
    truth = json.loads(reveal.read_text())
    # nothing in the campaign names the truth
    with database.session() as s:
        from railval.db import repo

        conf = repo.get_configuration(s, "hidden", "baseline")
        assert not set(truth["hidden_effects"]) & set(conf.effects or {})
    return database, truth


def _max_error(validation) -> float:
    return max(max(abs(q.mean_norm), q.std_norm) for q in validation.quantities.values())


def _worst(validation) -> str:
    """The quantity with the largest max(|mean_norm|, std_norm)."""
    return max(validation.quantities, key=lambda k: max(abs(validation.quantities[k].mean_norm),
                                                         validation.quantities[k].std_norm))


def _cli(database, capsys, *argv: str) -> dict:
    from railval.app.cli import main

    capsys.readouterr()
    assert main(["--db", database.url, *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _story_row(row: dict) -> None:
    """Print the figures gathered so far (``-s``): a failing story still reports them."""
    print(json.dumps(row), flush=True)


def check_hidden_effect(tmp_path, effect: str, *, template: str = "coach", candidates=None,
                        seed: int = 1, capsys=None, item: str | None = None,
                        workers: int | None = None) -> dict:
    """Run the whole story for one hidden effect; with ``capsys`` through the CLI verbs.

    ``item``: the ``--hidden`` item (default ``effect`` = its hidden default); ``workers``:
    process count of diagnose and calibrate (the slow sweep uses 1 on the shared machine).
    The diagnosis ranks template parameters (``model.*``) beside the effects; the hidden
    effect must be the first candidate of all."""
    database, truth = make_campaign(tmp_path, [item or effect], template=template, seed=seed)
    with database.write_session(deferred=True) as s:
        base = validate_configuration(s, "hidden", "baseline", n_boot=0)
    row = {"effect": effect, "template": template, "item": item or effect,
           "max_error_before": _max_error(base), "worst_before": _worst(base)}
    _story_row(row)
    assert not base.validated, f"baseline with hidden {item or effect} should fail validation"
    if capsys is None:
        diag = diagnose(database, "hidden", "baseline", effects=candidates, workers=workers).to_dict()
    else:
        diag = _cli(database, capsys, "diagnose", "hidden", "--config", "baseline",
                    *(["--candidates", *candidates] if candidates else []))
    ranked = [c["name"] for c in diag["candidates"]]
    row.update({"ranked": ranked[:5], "verdict": diag.get("verdict"),
                "explained_top": diag["candidates"][0]["explained"],
                "flags_top": diag["candidates"][0].get("flags")})
    _story_row(row)
    assert ranked[0] == effect, f"hidden {effect} ranked {ranked}"
    first = diag["candidates"][0]
    assert {"explained", "parameters", "fixes", "worsens", "explanation"} <= set(first)
    main = MAIN_PARAMETER[effect]
    row.update({"explained": first["explained"], "held_out_explained": first.get("held_out_explained"),
                "second": ranked[1], "diagnosed": first["parameters"][main]})
    start = {effect: first["parameters"]}
    if capsys is None:
        cal = calibrate(database, "hidden", "baseline", [effect], "calibrated", start=start,
                        workers=workers).to_dict()
    else:
        cal = _cli(database, capsys, "calibrate", "hidden", "--config", "baseline", "--effect", effect,
                   "--as", "calibrated", "--start", *[f"{effect}.{k}={v}" for k, v in first["parameters"].items()])
        assert {"validated", "coverage", "quantities"} <= set(cal["validation"])
    with database.write_session(deferred=True) as s:
        after = validate_configuration(s, "hidden", "calibrated", n_boot=0)
    before_err, after_err = _max_error(base), _max_error(after)
    all_pass = all(q.passed for q in after.quantities.values())
    true_value = truth["hidden_effects"][effect][main]
    fitted = cal["parameters"][f"{effect}.{main}"]
    row.update({"fitted": fitted, "truth": true_value, "max_error_after": after_err, "all_pass": all_pass,
                "fitted_all": {k: v for k, v in cal["parameters"].items() if k.startswith(effect)}})
    _story_row(row)
    assert all_pass or after_err <= 0.5 * before_err, (before_err, after_err)
    assert fitted == pytest.approx(true_value, rel=0.2), (effect, main, fitted, true_value)
    lineage = cal["lineage"]
    assert [x["configuration"] for x in lineage] == ["baseline", "calibrated"]
    assert lineage[-1]["max_error"] < lineage[0]["max_error"]
    return row


def test_hidden_friction_damping_fast(tmp_path, capsys):
    """CI variant through the CLI: hidden friction in the suspension, four candidate effects."""
    row = check_hidden_effect(tmp_path, "friction_damping", capsys=capsys,
                              candidates=["friction_damping", "damper_series_stiffness",
                                          "carbody_flexibility", "conicity"])
    assert row["explained"] > 0.5


#: (template, effect) → (``--hidden`` item the story runs at, value plausible?, why). The
#: plausible hidden default wherever it fails the baseline (seed 1, 12 sections); otherwise the
#: measured value that fails it with a margin (worst max(|mean_norm|, std_norm) ≥ 1.2), labelled
#: "outside the plausible range — an identifiability check only". Figures: docs/diagnosis.md
#: "The hidden-effect test" (measured 2026-11-23 with the corrected simulator).
OUTSIDE = "outside the plausible range — an identifiability check only"
STORY_VALUES: dict[tuple[str, str], tuple[str, bool, str]] = {
    # plausible hidden defaults that fail the baseline (worst error at seed 1 in the comment)
    ("coach", "friction_damping"): ("friction_damping", True, "plausible default 2.5 kN (1.91 ay_rms)"),
    ("coach", "wheel_rail_friction"): ("wheel_rail_friction", True, "plausible default μ 0.18 (1.42 YQ_qst)"),
    ("coach", "conicity"): ("conicity", True, "plausible default 0.45 (1.38 YQ_qst)"),
    ("coach", "parasitic_yaw_stiffness"): ("parasitic_yaw_stiffness", True,
                                           "plausible default 1500 kN·m/rad (1.47 SumY_qst)"),
    ("coach", "lateral_bumpstop"): ("lateral_bumpstop", True, "plausible default 12 mm, 2 kN/mm (1.72 ay_max)"),
    ("wagon", "friction_damping"): ("friction_damping", True, "plausible default 2.5 kN (1.26 ay_rms)"),
    ("wagon", "track_flexibility"): ("track_flexibility", True,
                                     "plausible default 20 / 5 MN/m (1.19 Y_max: fails, below the 1.2 margin)"),
    ("wagon", "wheel_rail_friction"): ("wheel_rail_friction", True, "plausible default μ 0.10 (2.08 Y_qst)"),
    ("wagon", "conicity"): ("conicity", True, "plausible default 0.50 (2.07 Y_qst)"),
    ("wagon", "parasitic_yaw_stiffness"): ("parasitic_yaw_stiffness", True,
                                           "plausible default 1500 kN·m/rad (1.40 Y_qst)"),
    # a plausible value other than the default: 8 mm passes (0.59), 6 mm at the stiff end fails
    ("wagon", "lateral_bumpstop"): ("lateral_bumpstop:clearance_mm=6,stiffness_kN_mm=5", True,
                                    "plausible 6 mm, 5 kN/mm (1.59 SumY_max; default 8 mm, 2 kN/mm: 0.59)"),
    # no plausible value fails: the measured failing value, outside the plausible range
    ("coach", "damper_series_stiffness"): ("damper_series_stiffness=0.2", False,
                                           f"{OUTSIDE}: 0.2 MN/m = the search bound (1.26 az_rms); "
                                           "0.25: 1.01, 0.3: 0.84, plausible 2–20 MN/m: ≤ 0.30"),
    ("coach", "track_flexibility"): ("track_flexibility:k_vertical_MN_m=12,k_lateral_MN_m=2", False,
                                     f"{OUTSIDE}: 12 / 2 MN/m (1.27 YQ_qst; the lateral 2 MN/m "
                                     "alone with 20 vertical: 1.26); plausible default 20 / 5: 0.74"),
    ("coach", "measured_irregularities"): ("measured_irregularities=1.3", False,
                                           f"{OUTSIDE}: recording gain 1.3 (1.34 az_max); "
                                           "plausible 0.9–1.1: ≤ 0.90"),
    ("wagon", "measured_irregularities"): ("measured_irregularities=1.4", False,
                                           f"{OUTSIDE}: recording gain 1.4 (1.29 az_max; "
                                           "1.3: 1.10); plausible 0.9–1.1: ≤ 0.76"),
}

#: (template, effect) → (plausible ``--hidden`` item, the item where the effect shows most inside
#: its search bounds, why): no value inside the bounds fails the baseline (bending frequency
#: 5–16 Hz scanned at ζ = 0.005, seed 1), so there is no diagnosis story; the slow test asserts
#: the documented claim that the baseline PASSES at both (docs/simulator.md)
BASELINE_PASSES: dict[tuple[str, str], tuple[str, str, str]] = {
    ("coach", "carbody_flexibility"): ("carbody_flexibility", "carbody_flexibility:frequency_Hz=5,damping_ratio=0.005",
                                       "7 Hz, ζ 0.01: 0.60 (az_max); 5 Hz, ζ 0.005 (both at the search bound): 0.84"),
    ("wagon", "carbody_flexibility"): ("carbody_flexibility", "carbody_flexibility:frequency_Hz=5,damping_ratio=0.005",
                                       "7 Hz, ζ 0.01: 0.20; 5 Hz, ζ 0.005: 0.29"),
}


def test_story_table_covers_every_effect_and_labels_plausibility():
    """Every (template, applicable effect) has a story value or a documented "baseline passes";
    the ``plausible`` label agrees with every parameter's plausible range (core/sim/effects.py)
    and every value lies inside the search bounds."""
    from railval.core.sim.synth import parse_hidden

    # input-side effects (the generated track's level) are no vehicle effect a model engineer
    # adds: the diagnosis answers them with "the track input differs" (docs/diagnosis.md)
    vehicle = [e for e in EFFECTS if not EFFECTS[e].input_side]
    cases = ({("coach", e) for e in COACH_EFFECTS if e in vehicle}
             | {("wagon", e) for e in WAGON_EFFECTS if e in vehicle})
    assert {e for e in EFFECTS if EFFECTS[e].input_side} == {"track_level_vertical",
                                                            "track_level_lateral"}
    assert set(STORY_VALUES) | set(BASELINE_PASSES) == cases
    assert not set(STORY_VALUES) & set(BASELINE_PASSES)
    items = {k: (v[0], v[1]) for k, v in STORY_VALUES.items()}
    items.update({k: (v[0], True) for k, v in BASELINE_PASSES.items()})
    for (template, effect), (_, strongest, _) in BASELINE_PASSES.items():
        parse_hidden([strongest], template)  # inside the search bounds
    for (template, effect), (item, plausible) in items.items():
        values = parse_hidden([item], template)[effect]  # raises outside the bounds
        inside = all(EFFECTS[effect].parameters[k].plausible[0] <= v <= EFFECTS[effect].parameters[k].plausible[1]
                     for k, v in values.items())
        assert inside == plausible, (template, effect, values)
        if not plausible:
            assert STORY_VALUES[(template, effect)][2].startswith(OUTSIDE)


def _story(tmp_path, template: str, effect: str) -> None:
    item, plausible, why = STORY_VALUES[(template, effect)]
    row = check_hidden_effect(tmp_path, effect, template=template, item=item, workers=1)
    row["plausible"] = plausible
    print(json.dumps(row))


@pytest.mark.slow
@pytest.mark.parametrize("effect", [e for t, e in STORY_VALUES if t == "coach"])
def test_hidden_effect_coach(tmp_path, effect):
    _story(tmp_path, "coach", effect)


@pytest.mark.slow
@pytest.mark.parametrize("effect", [e for t, e in STORY_VALUES if t == "wagon"])
def test_hidden_effect_wagon(tmp_path, effect):
    _story(tmp_path, "wagon", effect)


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(BASELINE_PASSES), ids=lambda c: f"{c[0]}-{c[1]}")
def test_baseline_passes_where_no_value_fails(tmp_path, case):
    """The documented claim for effects with no story: at the plausible value the baseline
    passes DynoTRAIN validation (docs/simulator.md "Synthetic campaigns")."""
    template, effect = case
    for k, item in enumerate(BASELINE_PASSES[case][:2]):
        (tmp_path / str(k)).mkdir()
        database, _ = make_campaign(tmp_path / str(k), [item], template=template)
        with database.write_session(deferred=True) as s:
            base = validate_configuration(s, "hidden", "baseline", n_boot=0)
        print(json.dumps({"template": template, "item": item, "max_error_before": _max_error(base),
                          "worst_before": _worst(base)}))
        assert base.validated, (item, _max_error(base), _worst(base))


@pytest.mark.slow
def test_two_hidden_effects_both_in_top_three(tmp_path):
    database, _ = make_campaign(tmp_path, ["conicity", "friction_damping"])
    diag = diagnose(database, "hidden", "baseline", workers=1)
    top3 = [c.name for c in diag.candidates[:3]]
    print(json.dumps({"top3": top3, "explained": [c.explained for c in diag.candidates[:3]],
                      "verdict": diag.verdict}))
    assert {"conicity", "friction_damping"} <= set(top3), top3


@pytest.mark.slow
@pytest.mark.parametrize("factor", [0.9, 1.1])
def test_mis_set_baseline_still_ranks_hidden_effect_first(tmp_path, factor):
    """The baseline's secondary suspension stiffnesses and dampings mis-set by ±10 %."""
    from railval.app.services.campaign_context import load_context, simulate_context
    from railval.core.sim.vehicles import template_parameters
    from railval.db import repo

    database, _ = make_campaign(tmp_path, ["parasitic_yaw_stiffness"])
    defaults = {p.name: p.default for p in template_parameters("coach")}
    params = {k: factor * defaults[k] for k in ("k_secondary_y", "k_secondary_z", "c_secondary_z",
                                                "c_secondary_y")}
    with database.session() as s:
        ctx = load_context(s, "hidden")
        effects = dict(repo.get_configuration(s, "hidden", "baseline").effects)
    sets = simulate_context(ctx, effects, params)
    with database.session(write=True) as s:
        repo.store_configuration(s, "hidden", "misset", parent="baseline", effects=effects,
                                 parameters=params, description="mis-set", signalsets=sets)
    diag = diagnose(database, "hidden", "misset", workers=1)
    print(json.dumps({"factor": factor, "top3": [c.name for c in diag.candidates[:3]]}))
    assert diag.candidates[0].name == "parasitic_yaw_stiffness", [c.name for c in diag.candidates]
