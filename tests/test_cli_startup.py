"""The command line starts without the heavy libraries: ``railval --help``, ``railval list``
and every ``railval VERB --help`` run in a fresh interpreter without importing scipy.signal,
pandas or numba (app/cli/__init__.py, start-up; docs/app.md). An import check, not a timing."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from railval.app.cli import build_parser, main

from tests.factories import write_demo_campaign

HEAVY = ("scipy.signal", "pandas", "numba")

#: runs one command line in this interpreter, then reports what it imported
_PROBE = """
import json, sys
from railval.app.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
sys.stdout.flush()
heavy = sorted(m for m in {heavy!r} if m in sys.modules)
sys.stderr.write("\\nPROBE " + json.dumps({{"code": code, "heavy": heavy}}) + "\\n")
""".format(heavy=HEAVY)


def _probe(*argv: str) -> tuple[dict, str]:
    proc = subprocess.run([sys.executable, "-c", _PROBE, *argv], capture_output=True,
                          text=True, timeout=120)
    line = [x for x in proc.stderr.splitlines() if x.startswith("PROBE ")]
    assert line, proc.stderr
    return json.loads(line[-1][len("PROBE "):]), proc.stdout


def _verbs() -> list[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "verb")
    return sorted(sub.choices)


def test_help_imports_no_heavy_library():
    report, out = _probe("--help")
    assert report == {"code": 0, "heavy": []}
    assert "list" in out and "validate" in out


#: verbs whose help lists the values of a registry (LazyChoices), read when the help prints
LISTS_A_REGISTRY = {"metrics": "numba"}


@pytest.mark.parametrize("verb", _verbs())
def test_every_verb_help_imports_no_heavy_library(verb):
    report, out = _probe(verb, "--help")
    assert report["code"] == 0 and f"railval {verb}" in out
    if verb in LISTS_A_REGISTRY:  # the metric families listed: the registry was read
        assert LISTS_A_REGISTRY[verb] in report["heavy"] and "sprague_geers" in out
    else:
        assert report["heavy"] == [], verb


def test_list_imports_no_heavy_library(db_url, tmp_path, capsys):
    assert main(["--db", db_url, "init"]) == 0
    write_demo_campaign(tmp_path / "c", n_sections=4, fmt="csv")
    assert main(["--db", db_url, "import", str(tmp_path / "c"), "--no-progress"]) == 0
    capsys.readouterr()
    report, out = _probe("--db", db_url, "list")
    assert report == {"code": 0, "heavy": []}
    assert "demo (id" in out
    report, out = _probe("--db", db_url, "list", "--json")
    assert report == {"code": 0, "heavy": []}
    assert [c["name"] for c in json.loads(out)["campaigns"]] == ["demo"]


def test_the_probe_sees_a_heavy_import():
    """The check can fail: a verb that computes (metrics --list reads the metric registry,
    which compiles with numba) is reported."""
    report, _ = _probe("metrics", "--list")
    assert report["code"] == 0 and "numba" in report["heavy"]


def _catalogue_db(db_url, tmp_path, capsys, n_configs=2):
    assert main(["--db", db_url, "init"]) == 0
    write_demo_campaign(tmp_path / "c", n_sections=4, fmt="csv", n_configs=n_configs)
    assert main(["--db", db_url, "import", str(tmp_path / "c"), "--no-progress"]) == 0
    capsys.readouterr()


def test_list_fast_path_equals_the_ordinary_summary(db_url, tmp_path, capsys):
    """The driver-only catalogue (db.catalogue) gives what repo.campaign_summary gives, on
    both backends; `railval list --json` prints it and imports neither SQLAlchemy's ORM nor
    the models."""
    from railval.db import catalogue, repo
    from railval.db.engine import connect

    _catalogue_db(db_url, tmp_path, capsys)
    database = connect(db_url)
    with database.session() as s:
        ordinary = [repo.campaign_summary(s, c.id) for c in repo.list_campaigns(s)]
    fast = catalogue.read_catalogue(catalogue.resolve_url(db_url), None)
    assert fast is not None and fast == ordinary
    assert catalogue.safe_url(catalogue.resolve_url(db_url)) == database.safe_url
    assert catalogue.head_revision() == database.head_revision()
    database.dispose()
    probe = _PROBE.replace(repr(HEAVY), repr(HEAVY + ("sqlalchemy", "railval.db.models")))
    proc = subprocess.run([sys.executable, "-c", probe, "--db", db_url, "list", "--json"],
                          check=False, capture_output=True, text=True, timeout=120)
    report = json.loads(proc.stderr.splitlines()[-1][len("PROBE "):])
    assert report == {"code": 0, "heavy": []}, proc.stderr
    assert json.loads(proc.stdout)["campaigns"] == json.loads(json.dumps(ordinary))


def test_list_with_users_checks_the_acting_user(db_url, tmp_path, capsys):
    """With users in the database the fast path answers only for a permitted user; the
    others get the ordinary refusals (exit 2, the same messages as every verb)."""
    from railval.db import catalogue

    _catalogue_db(db_url, tmp_path, capsys, n_configs=1)
    assert main(["--db", db_url, "user", "add", "boss", "--role", "admin", "--no-password",
                 "--reason", "first admin"]) == 0
    for name, role in (("off", "engineer"), ("pan", "panelist")):
        assert main(["--db", db_url, "--as", "boss", "user", "add", name, "--role", role,
                     "--no-password", "--reason", "t"]) == 0
    assert main(["--db", db_url, "--as", "boss", "user", "disable", "off",
                 "--reason", "t"]) == 0
    capsys.readouterr()
    url = catalogue.resolve_url(db_url)
    assert catalogue.read_catalogue(url, None) is None
    assert catalogue.read_catalogue(url, "nobody") is None
    assert catalogue.read_catalogue(url, "off") is None  # disabled
    assert catalogue.read_catalogue(url, "pan") is None  # no permission to read data
    assert [c["name"] for c in catalogue.read_catalogue(url, "boss")] == ["demo"]
    assert main(["--db", db_url, "list"]) == 2
    assert "--as USER" in capsys.readouterr().err
    assert main(["--db", db_url, "--as", "off", "list"]) == 2
    assert "disabled" in capsys.readouterr().err
    assert main(["--db", db_url, "--as", "pan", "list"]) == 2
    assert "pan" in capsys.readouterr().err
    assert main(["--db", db_url, "--as", "boss", "list"]) == 0
    assert "demo (id" in capsys.readouterr().out


def test_list_falls_back_on_an_uninitialised_database(tmp_path, capsys):
    """A missing SQLite file: the ordinary path creates and migrates it as before."""
    url = f"sqlite:///{tmp_path / 'new.db'}"
    assert main(["--db", url, "list"]) == 0
    assert "no campaigns" in capsys.readouterr().out
    assert (tmp_path / "new.db").exists()
