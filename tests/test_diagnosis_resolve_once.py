"""A diagnosis resolves its campaign and configuration names once, at its entrance (issue 42,
docs/design.md §2): from the CLI (``railval diagnose``) and from the service the Diagnose
page's "Run diagnosis" calls (the diagnosis and the stored runs the page then lists), one
SELECT finds the campaign by its name and one the configuration by its name; everything after
takes the :class:`railval.db.repo.CampaignRef` / :class:`railval.db.repo.ConfigRef`."""

from __future__ import annotations

import re

import pytest
from sqlalchemy import event
from sqlalchemy.engine import Engine

from railval.app.services import diagnosis as diagnosis_service

#: a SELECT that finds a campaign or a configuration by its name (the bound parameter of a
#: ``name =`` condition on that table), as SQLAlchemy renders it on SQLite and PostgreSQL
_BY_NAME = {"campaign": re.compile(r"FROM campaign\b.*WHERE.*\bcampaign\.name = ", re.S),
            "configuration": re.compile(r"FROM configuration\b.*WHERE.*\bconfiguration\.name = ", re.S)}
KW = {"effects": ["conicity"], "values_per_parameter": 2, "workers": 1, "refresh": True}


@pytest.fixture
def lookups():
    """Per table, the statements that looked a row up by name, on every engine of the process
    (the CLI connects its own)."""
    seen: dict[str, list[str]] = {k: [] for k in _BY_NAME}

    def listen(_conn, _cursor, statement, *_args) -> None:
        if statement.lstrip().upper().startswith("SELECT"):
            for table, rx in _BY_NAME.items():
                if rx.search(statement):
                    seen[table].append(statement)

    event.listen(Engine, "before_cursor_execute", listen)
    yield seen
    event.remove(Engine, "before_cursor_execute", listen)


@pytest.fixture
def synth_demo(database):
    from railval.app.services.synth import synth

    synth(database, name="demo", template="coach", hidden=["conicity"], seed=1, n_sections=12)
    return database


def test_the_counter_sees_a_lookup_by_name(synth_demo, lookups):
    """The planted violation: resolving the names twice is counted twice."""
    from railval.db import repo

    for _ in range(2):
        with synth_demo.session() as s:
            repo.resolve(s, "demo", "baseline")
    assert len(lookups["campaign"]) == 2 and len(lookups["configuration"]) == 2


def test_page_service_resolves_each_name_once(synth_demo, lookups):
    res, listed = diagnosis_service.diagnose_and_list(synth_demo, "demo", "baseline", **KW)
    assert res.candidates and listed and listed[0]["id"] == res.run["id"]
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) == 1, lookups["configuration"]


def test_cli_diagnose_resolves_each_name_once(synth_demo, lookups, capsys):
    from railval.app.cli import main

    lookups["campaign"].clear()
    lookups["configuration"].clear()
    rc = main(["--db", synth_demo.url, "diagnose", "demo", "--config", "baseline", "--candidates", "conicity",
               "--values", "2", "--json"])
    assert rc == 0 and '"verdict"' in capsys.readouterr().out
    assert len(lookups["campaign"]) == 1, lookups["campaign"]
    assert len(lookups["configuration"]) == 1, lookups["configuration"]
