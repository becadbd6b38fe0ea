"""The ``railval`` command line.

Every verb lives in its own module ``app/cli/cmd_<group>.py`` exposing
``register(subparsers) -> None``; it adds one or more sub-parsers and sets
``func=callable(args) -> int`` on each. This module only discovers the verbs, adds the global
options and dispatches. Global options: ``--db URL`` (else ``$RAILVAL_DB``, else the embedded
SQLite file ``railval.db`` in the working directory).
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys

from railval.core.errors import RailvalError


def build_parser() -> argparse.ArgumentParser:
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
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    package = importlib.import_module(__name__)
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            module = importlib.import_module(f"{__name__}.{info.name}")
            module.register(sub)
    return parser


def emit_json(document: object) -> None:
    """Print one JSON document on stdout (the ``--json`` contract of docs/design.md §8)."""
    json.dump(document, sys.stdout, indent=2, default=_json_default, allow_nan=False)
    sys.stdout.write("\n")


def _json_default(value: object) -> object:
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def verb_name(args: argparse.Namespace) -> str:
    """``VERB`` or ``VERB SUBVERB`` as in :data:`railval.core.roles.CLI_ACTIONS`."""
    sub = getattr(args, "subverb", None)
    return f"{args.verb} {sub}" if sub else args.verb


def authorize(args: argparse.Namespace) -> None:
    """Check the verb's action for the acting user when the database holds users.

    The acting user is ``--as`` (else ``$RAILVAL_USER``); audit rows written by the verb name
    them. Without users (a fresh or single-user database) every verb runs and the audit
    trail names ``cli:<OS user>``.
    """
    import getpass
    import os

    from railval.core.roles import CLI_ACTIONS, require
    from railval.db import engine

    verb = verb_name(args)
    action = CLI_ACTIONS[verb]
    who = args.as_user or os.environ.get("RAILVAL_USER")
    engine.default_actor = who or f"cli:{getpass.getuser()}"
    if action is None or getattr(args, "bundle", None):  # a bundle is checked without the database
        return
    from railval.db import users

    database = engine.connect(args.db)
    try:
        if database.current_revision() is None or not _has_user_table(database):
            return
        with database.session() as s:
            if not users.has_users(s):
                return
            if not who:
                raise RailvalError(
                    f"this database has users: name the user you act as with --as USER or "
                    f"RAILVAL_USER (`{verb}` needs the permission to {action})")
            user = users.find_user(s, who)
            if user is None:
                raise RailvalError(f"--as {who!r}: no such user in {database.safe_url}")
            if user.disabled:
                raise RailvalError(f"--as {who!r}: this account is disabled")
            require(users.principal(user), action)
    finally:
        database.dispose()


def _has_user_table(database) -> bool:
    from sqlalchemy import inspect

    return "app_user" in inspect(database.engine).get_table_names()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        authorize(args)
        return int(args.func(args) or 0)
    except RailvalError as exc:
        print(f"railval {verb_name(args)}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
