"""The command line starts by need: ``railval --help``, ``railval list``, every
``railval VERB --help`` and the verbs people type most (``signoff list``, ``signoff show``,
``audit verify``, ``user list``, ``validate``, ``workshop analyse``) run in a fresh interpreter
without importing scipy.signal, scipy.stats, pandas, numba or the plotting libraries, and a
command line naming a verb imports only that verb's command module (app/cli/__init__.py,
start-up by need; docs/app.md). Import checks, not timings (``railval bench startup``
times them)."""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys

import pytest

from railval.app.cli import VERBS, build_parser, chosen_verb, main

from tests.factories import write_demo_campaign

HEAVY = ("scipy.signal", "scipy.stats", "pandas", "numba", "panel", "bokeh", "holoviews",
         "matplotlib")

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


# -- start-up by need: the verbs people type most, the verb table, the deferred imports ----

#: what a listed verb must not load on an empty database: the heavy libraries, and Alembic (the
#: schema revision is read with one query; migrations import it only when they run)
NOT_AT_START = HEAVY + ("alembic", "statsmodels")

#: runs one command line, then reports the heavy modules and the command modules it imported
_VERB_PROBE = """
import json, sys
from railval.app.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
sys.stdout.flush()
loaded = {"heavy": sorted(m for m in %r if m in sys.modules),
          "cmd": sorted(m.rsplit(".", 1)[1] for m in sys.modules
                        if m.startswith("railval.app.cli.cmd_")),
          "pg_dialect": "sqlalchemy.dialects.postgresql" in sys.modules}
sys.stderr.write("\\nPROBE " + json.dumps({"code": code, **loaded}) + "\\n")
""" % (NOT_AT_START,)

#: (arguments after --db URL, exit code, a piece of the answer, the command module) on an
#: empty database: the answers are the verbs' whole work there
LISTED = {
    "signoff list": (["signoff", "list"], 0, "no sign-offs", "cmd_audit"),
    "signoff show": (["signoff", "show", "7"], 2, "sign-off 7 not found", "cmd_audit"),
    "audit verify": (["audit", "verify"], None, "0 audit rows", "cmd_audit"),
    "user list": (["user", "list"], 0, "no users", "cmd_user"),
    "validate": (["validate", "nowhere", "--config", "c"], 2, "campaign 'nowhere' not found",
                 "cmd_validate"),
    "workshop analyse": (["workshop", "analyse", "w0"], 2, "workshop 'w0' not found",
                         "cmd_workshop"),
    "list": (["list"], 0, "no campaigns", "cmd_data"),
}


def _probe_verb(url: str, argv: list[str]) -> tuple[dict, str]:
    proc = subprocess.run([sys.executable, "-c", _VERB_PROBE, "--db", url, *argv],
                          capture_output=True, text=True, timeout=180)
    line = [x for x in proc.stderr.splitlines() if x.startswith("PROBE ")]
    assert line, proc.stderr
    return json.loads(line[-1][len("PROBE "):]), proc.stdout + proc.stderr


@pytest.fixture(scope="module")
def empty_db(module_db_url):
    """An initialised database without data or users, one per backend."""
    proc = subprocess.run([sys.executable, "-m", "railval.app", "--db", module_db_url, "init"],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    return module_db_url


@pytest.mark.parametrize("label", sorted(LISTED))
def test_listed_verb_starts_by_need(empty_db, label):
    """Each listed verb answers on an empty database having imported none of the heavy
    libraries nor Alembic, and no command module but its own (the verb table)."""
    argv, code, answer, module = LISTED[label]
    report, out = _probe_verb(empty_db, argv)
    assert answer in out, out
    if code is not None:  # `audit verify` fails without a signing key on a fresh database
        assert report["code"] == code, out
    assert report["heavy"] == [], (label, report)
    assert report["cmd"] == [module], (label, report)
    if empty_db.startswith("sqlite"):  # SQLAlchemy's PostgreSQL dialect (five drivers) not
        assert not report["pg_dialect"], (label, report)


_PARTIAL_INDEX_PROBE = """
import sys
from sqlalchemy.dialects import postgresql
from sqlalchemy.schema import CreateIndex
from railval.db.models import Recording
from railval.db.engine import connect
index = next(i for i in Recording.__table__.indexes if i.name == "uq_recording_measured")
print(CreateIndex(index).compile(dialect=postgresql.dialect()))
connect(sys.argv[1])
print(CreateIndex(index).compile(dialect=postgresql.dialect()))
"""


def test_postgresql_condition_of_the_partial_index_comes_with_a_postgresql_engine():
    """The models declare only the SQLite condition of ``uq_recording_measured`` (so a start on
    SQLite does not import the PostgreSQL dialect); connecting to PostgreSQL adds its
    condition before any DDL. In a fresh interpreter the index is plain before and partial
    after (connect makes the engine; it does not need the server)."""
    proc = subprocess.run([sys.executable, "-c", _PARTIAL_INDEX_PROBE,
                           "postgresql+psycopg://nobody@127.0.0.1:1/none"],
                          capture_output=True, text=True, timeout=120, check=True)
    before, after = proc.stdout.strip().splitlines()
    assert before == "CREATE UNIQUE INDEX uq_recording_measured ON recording (section_id)"
    assert after == before + " WHERE configuration_id IS NULL"


def test_help_lists_every_verb_of_the_table():
    """``railval --help`` (no verb chosen) imports every command module and lists all verbs."""
    report, out = _probe("--help")
    assert report == {"code": 0, "heavy": []}
    for verb in VERBS:
        assert f"    {verb} " in out or f"    {verb}\n" in out, verb


def test_the_verb_table_names_every_registered_verb():
    """:data:`VERBS` holds exactly the verbs the command modules register, each with the module
    that registers it, and the parser built for one verb parses that verb."""
    sub = next(a for a in build_parser()._actions if a.dest == "verb")
    assert sorted(sub.choices) == sorted(VERBS)
    for verb, parser in sub.choices.items():
        funcs = [parser.get_default("func")]
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                funcs = [p.get_default("func") for p in action.choices.values()]
        modules = {f.__module__.rsplit(".", 1)[1] for f in funcs}
        assert modules == {VERBS[verb]}, verb
        only = next(a for a in build_parser(verb)._actions if a.dest == "verb")
        assert verb in only.choices
        assert {VERBS[v] for v in only.choices} == {VERBS[verb]}


@pytest.mark.parametrize("argv, verb", [
    (["signoff", "list"], "signoff"),
    (["--db", "sqlite:///x.db", "--as", "ann", "--debug", "user", "list"], "user"),
    (["--db=sqlite:///x.db", "--as=ann", "validate", "c", "--config", "k"], "validate"),
    (["--db", "user", "list"], "list"),  # "user" is the URL here
    (["-h", "list"], None),  # help before the verb: the full parser answers
    (["--help"], None),
    (["--d", "x", "list"], None),  # abbreviated option: argparse decides
    (["signof", "list"], None),  # unknown verb: the full parser names the choices
    ([], None),
    (["--db"], None),
])
def test_chosen_verb(argv, verb):
    assert chosen_verb(argv) == verb


def test_unknown_verb_lists_every_verb(capsys):
    with pytest.raises(SystemExit):
        main(["signof", "list"])
    err = capsys.readouterr().err
    assert "invalid choice: 'signof'" in err and "'signoff'" in err and "'workshop'" in err


def test_revision_check_reads_what_alembic_reads(db_url):
    """The start-up's schema check (one query, no Alembic import) gives Alembic's answers: no
    revision on an empty database, the head after ``init``; the head read from the scripts
    equals Alembic's ScriptDirectory head."""
    from alembic.migration import MigrationContext
    from alembic.script import ScriptDirectory

    from railval.db.engine import connect

    database = connect(db_url)
    try:
        def alembic_current():
            with database.engine.connect() as conn:
                return MigrationContext.configure(conn).get_current_revision()

        assert database.current_revision() is None and alembic_current() is None
        head = ScriptDirectory.from_config(database._alembic_config()).get_current_head()
        assert database.head_revision() == head
        database.init()
        assert database.current_revision() == alembic_current() == head
    finally:
        database.dispose()


# -- railval.core.lazy ---------------------------------------------------------------------

@pytest.fixture
def planted(tmp_path, monkeypatch):
    """A module ``startup_planted`` that counts its imports (in ``sys.startup_planted_loads``)."""
    (tmp_path / "startup_planted.py").write_text(
        "import sys\nsys.startup_planted_loads = getattr(sys, 'startup_planted_loads', 0) + 1\n"
        "def double(x):\n    return 2 * x\nVALUE = 41\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "startup_planted", raising=False)
    monkeypatch.setattr(sys, "startup_planted_loads", 0, raising=False)
    yield "startup_planted"
    sys.modules.pop("startup_planted", None)


def test_lazy_function_imports_on_first_call(planted):
    from railval.core import lazy

    double = lazy.function(planted, "double")
    assert planted not in sys.modules and sys.startup_planted_loads == 0
    assert double(21) == 42 and double(1) == 2
    assert sys.startup_planted_loads == 1 and planted in sys.modules
    clone = pickle.loads(pickle.dumps(double))  # sent to a worker process
    assert clone(5) == 10 and sys.startup_planted_loads == 1


def test_lazy_module_imports_on_first_attribute(planted):
    from railval.core import lazy

    module = lazy.module(planted)
    assert planted not in sys.modules and "not loaded" in repr(module)
    assert module.VALUE == 41 and module.double(2) == 4
    assert sys.startup_planted_loads == 1 and "(loaded)" in repr(module)


def test_lazy_import_error_surfaces_at_first_use():
    from railval.core import lazy

    missing = lazy.function("railval_no_such_module", "f")  # binding never fails
    with pytest.raises(ModuleNotFoundError, match="railval_no_such_module"):
        missing()
    with pytest.raises(ModuleNotFoundError):
        lazy.module("railval_no_such_module").anything  # noqa: B018


def test_startup_bench_times_the_verbs_against_the_baselines(capsys):
    """``railval bench startup`` runs each command in fresh processes and reports its wall
    time, the time to the verb's dispatch and function, and the heavy modules it imported,
    beside the baselines of the same rounds and the load."""
    assert main(["bench", "startup", "--repeat", "1", "--only", "list", "signoff list",
                 "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)["figures"]
    assert figures["repeat"] == 1 and figures["load_1min_before"] >= 0
    assert 0 < figures["baseline: python -c pass"]["best_s"]
    assert figures["baseline: import scipy.signal"]["best_s"] > 0
    for label in ("list", "signoff list"):
        row = figures[label]
        assert row["exit"] == 0 and row["heavy"] in ("none", "railval.db.models"), row
        assert 0 < row["to_dispatch_s"] <= row["to_verb_s"] <= row["best_s"] <= row["median_s"]
        assert 0 < row["best_cpu_s"]
    assert figures["list"]["heavy"] == "none"
    assert "validate" not in figures  # --only
    assert main(["bench", "startup", "--only", "nonsense"]) == 2
    assert "--only: unknown command(s) ['nonsense']" in capsys.readouterr().err


def test_review_plot_metrics_leave_pandas_unloaded():
    """``workshop create`` computes each plot's Sprague–Geers C with
    :mod:`railval.core.metrics.sprague_geers` on a :mod:`railval.core.metrics.grid` grid: that
    must not import pandas (≈ 0.7 s of a fresh process) through the package's ``compare``
    module, which reads pandas only for its tables; the tables still come as DataFrames."""
    code = ("import sys\n"
            "import railval.core.metrics as m\n"
            "from railval.core.metrics.grid import common_grid\n"
            "from railval.core.metrics.sprague_geers import sprague_geers\n"
            "import numpy as np\n"
            "x = np.sin(np.arange(400) / 9.0)\n"
            "sprague_geers(x, 1.1 * x)\n"
            "print('pandas' in sys.modules)\n"
            "r = m.compare(x, 1.1 * x, 200.0).to_pandas()\n"
            "print(type(r).__module__.split('.')[0], 'pandas' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "pandas", "True"]


def test_the_program_pauses_the_collector_until_the_verb_runs(tmp_path):
    """As the ``railval`` program (the benchmark's probe runs it so) the collector is off while
    the verb's modules load and its permission is checked, then the start-up's objects are
    frozen and the collector is back on for the verb's own work."""
    from railval.app.bench.bench_startup import _PROBE

    url = f"sqlite:///{tmp_path / 'gc.db'}"
    out = subprocess.run([sys.executable, "-c", _PROBE, "--db", url, "user", "list"],
                         capture_output=True, text=True, timeout=300, check=False)
    line = next((x for x in out.stderr.splitlines() if x.startswith("STARTUP ")), None)
    assert line is not None, out.stderr[-2000:]
    seen = json.loads(line[len("STARTUP "):])["collector"]
    assert seen["on_at_dispatch"] is False
    assert seen["on_at_verb"] is True
    assert seen["frozen_at_verb"] > 10_000  # SQLAlchemy's and railval's modules
    # the verb done, the process ends without the collector walking what it left
    assert seen["on_at_end"] is False
    assert seen["frozen_at_end"] > seen["frozen_at_verb"]


def test_main_called_from_python_leaves_the_collector_alone(tmp_path, monkeypatch):
    """``main(argv)`` from Python (tests, the benchmarks' own processes): no pause, no freeze."""
    import gc

    import railval.app.cli as cli

    seen = {}
    real = cli.authorize

    def spy(args):
        seen["on"] = gc.isenabled()
        return real(args)
    monkeypatch.setattr(cli, "authorize", spy)
    frozen = gc.get_freeze_count()
    assert main(["--db", f"sqlite:///{tmp_path / 'gc.db'}", "user", "list"]) == 0
    assert seen == {"on": True}
    assert gc.isenabled() and gc.get_freeze_count() == frozen
