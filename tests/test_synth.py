"""Synthetic campaigns: structure, coverage, hidden truth kept out of the campaign, import via the
CLI, the `simulate` verb, the demo seeding and the baseline-fails / corrected-passes property."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railval.app.cli import main
from railval.core.errors import InvalidParameter
from railval.core.sim.synth import HIDDEN_DEFAULTS, build_campaign, hidden_defaults, parse_hidden


def test_parse_hidden_forms_and_errors():
    assert parse_hidden(["conicity=0.4"]) == {"conicity": {"conicity": 0.4}}
    assert parse_hidden(["lateral_bumpstop:clearance_mm=15"]) == {
        "lateral_bumpstop": {"clearance_mm": 15.0, "stiffness_kN_mm": HIDDEN_DEFAULTS["lateral_bumpstop"]["stiffness_kN_mm"]}}
    assert parse_hidden(["friction_damping"]) == {"friction_damping": HIDDEN_DEFAULTS["friction_damping"]}
    with pytest.raises(InvalidParameter, match="unknown effect id 'nope'"):
        parse_hidden(["nope=1"])
    with pytest.raises(InvalidParameter, match=r"'mu' = 5.*\[0\.1, 0\.6\]"):
        parse_hidden(["wheel_rail_friction=5"])
    with pytest.raises(InvalidParameter, match="at least 12 sections"):
        build_campaign(n_sections=8)
    with pytest.raises(InvalidParameter, match="does not apply to template 'wagon'"):
        build_campaign(template="wagon", hidden=parse_hidden(["damper_series_stiffness"]))


@pytest.fixture(scope="module")
def wagon_campaign():
    return build_campaign(template="wagon", hidden=parse_hidden(["parasitic_yaw_stiffness"], "wagon"), seed=3)


def test_campaign_structure_coverage_and_run_in(wagon_campaign):
    sc = wagon_campaign
    zones = [s.zone for s in sc.sections]
    assert len(sc.sections) >= 12 and all(zones.count(z) >= 3 for z in (1, 2, 3, 4))
    assert len({s.country for s in sc.sections}) >= 3
    for s in sc.sections:
        t = s.track
        a, b = t.eval_range
        assert a / t.speed_ms >= 9.9 and (t.length_m - b) / t.speed_ms >= 9.9  # ≈ 10 s run-in/out
        m, bl = sc.measured[t.id], sc.baseline[t.id]
        assert set(m.channels) == set(bl.channels) and m.fs == bl.fs == 200.0
        assert m.distance_m[0] < a and m.distance_m[-1] > b
        rec = s.manifest_record()
        irr = rec["layout"]["irregularities"]
        assert len(irr["vertical_mm"]) == len(irr["gauge_mm"]) > (t.length_m / irr["ds_m"])
    # baseline uses the measured irregularities when another effect is hidden
    assert sc.baseline_effects == {"measured_irregularities": {"scale": 1.0}}
    assert sc.truth["hidden_effects"] == {"parasitic_yaw_stiffness": hidden_defaults("wagon")["parasitic_yaw_stiffness"]}


def test_measured_irregularities_hidden_makes_baseline_use_generated_track():
    sc = build_campaign(hidden=parse_hidden(["measured_irregularities"]), seed=4)
    assert sc.baseline_effects == {}


def test_synth_cli_imports_campaign_and_reveals_truth_only_on_request(sqlite_database, tmp_path, capsys):
    url = sqlite_database.url
    reveal = tmp_path / "truth.json"
    out = tmp_path / "camp"
    rc = main(["--db", url, "synth", "--name", "hid", "--hidden", "parasitic_yaw_stiffness=1200", "--seed", "9",
               "--reveal", str(reveal), "--out", str(out), "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["campaign"] == "hid" and doc["sections"] == 12
    truth = json.loads(reveal.read_text())
    assert truth["hidden_effects"] == {"parasitic_yaw_stiffness": {"k_yaw_kNm_rad": 1200.0}}
    manifest = (out / "campaign.json").read_text()
    assert "parasitic" not in manifest and "hidden" not in manifest and "truth" not in manifest

    from railval.db import repo

    with sqlite_database.session() as s:
        confs = [c.name for c in repo.list_configurations(s, "hid")]
        assert confs == ["baseline"]
        infos = repo.section_infos(s, "hid")
        assert sorted({i.zone for i in infos}) == [1, 2, 3, 4]
        layouts = repo.section_layouts(s, "hid")
        assert all("irregularities" in lay for lay in layouts.values())

    # the simulate verb stores a configuration with the effect, parent baseline
    rc = main(["--db", url, "simulate", "hid", "--config", "yaw", "--parent", "baseline",
               "--effect", "parasitic_yaw_stiffness:k_yaw_kNm_rad=1200", "--workers", "1", "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["effects"]["parasitic_yaw_stiffness"] == {"k_yaw_kNm_rad": 1200.0}
    assert "measured_irregularities" in doc["effects"]
    with sqlite_database.session() as s:
        sets = repo.load_signalsets(s, "hid", "yaw")
        base = repo.load_signalsets(s, "hid", "baseline")
    sid = next(i.id for i in infos if i.zone == 4)
    assert np.median(np.abs(sets[sid].channels["Y_w1L"] + sets[sid].channels["Y_w1R"])) > \
        np.median(np.abs(base[sid].channels["Y_w1L"] + base[sid].channels["Y_w1R"]))

    # unknown effect on the command line → exit code 2 with the message
    rc = main(["--db", url, "simulate", "hid", "--config", "bad", "--effect", "warp_drive"])
    assert rc == 2
    assert "unknown effect id 'warp_drive'" in capsys.readouterr().err


def test_ensure_demo_seeds_only_an_empty_database(sqlite_database):
    from railval.app.services.synth import DEMO_NAME, ensure_demo

    assert ensure_demo(sqlite_database) == DEMO_NAME
    assert ensure_demo(sqlite_database) is None


def test_baseline_fails_and_corrected_model_passes(wagon_campaign):
    """docs/design.md §7: the baseline clearly fails the DynoTRAIN limits, baseline + the hidden effect at
    its true value passes (the nuisances keep it from being perfect)."""
    from railval.core.en14363 import evaluate_batch
    from railval.core.sim import simulate_section
    from railval.core.types import SectionInfo
    from railval.core.validation import validate

    sc = wagon_campaign
    infos = [SectionInfo(id=s.track.id, radius_m=s.track.radius_m, cant_mm=s.track.cant_mm,
                         speed_kmh=s.track.speed_kmh, zone=s.zone, eval_start_m=s.track.eval_range[0],
                         eval_end_m=s.track.eval_range[1]) for s in sc.sections]
    ids = [i.id for i in infos]
    meas = dict(zip(ids, evaluate_batch([sc.measured[i] for i in ids], infos), strict=True))
    base = dict(zip(ids, evaluate_batch([sc.baseline[i] for i in ids], infos), strict=True))
    eff = {**sc.baseline_effects, **sc.truth["hidden_effects"]}
    corr_sets = [simulate_section(sc.vehicle, s.track, eff) for s in sc.sections]
    corr = dict(zip(ids, evaluate_batch(corr_sets, infos), strict=True))
    veh = sc.vehicle_record()

    def worst(vals):
        vr = validate({k: dict(v) for k, v in meas.items()}, {k: dict(v) for k, v in vals.items()}, infos, veh,
                      n_boot=0).to_dict()
        qs = vr["quantities"]
        rows = qs.values() if isinstance(qs, dict) else qs
        return vr["validated"], max(max(abs(q["mean_norm"]), q["std_norm"]) for q in rows)

    ok_b, w_b = worst(base)
    ok_c, w_c = worst(corr)
    assert not ok_b and w_b > 1.0
    assert ok_c and w_c < 0.5 * w_b
