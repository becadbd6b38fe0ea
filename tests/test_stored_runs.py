"""Diagnosis and metrics results persist (SQLite and PostgreSQL): a second request with the
same inputs reads the stored run instead of computing, changed settings or re-imported
signals compute afresh, every run is listed, and a new app session sees the latest one."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from railval.app.services import diagnosis as diagnosis_service
from railval.app.services import metrics as metrics_service
from railval.core.diagnosis import DiagnosisResult
from railval.db import runs


@pytest.fixture
def demo(database, tmp_path):
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(tmp_path / "camp", n_sections=4, fmt="csv", n_configs=1)
    import_campaign(database, manifest.parent)
    return database


@pytest.fixture
def synth_demo(database):
    """A small synthetic campaign the built-in simulator can re-simulate (12 sections, the fewest synth makes)."""
    from railval.app.services.synth import synth

    synth(database, name="demo", template="coach", hidden=["conicity"], seed=1, n_sections=12)
    return database


def _no_simulation(*a, **k):
    """Stands in for the simulating diagnosis: any call fails the test."""
    raise AssertionError("the stored diagnosis should have been reused, not simulated")


def test_diagnosis_is_stored_and_reused(synth_demo, monkeypatch):
    demo = synth_demo
    kw = {"effects": ["conicity"], "values_per_parameter": 2, "workers": 1}
    first = diagnosis_service.diagnose(demo, "demo", "baseline", **kw)
    assert first.run["reused"] is False and first.run["current"] is True
    monkeypatch.setattr(diagnosis_service, "rank_causes", _no_simulation)
    again = diagnosis_service.diagnose(demo, "demo", "baseline", **kw)
    assert again.run["reused"] is True
    assert again.run["id"] == first.run["id"]
    assert [c.name for c in again.candidates] == [c.name for c in first.candidates]
    assert again.candidates[0].explained == pytest.approx(first.candidates[0].explained, rel=1e-12)
    np.testing.assert_allclose(again.residual.values, first.residual.values, rtol=1e-12)
    # the whole ranking reads back as stored (NaN compared as null, as stored)
    assert (runs.json_safe(again.to_dict(with_signatures=True)["candidates"])
            == runs.json_safe(first.to_dict(with_signatures=True)["candidates"]))
    # other settings: computed afresh (the stand-in executor refuses)
    with pytest.raises(AssertionError, match="should have been reused"):
        diagnosis_service.diagnose(demo, "demo", "baseline", **{**kw, "values_per_parameter": 3})
    with pytest.raises(AssertionError, match="should have been reused"):
        diagnosis_service.diagnose(demo, "demo", "baseline", **kw, refresh=True)
    with demo.session() as s:  # a new session (reload, second tab) finds it
        listed = diagnosis_service.diagnosis_runs(s, "demo", "baseline")
        latest = diagnosis_service.latest_diagnosis(s, "demo", "baseline")
    assert len(listed) == 1 and listed[0]["top"] == first.candidates[0].name
    assert listed[0]["settings"]["values_per_parameter"] == 2 and listed[0]["current"] is True
    assert isinstance(latest, DiagnosisResult) and latest.run["id"] == first.run["id"]


def test_metrics_are_stored_reused_and_recomputed_when_inputs_change(demo, monkeypatch):
    args = ("demo", "baseline", ["S02"], ["Y_w1L", "ay_cb_b1"])
    with demo.write_session(deferred=True) as s:
        first = metrics_service.metrics_for_configuration(s, *args, families=["sprague_geers"])
    assert first.attrs["run"]["reused"] is False
    calls = []
    real = metrics_service._compute
    monkeypatch.setattr(metrics_service, "_compute", lambda *a, **k: calls.append(1) or real(*a, **k))
    with demo.write_session(deferred=True) as s:  # a new session: the stored run, not a computation
        again = metrics_service.metrics_for_configuration(s, *args, families=["sprague_geers"])
        assert metrics_service.stored_metrics(s, *args, families=["sprague_geers"]) is not None
        assert metrics_service.stored_metrics(s, *args, families=["area"]) is None
    assert calls == [] and again.attrs["run"]["reused"] is True
    pd.testing.assert_frame_equal(again, first, check_exact=False, rtol=1e-12)
    with demo.write_session(deferred=True) as s:  # other settings: computed and stored as a second run
        metrics_service.metrics_for_configuration(s, *args, families=["sprague_geers"], max_lag_s=1.0)
    assert calls == [1]
    # a re-imported measured signal (another content hash) computes afresh; the earlier
    # runs are listed as no longer current
    with demo.session(write=True) as s:
        from sqlalchemy import select

        from railval.db.models import Channel, Recording, Section, Signal

        sig = s.scalars(select(Signal).join(Recording, Signal.recording_id == Recording.id)
                        .join(Section, Recording.section_id == Section.id)
                        .join(Channel, Signal.channel_id == Channel.id)
                        .where(Section.section_id == "S02", Channel.name == "Y_w1L",
                               Recording.configuration_id.is_(None))).one()
        sig.sha256 = "0" * 64
    with demo.write_session(deferred=True) as s:
        metrics_service.metrics_for_configuration(s, *args, families=["sprague_geers"])
        listed = metrics_service.metrics_runs(s, "demo", "baseline")
    assert calls == [1, 1]
    assert [r["settings"]["max_lag_s"] for r in listed] == [2.0, 1.0, 2.0] and listed[0]["rows"] == 2
    assert [r["current"] for r in listed] == [True, False, False]


def test_a_new_session_shows_the_stored_diagnosis_and_metrics(synth_demo):
    demo = synth_demo
    from railval.app.state import AppState, Backend, DiagnoseState, MetricsState

    app = AppState(Backend(demo))
    fresh = DiagnoseState(app)
    assert fresh.candidates == [] and fresh.runs == []  # never diagnosed
    fresh.values_per_parameter = 2
    fresh.candidate_effects = ["conicity"]
    fresh.run_diagnosis(background=False)
    top = fresh.candidates[0]["effect"]
    # a reload / second tab: a new AppState and DiagnoseState on the same database
    app2 = AppState(Backend(demo))
    again = DiagnoseState(app2)
    assert [c["effect"] for c in again.candidates] == [c["effect"] for c in fresh.candidates]
    assert again.effect == top and again.stored_run["reused"] is True
    assert again.stored_run["settings"]["values_per_parameter"] == 2
    assert [r["top"] for r in again.runs] == [top]
    assert again.residual["values"] == fresh.residual["values"]

    metrics = MetricsState(app)
    assert metrics.load_stored() is False  # nothing computed yet
    metrics.compute(background=False)
    shown = MetricsState(AppState(Backend(demo)))
    assert shown.load_stored() is True and shown.computed_for == metrics.computed_for
    pd.testing.assert_frame_equal(shown.frame, metrics.frame, check_exact=False, rtol=1e-12)
    assert len(shown.runs) == 1 and shown.runs[0]["settings"]["sections"] == [app.section]
