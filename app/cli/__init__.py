"""The ``railval`` command line.

Every verb lives in its own module ``app/cli/cmd_<group>.py`` exposing
``register(subparsers) -> None``; it adds one or more sub-parsers and sets
``func=callable(args) -> int`` on each. This module only discovers the verbs, adds the global
options and dispatches. Global options: ``--db URL`` (else ``$RAILVAL_DB``, else the embedded
SQLite file ``railval.db`` in the working directory).

Start-up by need. :data:`VERBS` maps every verb to the module that registers it; a command
line naming a verb imports that one module (:func:`chosen_verb`, :func:`build_parser`), and
only ``railval --help``, a bare ``railval`` or an unknown verb imports them all (to list them
with their help). A module's top level and its ``register`` import only the standard library
and light railval modules; a verb imports what it computes with (the services, the database
layer) inside its function, when it runs, and the services defer scipy.signal, scipy.stats,
pandas, numba and the plotting libraries until the work reaches them
(:mod:`railval.core.lazy`, :mod:`railval.core.processing`). A registration that needs a
registry of a heavy module (argparse ``choices``) passes :class:`LazyChoices`, which reads the
registry only when that verb's arguments are parsed or its help is printed.
tests/test_cli_startup.py checks this in a fresh interpreter for every verb and that the table
names every registered verb; ``railval bench startup`` times it (docs/app.md, command-line
start-up).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import json
import logging
import os
import pkgutil
import sys
import time
import traceback

from railval.core import lazy
from railval.core.errors import RailvalError

#: deferred (railval.core.lazy): ``railval --help`` loads this module alone; the database
#: services, the roles table and the user check only once a verb is dispatched
database_message = lazy.function("railval.app.security", "database_message")
db_service = lazy.module("railval.app.services.database")
roles = lazy.module("railval.core.roles")
np = lazy.module("numpy")  # a --json document with numpy values
getpass = lazy.module("getpass")  # the OS user, once a verb is authorised (not for `list`)
sa_exc = lazy.module("sqlalchemy.exc")  # a database error turned into its message
check_cli = lazy.function("railval.app.services.users", "check_cli")


#: every verb → the module of app/cli whose ``register`` adds it; a command line naming a verb
#: imports only that module (tests/test_cli_startup.py checks the table against the modules)
VERBS: dict[str, str] = {
    "serve": "cmd_app", "report": "cmd_app", "nginx-static": "cmd_app",
    "audit": "cmd_audit", "signoff": "cmd_audit",
    "backup": "cmd_backup", "restore": "cmd_backup",
    "bench": "cmd_bench",
    "init": "cmd_data", "import": "cmd_data", "export": "cmd_data", "verify": "cmd_data",
    "list": "cmd_data",
    "diagnose": "cmd_diagnose", "calibrate": "cmd_diagnose", "modal": "cmd_diagnose",
    "metrics": "cmd_metrics",
    "simulate": "cmd_sim", "synth": "cmd_sim",
    "user": "cmd_user",
    "validate": "cmd_validate",
    "workshop": "cmd_workshop",
}
#: the global options that take a value (``--db URL``, ``--as USER``) and the one that takes none
_VALUE_OPTIONS = ("--db", "--as")
_FLAG_OPTIONS = ("--debug",)


def chosen_verb(argv: list[str]) -> str | None:
    """The verb of a command line when it can be told without argparse: the first word after
    the global options, if it is in :data:`VERBS`. None for help (``-h`` before the verb), an
    abbreviated or unknown option, an unknown verb or no verb: the full parser answers those."""
    i = 0
    while i < len(argv):
        word = argv[i]
        if word in _VALUE_OPTIONS:
            i += 2
        elif word in _FLAG_OPTIONS or ("=" in word and word.split("=", 1)[0] in _VALUE_OPTIONS):
            i += 1
        elif word.startswith("-"):
            return None
        else:
            return word if word in VERBS else None
    return None


def build_parser(verb: str | None = None) -> argparse.ArgumentParser:
    """The parser of the command line: with ``verb`` (a key of :data:`VERBS`) it holds the
    verbs of that verb's module only, else every module's verbs."""
    parser = argparse.ArgumentParser(
        prog="railval",
        description="Validate railway vehicle simulation models against on-track measurements.",
    )
    parser.add_argument(
        "--db",
        metavar="URL",
        default=None,
        help="database URL (sqlite:///file.db or postgresql+psycopg://...); default $RAILVAL_DB "
        "or sqlite:///railval.db",
    )
    parser.add_argument(
        "--as", dest="as_user", metavar="USER", default=None,
        help="the user you act as when the database holds users (default $RAILVAL_USER); "
        "the verb needs a role of that user (docs/security.md)",
    )
    parser.add_argument("--debug", action="store_true",
                        help="print the traceback of an error (also RAILVAL_DEBUG=1)")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    if verb is not None:
        importlib.import_module(f"{__name__}.{VERBS[verb]}").register(sub)
        return parser
    package = importlib.import_module(__name__)
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            module = importlib.import_module(f"{__name__}.{info.name}")
            module.register(sub)
    return parser


class LazyChoices:
    """argparse ``choices`` taken from a registry on first use (``loader()`` returns the
    allowed values). Give the argument a ``metavar`` (argparse builds the default metavar from
    the choices when the argument is added); ``%(choices)s`` in its help lists the values when
    the help is printed."""

    def __init__(self, loader):
        self._loader = loader
        self._values: list | None = None

    def _get(self) -> list:
        if self._values is None:
            self._values = list(self._loader())
        return self._values

    def __contains__(self, value: object) -> bool:
        return value in self._get()

    def __iter__(self):
        return iter(self._get())

    def __len__(self) -> int:
        return len(self._get())


def emit_json(document: object) -> None:
    """Print one JSON document on stdout (the ``--json`` contract of docs/design.md §8)."""
    json.dump(document, sys.stdout, indent=2, default=_json_default, allow_nan=False)
    sys.stdout.write("\n")


def _json_default(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


class Progress:
    """Progress of a long verb on stderr: ``progress(stage, fraction, info)``.

    On a terminal one bar redrawn in place (``\\r``); otherwise (a log file, a pipe, CI) one
    plain line when the stage changes and at most every ``interval_s`` seconds, never a
    carriage return.
    """

    def __init__(self, interval_s: float = 5.0, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.interval_s = interval_s
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last = float("-inf")
        self._stage: str | None = None

    def __call__(self, stage: str, fraction: float, info: dict | None = None) -> None:
        info = info or {}
        extra = ""
        if "best" in info:
            extra = f" best objective {info['best']:.4g}"
        elif "done" in info and "total" in info:
            extra = f" {info['done']}/{info['total']}"
        if self.tty:
            width = 30
            filled = round(width * fraction)
            print(f"\r[{'#' * filled}{'.' * (width - filled)}] {fraction * 100:5.1f} % "
                  f"{stage}{extra}   ", end="\n" if fraction >= 1.0 else "", file=self.stream,
                  flush=True)
            return
        now = time.monotonic()
        if stage != self._stage or fraction >= 1.0 or now - self._last >= self.interval_s:
            print(f"[{fraction * 100:5.1f} %] {stage}{extra}", file=self.stream, flush=True)
            self._last, self._stage = now, stage


def _database_message(exc: Exception) -> str:
    return database_message(exc)


def verb_name(args: argparse.Namespace) -> str:
    """``VERB`` or ``VERB SUBVERB`` as in :data:`railval.core.roles.CLI_ACTIONS`."""
    sub = getattr(args, "subverb", None)
    return f"{args.verb} {sub}" if sub else args.verb


def authorize(args: argparse.Namespace) -> None:
    """Check the verb's action for the acting user when the database holds users.

    The acting user is ``--as`` (else ``$RAILVAL_USER``); audit rows written by the verb name
    them. Without users (a fresh or single-user database) every verb runs and the audit
    trail names ``cli:<OS user>``. While no enabled user holds ``admin``, ``user add NAME
    --role admin`` runs for whoever can write the database (:func:`first_admin`), so no
    sequence of verbs leaves a database nobody can administer.
    """
    if getattr(args, "authorizes_itself", False):  # `list`: checked in its verb (cmd_list)
        return
    verb = verb_name(args)
    action = roles.CLI_ACTIONS[verb]
    who = args.as_user or os.environ.get("RAILVAL_USER")
    db_service.set_default_actor(who or f"cli:{getpass.getuser()}")
    if action is None or getattr(args, "bundle", None):  # a bundle is checked without the database
        return
    database = db_service.open_database(args.db, upgrade=None)
    try:
        if database.current_revision() is None or not db_service.has_user_table(database):
            return

        # while nobody can manage users (e.g. open-mode `workshop import-answers` created
        # panelists), whoever runs the CLI on the database may add the first admin
        if check_cli(database, who, action, verb, adds_admin=first_admin(args)).first_admin \
                and not args.reason:
            args.reason = "first admin: the database had users but no enabled admin"
    finally:
        database.dispose()


def first_admin(args: argparse.Namespace) -> bool:
    """``user add NAME --role admin …``: allowed without ``--as`` while the database has no
    enabled admin (the README's first step; also after open-mode verbs created users)."""
    return verb_name(args) == "user add" and "admin" in (getattr(args, "role", None) or [])


def ending_without_collection() -> None:
    """The verb has finished and the process is about to end: turn the cyclic collector off
    and freeze what is alive, so that the interpreter's last collections at exit walk nothing
    (the memory goes back to the system with the process). After a workshop's creation that
    walk took ≈ 0.4 s of a 4.2 s command (docs/app.md "Command-line start-up"). Reference
    counting still frees objects as the modules are torn down; only objects in reference
    cycles keep their finalizers unrun, which Python never promised at exit."""
    gc.disable()
    gc.freeze()


def main(argv: list[str] | None = None) -> int:
    """Run one verb. Errors print one line ``railval VERB: error: …`` on stderr (exit 2 for
    bad input, 1 for anything else); ``--debug`` (or ``RAILVAL_DEBUG=1``) adds the
    traceback. Output piped into a reader that stops early (``| head``) ends quietly.

    Called as the program (``argv`` not given: the ``railval`` command, ``python -m
    railval.app``), the cyclic garbage collector pauses while the verb's modules are imported
    and its permission checked, and what is alive then is frozen (``gc.freeze``: modules and
    classes, kept for the whole process) before the verb runs with the collector back on: the
    full collections the imports' many allocations set off cost ≈ 10 % of the start-up
    (docs/app.md, "Start-up by need"), and the verb's own later collections no longer walk the
    modules. Called with ``argv`` (tests, the benchmarks' own processes) nothing changes."""
    program = argv is None
    if program:
        gc.disable()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(chosen_verb(argv))
    args = parser.parse_args(argv)
    debug = bool(args.debug) or os.environ.get("RAILVAL_DEBUG") == "1"
    if debug:
        logging.basicConfig(level=logging.INFO, stream=sys.stderr)
    code = 1
    try:
        authorize(args)
        if program:
            gc.freeze()
            gc.enable()
        code = int(args.func(args) or 0)
        sys.stdout.flush()
        if program:
            ending_without_collection()
        return code
    except BrokenPipeError:
        # the reader of stdout went away: send the rest of the output nowhere, no traceback
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return code
    except KeyboardInterrupt:
        print(f"railval {verb_name(args)}: interrupted", file=sys.stderr)
        return 130
    except RailvalError as exc:
        error, message, code = exc, str(exc), 2
    except Exception as exc:  # noqa: BLE001 - the one place that turns any error into a message
        error = exc
        if isinstance(exc, sa_exc.SQLAlchemyError):
            message = _database_message(exc)
        elif isinstance(exc, OSError) and exc.strerror:
            message = f"{exc.strerror}" + (f": {exc.filename}" if exc.filename else "")
        else:
            message = (f"internal error ({type(exc).__name__}); run `railval --debug "
                       f"{verb_name(args)} …` for the details")
        code = 1
    if debug:
        traceback.print_exception(error, file=sys.stderr)
    print(f"railval {verb_name(args)}: error: {message}", file=sys.stderr)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
