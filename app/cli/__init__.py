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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except RailvalError as exc:
        print(f"railval {args.verb}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
