"""Curve metrics, the campaign overview and the stored runs resolve each campaign and
configuration name once, at their entrance (issue 42, docs/design.md §2): every public
function of :mod:`railval.app.services.overview`, :mod:`railval.app.services.metrics` and
:mod:`railval.app.services.stored_runs`, and the ``railval metrics`` verb, find the campaign
by its name with one SELECT and the configuration with one; what follows takes the
:class:`railval.db.repo.CampaignRef` / :class:`railval.db.repo.ConfigRef` (or the row). The
counter is the one of ``tests/test_diagnosis_resolve_once.py`` (SQLite and PostgreSQL, the
statements as the database receives them)."""

from __future__ import annotations

import pytest

from railval.app.cli import main
from railval.app.services import metrics as metrics_service
from railval.app.services import overview as overview_service
from railval.app.services import stored_runs
from railval.app.services.synth import synth
from railval.db import repo
from tests.test_diagnosis_resolve_once import lookups  # noqa: F401  (the counting fixture)

#: the metrics of two sections are enough to pass through every step
SECTIONS = ["S01", "S02"]


@pytest.fixture
def synth_demo(database):
    synth(database, name="demo", template="coach", hidden=["conicity"], seed=1, n_sections=12)
    return database


def _count(seen: dict) -> tuple[int, int]:
    return len(seen["campaign"]), len(seen["configuration"])


def _clear(seen: dict) -> None:
    for v in seen.values():
        v.clear()


def test_the_counter_sees_a_planted_double_lookup(synth_demo, lookups):  # noqa: F811
    """The planted violation: the stored-run inputs given the resolved campaign but the
    configuration's name again (as ``metrics_runs`` did before it passed the reference) are
    counted as a second configuration lookup."""
    _clear(lookups)
    with synth_demo.session() as s:
        camp, conf = repo.resolve(s, "demo", "baseline")
        stored_runs.data_inputs(s, camp, conf)
        assert _count(lookups) == (1, 1)
        stored_runs.data_inputs(s, camp, "baseline")  # the name, not the reference
    assert _count(lookups) == (1, 2)


def test_overview_functions_resolve_each_name_once(synth_demo, lookups):  # noqa: F811
    db = synth_demo
    cases = {  # call → (campaign lookups, configuration lookups)
        "overview": (lambda: overview_service.overview(db, "demo"), (1, 0)),
        "configurations": (lambda: overview_service.configurations(db, "demo"), (1, 0)),
        "signals measured": (lambda: overview_service.signals(db, "demo", None, "S01"), (1, 0)),
        "signals simulated": (lambda: overview_service.signals(db, "demo", "baseline", "S01"),
                              (1, 1)),
        "hashes": (lambda: overview_service.hashes(db, "demo", "baseline"), (1, 1)),
        "lineage": (lambda: overview_service.lineage(db, "demo", "baseline"), (1, 1)),
        "require_sealed": (lambda: overview_service.require_sealed(db, "demo", "baseline"),
                           (1, 1)),
    }
    for label, (call, expected) in cases.items():
        _clear(lookups)
        call()
        assert _count(lookups) == expected, (label, lookups)


def test_metrics_compute_reuse_and_list_resolve_each_name_once(synth_demo, lookups):  # noqa: F811
    db = synth_demo
    for refresh in (True, False):  # computed and stored, then the stored run reused
        _clear(lookups)
        df = overview_service.metrics(db, "demo", "baseline", SECTIONS, refresh=refresh)
        assert sorted(set(df["section"])) == SECTIONS
        assert df.attrs["run"]["reused"] is (not refresh)
        assert _count(lookups) == (1, 1), (refresh, lookups)
    for service in (metrics_service.stored_metrics, metrics_service.metrics_runs):
        _clear(lookups)
        kw = {"sections": SECTIONS} if service is metrics_service.stored_metrics else {}
        out = overview_service.in_session(db, service, "demo", "baseline", **kw)
        assert out is not None and len(out) > 0
        assert _count(lookups) == (1, 1), (service.__name__, lookups)


def test_stored_run_inputs_take_names_or_references(synth_demo, lookups):  # noqa: F811
    """Given names, :func:`stored_runs.data_inputs` resolves them once; given the references,
    not at all — and both read the same inputs."""
    with synth_demo.session() as s:
        _clear(lookups)
        by_name = stored_runs.data_inputs(s, "demo", "baseline", SECTIONS)
        assert _count(lookups) == (1, 1)
        camp, conf = repo.resolve(s, "demo", "baseline")
        _clear(lookups)
        by_ref = stored_runs.data_inputs(s, camp, conf, SECTIONS)
        assert _count(lookups) == (0, 0)
    assert by_ref == by_name and sorted(by_ref["measured"]) == SECTIONS


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_cli_metrics_resolves_each_name_once(synth_demo, lookups, capsys, json_flag):  # noqa: F811
    _clear(lookups)
    rc = main(["--db", synth_demo.url, "metrics", "demo", "--config", "baseline",
               "--section", "S01", *json_flag])
    assert rc == 0 and "S01" in capsys.readouterr().out
    assert _count(lookups) == (1, 1), lookups
