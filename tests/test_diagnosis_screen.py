"""The screened diagnosis (issue 41, docs/diagnosis.md "Screened diagnosis"): every effect and
parameter candidate simulated on the screen sections first, the best ``screen`` of them on the
rest of the campaign. A kept candidate's runs must be those of the whole diagnosis (each section
is its own run), so its shares and fitted value equal the whole diagnosis's exactly; the others
are listed with their shares on the screen; bad ``screen`` values are refused by name."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railval.app.services import diagnosis_ranking as ranking
from railval.app.services.campaign_context import load_context
from railval.core.diagnosis.screen import check_keep, screen_sections
from railval.core.errors import InvalidParameter

PARAMETERS = ["model.c_secondary_z", "model.k_secondary_z", "model.m_carbody", "model.c_yaw_damper",
              "model.k_primary_y"]
KW = {"effects": ["conicity", "friction_damping", "lateral_bumpstop"], "parameters": PARAMETERS,
      "values_per_parameter": 2, "measurement": False, "n_boot": 20, "refine": 2}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from railval.app.services.synth import synth
    from railval.db.engine import connect

    db = connect(f"sqlite:///{tmp_path_factory.mktemp('screen') / 'screen.db'}")
    db.init()
    synth(db, name="demo", template="coach", hidden=["friction_damping"], seed=5, n_sections=12)
    yield db
    db.dispose()


def test_screen_sections_cover_every_zone_first_and_keep_campaign_order():
    secs = [("A", 1), ("B", 1), ("C", 2), ("D", 3), ("E", 3), ("F", 4), ("G", 2)]
    assert screen_sections(secs, 4) == ["A", "C", "D", "F"]
    assert screen_sections(secs, 6) == ["A", "B", "C", "D", "F", "G"]  # then the second of zones 1, 2, …
    assert screen_sections(secs, 2) == ["A", "C"]
    assert screen_sections(secs[:3], 4) == ["A", "B", "C"]


@pytest.mark.parametrize("bad", [0, -3, True, 2.5, "8", None])
def test_a_bad_screen_is_refused_by_name(bad):
    with pytest.raises(InvalidParameter, match="screen"):
        check_keep(bad)


def test_runs_on_a_screen_and_on_the_rest_are_the_whole_run(campaign):
    """Each section is its own run: the screen's and the rest's validation pairs and band powers
    together are the whole campaign run's, bit for bit, section by section."""
    with campaign.session() as s:
        ctx = load_context(s, "demo")
    job = ({"conicity": {"conicity": 0.3}}, {"c_secondary_z": 15000.0})
    ids = [(x.id, int(x.zone)) for x in ctx.sections]
    on = screen_sections(ids)
    rest = [sid for sid, _ in ids if sid not in on]
    whole = ranking._evaluate_sections(ctx, job)
    a = ranking._evaluate_sections(ctx, (*job, on))
    b = ranking._evaluate_sections(ctx, (*job, rest))
    assert {r["section"] for r in a[0]} == set(on) and {r["section"] for r in b[0]} == set(rest)
    for sid, _ in ids:
        mine = [r for r in a[0] + b[0] if r["section"] == sid]
        theirs = [r for r in whole[0] if r["section"] == sid]
        assert mine == theirs, sid
        got = {**a[1], **b[1]}[sid]
        assert got.keys() == whole[1][sid].keys()
        for ch in got:
            assert np.array_equal(got[ch], whole[1][sid][ch]), (sid, ch)


def test_screened_diagnosis_keeps_the_whole_diagnosis_figures_of_its_candidates(campaign):
    whole = ranking.rank_causes(campaign, "demo", "baseline", workers=2, **KW)
    screened = ranking.rank_causes(campaign, "demo", "baseline", workers=2, screen=4, **KW)
    info = screened.screen
    assert info["applied"] and info["kept"] == 4 and len(info["sections"]) == 4
    kept = {c.name for c in screened.candidates}
    out = {x["name"] for x in info["screened_out"]}
    assert len(kept) == 4 and not kept & out
    assert kept | out == {c.name for c in whole.candidates}  # every simulated candidate: kept or listed
    by_name = {c.name: c for c in whole.candidates}
    for c in screened.candidates:  # the same runs → the same fit, shares and intervals
        w = by_name[c.name]
        assert (c.explained, c.held_out_explained, c.fitted, c.explained_ci) == \
               (w.explained, w.held_out_explained, w.fitted, w.explained_ci), c.name
    assert screened.candidates[0].name == whole.candidates[0].name == "friction_damping"
    assert screened.verdict == whole.verdict
    assert info["section_runs"] < info["section_runs_whole"]
    assert screened.simulations < whole.simulations
    assert "screened: 4 of" in screened.note
    # listed in the screen's order: best share on the screen first
    shares = [x["explained_on_screen"] for x in info["screened_out"]]
    assert shares == sorted(shares, reverse=True) and len(shares) == len(out)
    assert whole.screen is None and "screen" not in whole.to_dict()


def _evidence(sections, zones, sums, counts, sim, meas):
    from railval.core.diagnosis.evidence import SectionEvidence

    return SectionEvidence(list(sections), list(zones), ["q1", "q2", "psd a 1-2 Hz"], ["q1", "q2", "psd a"], 2,
                           np.asarray(sums, float), np.asarray(counts, float), np.asarray(sim, float),
                           np.asarray(meas, float))


def test_a_stand_in_is_the_candidate_on_the_screen_and_its_zone_change_elsewhere():
    """Sections A, B (zone 1), C, D (zone 2); the screen A, C. Off the screen a section takes the
    configuration's values moved by the change of its zone's screen section: worked by hand."""
    from railval.core.diagnosis.screen import stand_in

    secs, zones = ["A", "B", "C", "D"], [1, 1, 2, 2]
    base = _evidence(secs, zones, [[1.0, 2.0], [3.0, 0.0], [0.5, 4.0], [2.0, 1.0]],
                     [[2, 1], [3, 0], [1, 2], [2, 1]], [[10.0], [20.0], [30.0], [40.0]], [[5.0], [6.0], [7.0], [8.0]])
    screen_base = _evidence(["A", "C"], [1, 2], [[1.0, 2.0], [0.5, 4.0]], [[2, 1], [1, 2]], [[10.0], [30.0]],
                            [[5.0], [7.0]])
    cand = _evidence(["A", "C"], [1, 2], [[3.0, 2.5], [2.5, 3.0]], [[2, 1], [1, 2]], [[15.0], [15.0]],
                     [[5.0], [7.0]])
    got = stand_in(base, screen_base, cand)
    # A, C: the candidate's own evidence
    assert got.sums[0].tolist() == [3.0, 2.5] and got.sums[2].tolist() == [2.5, 3.0]
    assert got.sim_power[0, 0] == 15.0 and got.sim_power[2, 0] == 15.0
    # B (zone 1, from A): mean shifts +1.0 (q1: 3/2 − 1/2) and +0.5 (q2: 2.5 − 2); B has no q2 data
    # (zone 2's shift, +2.0, would give 9.0: the zone decides)
    assert got.sums[1].tolist() == [3.0 + 1.0 * 3, 0.0] and got.counts[1].tolist() == [3.0, 0.0]
    # D (zone 2, from C): q1 +2.0 (2.5 − 0.5), q2 −0.5 (3/2 − 4/2); power × 0.5 (15 / 30)
    assert got.sums[3].tolist() == [2.0 + 2.0 * 2, 1.0 - 0.5 * 1]
    assert got.sim_power[1, 0] == 20.0 * 1.5 and got.sim_power[3, 0] == 40.0 * 0.5
    assert np.array_equal(got.meas_power, base.meas_power)


def test_a_stand_in_equals_the_whole_evidence_where_every_section_of_a_zone_changes_alike():
    from railval.core.diagnosis.screen import stand_in

    rng = np.random.default_rng(4)
    secs, zones = ["A", "B", "C", "D", "E", "F"], [1, 1, 1, 2, 2, 3]
    counts = rng.integers(1, 4, size=(6, 2)).astype(float)
    base_mean, power = rng.normal(size=(6, 2)), rng.uniform(1, 9, size=(6, 1))
    zone_shift = {1: [0.5, -0.25], 2: [-1.0, 0.75], 3: [0.125, 0.5]}
    zone_scale = {1: 2.0, 2: 0.5, 3: 4.0}
    shift = np.array([zone_shift[z] for z in zones])
    scale = np.array([[zone_scale[z]] for z in zones])
    meas = rng.uniform(1, 9, size=(6, 1))
    base = _evidence(secs, zones, base_mean * counts, counts, power, meas)
    whole = _evidence(secs, zones, (base_mean + shift) * counts, counts, power * scale, meas)
    on = [0, 3, 5]  # A, D, F: every zone once
    pick = lambda ev: _evidence([secs[i] for i in on], [zones[i] for i in on], ev.sums[on], ev.counts[on],
                                ev.sim_power[on], ev.meas_power[on])
    got = stand_in(base, pick(base), pick(whole))
    assert np.allclose(got.values(), whole.values(), rtol=0, atol=1e-12)
    assert np.allclose(got.sums, whole.sums, rtol=0, atol=1e-12) and np.array_equal(got.counts, whole.counts)


def test_the_screened_noise_floor_counts_the_screened_out_candidates(campaign):
    """The floor is a maximum over candidates: with the screened-out candidates' stand-ins it is
    at least the floor over the kept and the measurement candidates alone (what the screen gave
    before), and the stand-ins are never ranked."""
    from railval.core.diagnosis import diagnose_evidence

    captured = {}
    real = ranking._score

    def spy(base, fams, *a, **k):
        captured["base"], captured["fams"] = base, list(fams)
        return real(base, fams, *a, **k)

    from unittest import mock

    with mock.patch.object(ranking, "_score", spy):
        screened = ranking.rank_causes(campaign, "demo", "baseline", workers=2, screen=4, **KW)
    fams = captured["fams"]
    stand_ins = [f for f in fams if f.floor_only]
    out = {x["name"] for x in screened.screen["screened_out"] if x["explained_on_screen"] > 0}
    assert {f.name for f in stand_ins} == out and screened.screen["floor_stand_ins"] == len(out) > 0
    assert all(len(e.sections) == 12 for f in stand_ins for e in f.evidence)
    assert not {c.name for c in screened.candidates} & out
    without = diagnose_evidence(captured["base"], [f for f in fams if not f.floor_only], n_boot=KW["n_boot"],
                                folds=3, seed=0)
    assert screened.noise_floor >= without.noise_floor
    assert "noise floor over every candidate" in screened.note


def test_a_screen_that_would_leave_nothing_out_runs_the_whole_diagnosis(campaign):
    res = ranking.rank_causes(campaign, "demo", "baseline", workers=1, screen=50, **KW)
    assert res.screen["applied"] is False and "nothing to screen" in res.screen["reason"]
    assert res.to_dict()["screen"]["kept"] == 50


def _doc(res) -> str:
    d = res.to_dict()
    d.pop("run", None)
    return json.dumps(d, sort_keys=True, default=str)


def test_screened_diagnosis_is_the_same_serial_pooled_and_on_a_dask_cluster(campaign):
    """The screen's two stages and the refinement handed over in turn give one result whatever
    runs them: every run in the calling thread, a process pool, a Dask LocalCluster."""
    distributed = pytest.importorskip("distributed")
    serial = ranking.rank_causes(campaign, "demo", "baseline", workers=1, screen=4, **KW)
    pooled = ranking.rank_causes(campaign, "demo", "baseline", workers=2, screen=4, **KW)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        dask = ranking.rank_causes(campaign, "demo", "baseline", scheduler=client, screen=4, **KW)
    assert serial.screen["applied"]
    assert _doc(serial) == _doc(pooled) == _doc(dask)


def test_the_diagnose_page_runs_a_screened_diagnosis_and_lists_what_it_screened_out(campaign, monkeypatch):
    """The page's "Screened" box, ticked by default, hands ``screen`` = SCREEN_KEEP to the
    service (unticked: no screen), and the page says which candidates the screen left out, with
    their shares."""
    import panel as pn

    from railval.app.pages.diagnose import DiagnosePage
    from railval.app.state import AppState, Backend
    from railval.core.diagnosis.screen import SCREEN_KEEP

    app = AppState(Backend(campaign))
    page = DiagnosePage(app)
    seen: list[dict] = []
    real = app.backend.diagnose_and_list

    def spy(c, k, progress=None, **kw):
        seen.append(dict(kw))
        kw.update(effects=KW["effects"] + ["wheel_rail_friction", "parasitic_yaw_stiffness"] + PARAMETERS,
                  values_per_parameter=2)
        return real(c, k, progress=progress, **kw)
    monkeypatch.setattr(app.backend, "diagnose_and_list", spy)
    assert page.state.screened is True  # the default (docs/diagnosis.md round 11)
    page.state.screened = False
    assert "about half" not in page.diag_estimate.object
    page.state.screened = True
    assert "screened, every candidate on 4 sections" in page.diag_estimate.object  # the cost shown
    page.state.run_diagnosis(background=False)
    assert seen[-1]["screen"] == SCREEN_KEEP
    res_screen = page.state.view.result.screen
    assert res_screen["applied"] and len(page.state.candidates) == SCREEN_KEEP + len(
        [c for c in page.state.view.candidates if c.kind == "measurement"])
    text = " ".join(o.object for o in page.candidates_box.objects if isinstance(o, pn.pane.Alert))
    assert "Screened out (simulated on " + ", ".join(res_screen["sections"]) in text
    for x in res_screen["screened_out"]:
        assert f"{x['name']} {100 * x['explained_on_screen']:.1f} %" in text
    line = " ".join(o.object for o in page.candidates_box.objects if "rv-stored-run" in (o.css_classes or []))
    assert f"10 chosen candidates, screened to the {SCREEN_KEEP} best" in line  # the stored run says it
    # the candidates' heading and caption sit directly above their table, after the verdict
    objs = list(page.candidates_box.objects)
    at = next(i for i, o in enumerate(objs) if "rv-candidates" in (getattr(o, "css_classes", None) or []))
    assert str(getattr(objs[at - 2], "object", "")).startswith("#### Ranked candidates")
    assert str(getattr(objs[at - 1], "object", "")).startswith("Shares of the residual explained")
    verdict = next(i for i, o in enumerate(objs) if isinstance(o, pn.pane.Alert))
    assert verdict < at - 2
    page.state.screened = False
    page.state.run_diagnosis(background=False)
    assert "screen" not in seen[-1]
    assert page.state.view.result.screen is None
    assert "Screened out" not in " ".join(o.object for o in page.candidates_box.objects if isinstance(o, pn.pane.Alert))


def test_a_bad_screen_is_refused_before_the_campaign_is_read(campaign):
    with pytest.raises(InvalidParameter, match="screen: .* got 0"):
        ranking.rank_causes(campaign, "no such campaign", "baseline", screen=0)


def test_a_floor_only_family_counts_in_the_noise_floor_exactly_as_a_ranked_one_and_is_not_ranked():
    """Two candidates ranked give a floor; the same two with the second marked ``floor_only`` give
    the same floor (its scatter rows alone, the same arithmetic), the first's figures unchanged,
    and only the first ranked."""
    from dataclasses import replace

    from railval.core.diagnosis import diagnose_evidence
    from railval.core.diagnosis.fit import CandidateFamily

    rng = np.random.default_rng(11)
    secs, zones = [f"S{i}" for i in range(8)], [1, 1, 1, 1, 2, 2, 2, 2]
    counts = np.full((8, 2), 2.0)
    meas = rng.uniform(1, 2, size=(8, 1))

    def ev(mean, power):
        return _evidence(secs, zones, mean * counts, counts, power, meas)

    base_mean = rng.normal(1.0, 0.4, size=(8, 2))
    base = ev(base_mean, meas * 1.5)
    fams = []
    for j, name in enumerate(["one", "two"]):
        direction = rng.normal(size=2) * (1.0 if j == 0 else 0.3)
        values = [0.5, 1.0, 2.0]
        evidence = [ev(base_mean - v * direction, meas * (1.5 - 0.1 * v * (j + 1))) for v in values]
        fams.append(CandidateFamily("effect", name, "p", values, evidence, (0.5, 2.0)))
    both = diagnose_evidence(base, fams, n_boot=40, folds=2, seed=1)
    alone = diagnose_evidence(base, fams[:1], n_boot=40, folds=2, seed=1)
    marked = diagnose_evidence(base, [fams[0], replace(fams[1], floor_only=True)], n_boot=40, folds=2, seed=1)
    assert [c.name for c in marked.candidates] == ["one"]
    assert marked.noise_floor == both.noise_floor
    assert both.noise_floor != alone.noise_floor  # the second candidate matters to the floor here
    one = next(c for c in both.candidates if c.name == "one")
    assert (marked.candidates[0].held_out_explained, marked.candidates[0].explained_ci) == \
           (one.held_out_explained, one.explained_ci)


def test_the_command_line_screens_by_default_and_whole_turns_it_off(campaign, monkeypatch, capsys):
    """``railval diagnose`` hands ``screen`` = SCREEN_KEEP to the service unless ``--whole``
    (``--screen K`` another K); ``--screen`` and ``--whole`` together are refused."""
    from railval.app.cli import main
    from railval.app.services import diagnosis as service
    from railval.core.diagnosis.screen import SCREEN_KEEP

    seen: list[dict] = []
    real = service.diagnose

    def spy(*a, **kw):
        seen.append(kw)
        return real(*a, **kw)
    monkeypatch.setattr(service, "diagnose", spy)
    url = str(campaign.engine.url)
    base = ["--db", url, "diagnose", "demo", "--config", "baseline", "--candidates", "conicity", "--values", "2"]
    assert main(base) == 0 and seen[-1]["screen"] == SCREEN_KEEP
    assert main([*base, "--screen", "3"]) == 0 and seen[-1]["screen"] == 3
    assert main([*base, "--whole"]) == 0 and "screen" not in seen[-1]
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main([*base, "--whole", "--screen", "3"])
    assert "not allowed with argument" in capsys.readouterr().err


def test_the_trust_bench_compares_a_screened_case_with_its_whole_diagnosis():
    """``bench diagnosis_trust --screen K --against-whole``: same or not, and the floor's move."""
    from railval.app.bench.trust_against_whole import (
        against_whole_lines,
        against_whole_summary,
        whole_of,
    )

    def doc(verdict, top, causes, floor):
        return {"verdict": verdict, "candidates": [{"name": top}], "causes": [{"name": c} for c in causes],
                "noise_floor": floor}
    same = whole_of(doc("cause", "a", ["a"], 0.20), doc("cause", "a", ["a"], 0.18), 9.04)
    assert same["same"] and same["floor_change"] == 0.02 and same["diagnose_s"] == 9.0
    other = whole_of(doc("cause", "a", ["a"], 0.10), doc("uncertain", "a", ["a"], 0.15), 1.0)
    assert not other["same"] and other["floor_change"] == -0.05
    records = [{"class": "a", "case": "x", "verdict": "cause", "top": "a", "causes": ["a"], "whole": same},
               {"class": "b", "case": "y", "verdict": "cause", "top": "a", "causes": ["a"], "whole": other},
               {"class": "c", "case": "z", "verdict": "none", "top": None}]
    summary = against_whole_summary(records)
    assert summary["against_whole"] == {"cases": 2, "same_verdict_top_causes": 1, "floor_lower": 1, "floor_higher": 1,
                                        "floor_change_min": -0.05, "floor_change_max": 0.02}
    lines = against_whole_lines(records, summary)
    assert lines[0].startswith("screened against whole: verdict, top and cause set the same in 1 of 2")
    assert len(lines) == 2 and "(b) y: screened cause a ['a'], whole uncertain a ['a']" in lines[1]
    assert against_whole_summary(records[2:]) == {} and against_whole_lines(records[2:], {}) == []
