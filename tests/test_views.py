"""The view model of a validation (app/views.py): pages, the report and the CLI's text read
core's result objects through it, so a renamed field breaks here instead of emptying a
table; coverage rules live once in core."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from railval.app.cli.cmd_validate import format_result
from railval.app.report import _coverage_html, _quantities_html, definition_html, supplementary_html
from railval.app.services.overview import CampaignOverview
from railval.app.views import InSample, ValidationView, view_of
from railval.core.coverage import Coverage, layout_shortfalls
from railval.core.quantities import QUANTITIES, QUANTITY_IDS
from railval.core.types import SectionInfo
from railval.core.validation import QuantityResult, validate

VEHICLE = {"kind": "passenger", "Q0_kN": 80.0}


def _campaign(n_per_zone: int = 3, positions: int = 2, bias: float = 0.3):
    """Sections in every zone with every quantity at ``positions`` positions; the
    simulation off by ``bias`` (times the std limit) plus noise."""
    rng = np.random.default_rng(4)
    sections, meas, sim = [], {}, {}
    for zone in (1, 2, 3, 4):
        for i in range(n_per_zone):
            sid = f"z{zone}s{i}"
            sections.append(SectionInfo(sid, 1000.0, 0.0, 100.0, zone, 0.0, 100.0))
            meas[sid], sim[sid] = {}, {}
            for q in QUANTITY_IDS:
                lim = QUANTITIES[q].std_limit(80.0, "passenger", True)
                for p in QUANTITIES[q].positions()[:positions]:
                    m = 1.0 + rng.normal()
                    meas[sid][(q, p)] = m
                    sim[sid][(q, p)] = m + lim * (bias + 0.2 * rng.normal())
    return sections, meas, sim


@pytest.fixture(scope="module")
def view() -> ValidationView:
    sections, meas, sim = _campaign()
    return view_of(validate(meas, sim, sections, VEHICLE, n_boot=50, seed=1))


def test_rows_are_the_json_fields_of_each_quantity(view):
    assert [r["quantity"] for r in view.quantities] == list(QUANTITY_IDS)
    doc = view.result.to_dict()
    assert view.quantities == doc["quantities"]  # the same fields as ``railval validate --json``
    assert view.failing == [r["quantity"] for r in doc["quantities"] if not r["pass"]]
    assert view.coverage.ok and view.coverage.shortfalls == []


def test_drilldown_carries_cores_normalised_column(view):
    rows = view.drilldown("Y_max")
    pairs = view.pairs[view.pairs["quantity"] == "Y_max"]
    assert len(rows) == len(pairs) and len(view.drilldown("Y_max", 5)) == 5
    limit = view.quantity("Y_max").std_limit
    for r in rows:
        assert r["norm"] == pytest.approx(r["D_v"] / limit)
    assert [abs(r["D_v"]) for r in rows] == sorted((abs(r["D_v"]) for r in rows), reverse=True)


def test_a_renamed_quantity_field_breaks_instead_of_emptying_a_table(view, monkeypatch):
    original = QuantityResult.to_dict

    def renamed(self):
        d = original(self)
        d["mean_normalised"] = d.pop("mean_norm")
        return d

    monkeypatch.setattr(QuantityResult, "to_dict", renamed)
    with pytest.raises(KeyError, match="mean_norm"):
        _quantities_html(view)
    with pytest.raises(KeyError, match="mean_norm"):
        format_result(view.result)


def test_a_renamed_coverage_field_breaks_instead_of_hiding_shortfalls():
    @dataclasses.dataclass
    class Renamed:  # Coverage with ``shortfalls`` renamed
        n_sections: int
        zones: dict
        positions: dict
        values: dict
        messages: list
        sections_required = 12
        sections_per_zone_required = 3

    cov = Renamed(10, {1: 2, 2: 3, 3: 3, 4: 2}, {}, {}, ["zone 1 has 2 sections, needs 3"])
    with pytest.raises(AttributeError, match="shortfalls"):
        _coverage_html(cov)


def test_coverage_shortfalls_reach_report_and_cli():
    sections, meas, sim = _campaign(n_per_zone=2, positions=1)
    res = validate(meas, sim, sections, VEHICLE, n_boot=0)
    v = view_of(res)
    assert not v.validated and not v.coverage.ok
    html = _coverage_html(v.coverage)
    text = format_result(res)
    for s in v.coverage.shortfalls:
        assert f"<li class='fail'>{s}</li>" in html
        assert f"coverage shortfall: {s}" in text
    assert "zone 3 has 2 sections, needs 3" in v.coverage.shortfalls


def test_in_sample_reads_the_provenance_strictly():
    assert InSample.of({}) is None and InSample.of({"in_sample": False}) is None
    ins = InSample.of({"in_sample": True, "calibrated_in": ["a+fd"], "fit_sections": ["S1", "S2"],
                       "held_out_sections": []})
    assert ins.note() == "a+fd was calibrated on 2 of these sections"
    with pytest.raises(KeyError):
        InSample.of({"in_sample": True, "calibrated_in": ["a+fd"]})


def test_plain_values_have_no_definition_or_supplementary_rows(view):
    assert view.definition_rows() == [] and not view.definitions_available
    assert view.supplementary_rows() == []
    assert "Not available for this result." in definition_html(view)
    assert "No supplementary channels" in supplementary_html(view)


def test_view_of_refuses_a_dictionary(view):
    with pytest.raises(TypeError, match="ValidationResult"):
        view_of(view.result.to_dict())


def test_layout_coverage_uses_the_validation_rules():
    zones = [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4]
    kinds = ["Y"] * 8 + ["Q"] * 8 + ["ay_cb", "az_cb", "az_cb"]
    assert layout_shortfalls(zones, kinds) == [
        "11 sections, needs 12", "zone 4 has 2 sections, needs 3",
        "channel kind ay_cb has 1 signal, needs 2"]
    ov = CampaignOverview("c", "", {}, [SectionInfo(f"s{i}", 0.0, 0.0, 80.0, z, 0.0, 1.0)
                                        for i, z in enumerate(zones)],
                          [{"kind": k} for k in kinds], [])
    assert ov.coverage_shortfalls() == layout_shortfalls(zones, kinds)
    assert Coverage.sections_per_zone_required == 3 and Coverage.sections_required == 12
