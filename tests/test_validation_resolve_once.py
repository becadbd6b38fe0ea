"""A validation resolves its campaign and configuration names once, at its entrance (issue 42,
docs/design.md §2): from the CLI (``railval validate``, in-process and ``--scheduler``-less
many-configuration path) and from the service the Validation/Dashboard pages call
(:meth:`railval.app.state.backend.Backend.validation` →
:func:`railval.app.services.overview.validation`), one SELECT finds the campaign by its name
and one the configuration by its name; everything after takes the references. The counter
is the one of ``tests/test_diagnosis_resolve_once.py``."""

from __future__ import annotations

import pytest

from railval.app.services import overview as overview_service
from railval.app.services import validation as validation_service
from tests.test_diagnosis_resolve_once import lookups  # noqa: F401  (the counting fixture)

KW = {"n_boot": 50, "seed": 0}


@pytest.fixture
def synth_demo(database):
    from railval.app.services.synth import synth

    synth(database, name="demo", template="coach", hidden=["conicity"], seed=1, n_sections=12)
    return database


def _clear(seen: dict) -> None:
    for v in seen.values():
        v.clear()


def test_the_counter_sees_a_double_lookup(synth_demo, lookups):  # noqa: F811
    """The planted violation: a validation that resolved the names, then looked the
    configuration up by name again, is counted twice."""
    from railval.db import repo

    _clear(lookups)
    with synth_demo.session() as s:
        camp, conf = repo.resolve(s, "demo", "baseline")
        validation_service.calibration_provenance(s, camp, "baseline")  # a name, not the ref
    assert len(lookups["campaign"]) == 1 and len(lookups["configuration"]) == 2


def test_page_service_resolves_each_name_once(synth_demo, lookups):  # noqa: F811
    _clear(lookups)
    res = overview_service.validation(synth_demo, "demo", "baseline", **KW)
    assert res.info["configuration"] == "baseline"
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) == 1, lookups["configuration"]


def test_many_configurations_resolve_each_name_once(synth_demo, lookups):  # noqa: F811
    _clear(lookups)
    (res,) = validation_service.validate_configurations(synth_demo, "demo", ["baseline"],
                                                        **KW).values()
    assert res.info["configuration"] == "baseline"
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) <= 1, lookups["configuration"]


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_cli_validate_resolves_each_name_once(synth_demo, lookups, capsys, json_flag):  # noqa: F811
    from railval.app.cli import main

    _clear(lookups)
    rc = main(["--db", synth_demo.url, "validate", "demo", "--config", "baseline",
               "--boot", "50", *json_flag])
    assert rc == 0 and "baseline" in capsys.readouterr().out
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) == 1, lookups["configuration"]


def test_signing_summary_resolves_each_name_once(synth_demo, lookups):  # noqa: F811
    """What a signer sees (the sign-off page, ``railval signoff create``): the verdict, the
    newest diagnosis and the sign-offs, from one resolve (it was three of each name)."""
    from railval.app.services.signoff import signing_summary

    _clear(lookups)
    with synth_demo.write_session(deferred=True) as s:
        summary = signing_summary(s, "demo", "baseline")
    assert summary["configuration"] == "baseline" and "objective" in summary
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) == 1, lookups["configuration"]
