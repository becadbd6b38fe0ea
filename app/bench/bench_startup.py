"""CLI start-up: wall time of the verbs people type most, each in a fresh interpreter.

Every command runs ``--repeat`` times in a new process (``python -c PROBE railval-args``, the
entry point's ``main`` with a timer around the chosen verb's function); the commands take turns
in each round, so a change in the machine's load falls on all of them alike, and the best and
the median are reported. Per command:

* ``best_s`` / ``median_s``: from the process's spawn to its exit (what a user waits for);
* ``best_cpu_s``: the process's CPU time (user + system), which the other jobs of a shared
  machine change far less than the wall time;
* ``to_dispatch_s``: from the spawn to the verb's dispatch (the interpreter, the parser and the
  verb's command module loaded, arguments parsed) — the command line's own start-up;
* ``to_verb_s``: from the spawn to the call of the verb's own function, after the permission
  check (which opens the database through SQLAlchemy);
* ``heavy``: which of the heavy libraries (scipy.signal, scipy.stats, pandas, numba, the
  plotting libraries, Alembic, statsmodels, SQLAlchemy's ORM models) the command imported;
* ``modules``: how many modules the process had loaded at its exit (the probe's own included:
  compare counts of one version against another, not against other probes).
* ``collector_paused``: whether the cyclic garbage collector was off during the permission
  check and back on, with the start-up's objects frozen, when the verb ran (the program's
  start-up, :func:`railval.app.cli.main`).

Baselines timed in the same rounds: ``python -c pass`` (the interpreter with this
environment's site packages), ``import sqlalchemy.orm and railval.db.models`` (the floor of a
verb that reads the database through the ORM) and ``import scipy.signal`` (what a verb paid
when a service imported the filters at its top). The 1-minute load average is printed before
and after: on a shared machine compare figures taken at a similar load.

Bytecode: with ``PYTHONDONTWRITEBYTECODE`` set (as in the development shells here) Python
writes no ``.pyc`` for railval's own modules, so every start compiles them from source (the
site packages were compiled at install); ``--bytecode cached`` unsets it for the timed
processes after one warm-up run, which is what an installed railval does. The report names the
mode (``bytecode``).

The database is a fresh, empty SQLite file made by ``railval init`` (untimed) unless
``railval --db URL bench startup`` names one. Goal (docs/app.md, command-line start-up):
every listed verb reaches its own work within 0.3 s of launch on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from railval.core.errors import InvalidParameter

#: the libraries a verb must not load unless its work needs them
HEAVY = ("scipy.signal", "scipy.stats", "pandas", "numba", "panel", "bokeh", "holoviews",
         "matplotlib", "statsmodels", "alembic", "railval.db.models")

#: label → railval arguments after ``--db URL`` (an empty database: the error answers of
#: ``signoff show``, ``validate`` and ``workshop analyse`` are their whole work there)
COMMANDS: dict[str, list[str]] = {
    "--help": ["--help"],
    "list": ["list"],
    "signoff list": ["signoff", "list"],
    "signoff show": ["signoff", "show", "1"],
    "audit verify": ["audit", "verify"],
    "user list": ["user", "list"],
    "validate": ["validate", "bench-campaign", "--config", "c0"],
    "workshop analyse": ["workshop", "analyse", "bench-workshop"],
}

BASELINES: dict[str, str] = {
    "python -c pass": "pass",
    "import sqlalchemy.orm, railval.db.models": "import sqlalchemy.orm, railval.db.models",
    "import scipy.signal": "import scipy.signal",
}

#: runs ``railval ARGS`` as the entry point does, marking when the verb's function is called
_PROBE = """
import gc, json, sys, time
import railval.app.cli as cli
marks = {}
collector = {}
_build = cli.build_parser
def build(verb=None):
    parser = _build(verb)
    parse = parser.parse_args
    def parse_args(argv=None):
        args = parse(argv)
        func = args.func
        def timed(a):
            marks["verb"] = time.time()
            collector.update(on_at_verb=gc.isenabled(), frozen_at_verb=gc.get_freeze_count())
            return func(a)
        args.func = timed
        return args
    parser.parse_args = parse_args
    return parser
cli.build_parser = build
_authorize = cli.authorize
def authorize(args):
    marks["dispatch"] = time.time()
    collector["on_at_dispatch"] = gc.isenabled()
    return _authorize(args)
cli.authorize = authorize
try:
    code = cli.main()  # as the program: argv from sys.argv
except SystemExit as exc:
    code = exc.code
collector.update(on_at_end=gc.isenabled(), frozen_at_end=gc.get_freeze_count())
sys.stdout.flush()
heavy = [m for m in %r if m in sys.modules]
sys.stderr.write("\\nSTARTUP " + json.dumps({"code": code, "marks": marks, "heavy": heavy,
                                            "modules": len(sys.modules), "collector": collector}) + "\\n")
""" % (HEAVY,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeat", type=int, default=7,
                        help="fresh processes per command, best and median reported (default 7)")
    parser.add_argument("--only", nargs="+", default=None, metavar="LABEL",
                        help=f"time only these commands (of: {', '.join(COMMANDS)})")
    parser.add_argument("--bytecode", choices=("env", "cached"), default="env",
                        help="env: as the environment says (PYTHONDONTWRITEBYTECODE); cached: "
                             "railval's modules compiled once to .pyc before timing")


def _run(argv: list[str], env: dict, probe: bool) -> tuple[tuple[float, float], dict | None]:
    """(wall, CPU) time of one fresh process and, for a railval command (``probe``), its
    report."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    spawned = time.time()
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=300)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    lines = [x for x in proc.stderr.splitlines() if x.startswith("STARTUP ")]
    if probe:
        if not lines:
            raise RuntimeError(f"`railval {' '.join(argv[3:])}` gave no report: "
                               f"{proc.stderr[-500:]}")
        report = json.loads(lines[-1][len("STARTUP "):])
        for mark in ("dispatch", "verb"):
            at = report["marks"].get(mark)
            report[f"to_{mark}"] = None if at is None else at - spawned
        return (wall, cpu), report
    if proc.returncode != 0:
        raise RuntimeError(f"baseline {argv[2]!r} failed: {proc.stderr[-500:]}")
    return (wall, cpu), None


def _initialise(url: str, env: dict) -> None:
    proc = subprocess.run([sys.executable, "-m", "railval.app", "--db", url, "init"],
                          capture_output=True, text=True, env=env, timeout=300)
    if proc.returncode != 0:
        raise RuntimeError(f"railval init {url}: {proc.stderr[-500:]}")


def _summary(times: list[tuple[float, float]], reports: list[dict]) -> dict:
    walls = [w for w, _ in times]
    out = {"best_s": round(min(walls), 3), "median_s": round(statistics.median(walls), 3),
           "best_cpu_s": round(min(c for _, c in times), 3)}
    if reports:
        for mark in ("dispatch", "verb"):
            at = [r[f"to_{mark}"] for r in reports if r[f"to_{mark}"] is not None]
            out[f"to_{mark}_s"] = round(min(at), 3) if at else "n/a (help printed)"
        out["exit"] = reports[-1]["code"]
        out["heavy"] = ", ".join(reports[-1]["heavy"]) or "none"
        out["modules"] = reports[-1].get("modules")
        col = reports[-1].get("collector") or {}
        # off while the verb's modules loaded, on with the start-up frozen when it ran
        out["collector_paused"] = ("n/a (help printed)" if "on_at_verb" not in col else
                                   col.get("on_at_dispatch") is False and col["on_at_verb"]
                                   and col.get("frozen_at_verb", 0) > 0)
    return out


def run(args: argparse.Namespace) -> dict:
    if args.repeat < 1:
        raise InvalidParameter(f"--repeat must be at least 1, got {args.repeat}")
    labels = args.only or list(COMMANDS)
    unknown = [x for x in labels if x not in COMMANDS]
    if unknown:
        raise InvalidParameter(f"--only: unknown command(s) {unknown}; known: {list(COMMANDS)}")
    drop = {"RAILVAL_DEBUG"}
    if args.bytecode == "cached":
        drop.add("PYTHONDONTWRITEBYTECODE")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    bytecode = ("compiled at every start (PYTHONDONTWRITEBYTECODE)"
                if env.get("PYTHONDONTWRITEBYTECODE") else "cached .pyc")
    with tempfile.TemporaryDirectory(prefix="railval-startup-") as tmp:
        url = args.db or f"sqlite:///{Path(tmp) / 'empty.db'}"
        if not args.db:
            _initialise(url, env)
        jobs = {**{f"baseline: {k}": ([sys.executable, "-c", v], False)
                   for k, v in BASELINES.items()},
                **{k: ([sys.executable, "-c", _PROBE, "--db", url, *COMMANDS[k]], True)
                   for k in labels}}
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in jobs}
        reports: dict[str, list[dict]] = {k: [] for k in jobs}
        if args.bytecode == "cached":  # one untimed run of each writes the .pyc files
            for argv, _probe in jobs.values():
                subprocess.run(argv, capture_output=True, env=env, timeout=300, check=False)
        load_before = os.getloadavg()[0]
        for _ in range(args.repeat):  # the commands take turns in every round
            for label, (argv, probe) in jobs.items():
                measured, report = _run(argv, env, probe)
                times[label].append(measured)
                if report is not None:
                    reports[label].append(report)
        load_after = os.getloadavg()[0]
    return {"load_1min_before": round(load_before, 2), "load_1min_after": round(load_after, 2),
            "cpus": os.cpu_count(), "repeat": args.repeat, "bytecode": bytecode,
            "database": "empty SQLite (railval init)" if not args.db else "--db",
            **{label: _summary(times[label], reports[label]) for label in jobs}}
