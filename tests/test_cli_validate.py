"""``railval validate``: human table, one JSON document, exit codes."""

from __future__ import annotations

import json

import pytest

from railval.app.cli import main
from railval.app.cli.cmd_validate import BAR_CELLS, bar
from railval.core.quantities import QUANTITY_IDS
from railval.db.engine import connect
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def db_urls(tmp_path_factory):
    """Two SQLite databases: the full demo campaign (12 sections) and a short one (8)."""
    root = tmp_path_factory.mktemp("cli")
    urls = {}
    for label, n in (("full", 12), ("short", 8)):
        write_demo_campaign(root / label, n_sections=n, fs=200.0)
        url = f"sqlite:///{root / label}.db"
        database = connect(url)
        database.init()
        import_campaign(database, root / label)
        database.dispose()
        urls[label] = url
    return urls


def test_human_output(db_urls, capsys):
    assert main(["--db", db_urls["full"], "validate", "demo", "--config", "baseline",
                 "--boot", "100"]) == 0
    out = capsys.readouterr().out
    for qid in QUANTITY_IDS:
        assert f"\n{qid} " in out
    assert "sample standard deviation (n − 1)" in out
    assert "coverage: all rules met" in out
    assert out.rstrip().endswith("VALIDATED")
    assert "█" in out or "▏" in out


def test_json_document_and_not_validated_exit_code(db_urls, capsys):
    rc = main(["--db", db_urls["short"], "validate", "demo", "--config", "baseline", "--json",
               "--boot", "50", "--order", "3"])
    assert rc == 0  # not validated is not an error
    doc = json.loads(capsys.readouterr().out)
    assert doc["validated"] is False
    assert "8 sections have comparisons, needs 12" in doc["coverage"]["shortfalls"]
    assert "zone 1 has 2 sections, needs 3" in doc["coverage"]["shortfalls"]
    assert doc["info"]["filter_order"] == 3 and doc["std_ddof"] == 1
    q = {row["quantity"]: row for row in doc["quantities"]}
    assert set(q) == set(QUANTITY_IDS)
    for row in q.values():
        assert {"quantity", "n", "mean", "std", "mean_limit", "std_limit", "mean_norm",
                "std_norm", "pass"} <= set(row)


def test_human_output_lists_shortfalls(db_urls, capsys):
    assert main(["--db", db_urls["short"], "validate", "demo", "--config", "baseline",
                 "--boot", "0"]) == 0
    out = capsys.readouterr().out
    assert "coverage shortfall: zone 4 has 2 sections, needs 3" in out
    assert out.rstrip().endswith("NOT VALIDATED")


def test_errors_exit_2(db_urls, capsys):
    assert main(["--db", db_urls["full"], "validate", "demo", "--config", "nope"]) == 2
    assert "configuration 'nope' not found" in capsys.readouterr().err


def test_bar_scale():
    assert len(bar(0.0)) == BAR_CELLS + 1
    assert bar(1.0).startswith("█" * (BAR_CELLS // 2))
    assert bar(0.25)[BAR_CELLS // 2] == "│"  # limit mark visible when not reached
    assert bar(-0.5) == bar(0.5)
    assert bar(3.0).endswith("+") and bar(None).startswith("n/a")
    assert bar(0.05)[0] in "▏▎▍▌▋▊▉"  # 0.05/2·20 = 0.5 cell → half block
