"""CLI verbs ``backup`` and ``restore`` (docs/database.md, "Backup and restore").

``railval backup DIR [--json]``
    write a backup of the database (``--db``) into the new or empty folder DIR: SQLite through
    the online backup API, PostgreSQL through ``pg_dump --format=custom``, with the seal
    secret (``secret.key``) and ``backup.json``. Safe while ``railval serve`` runs.
``railval restore DIR [--json]``
    restore the backup in DIR into the empty database ``--db`` of the same backend, install
    its seal secret, migrate to the newest schema; ``railval verify`` and ``railval audit
    verify`` then pass and sign-offs are as valid as they were.
"""

from __future__ import annotations

import argparse

from railval.app.cli import emit_json
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
database_service = lazy.module("railval.app.services.database")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("backup", help="back up the database with its seal secret (online)")
    p.add_argument("folder", metavar="DIR", help="new or empty backup folder (keep it private)")
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")
    p.set_defaults(func=cmd_backup)
    p = sub.add_parser("restore", help="restore a backup into an empty database")
    p.add_argument("folder", metavar="DIR", help="backup folder written by `railval backup`")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_restore)


def cmd_backup(args: argparse.Namespace) -> int:
    doc = database_service.backup(args.db, args.folder)
    if args.json:
        emit_json(doc)
    else:
        print(f"backup of {doc['source']} (revision {doc['revision']}, {doc['signals']} signals, "
              f"audit head {doc['audit_head']['seq']}) written to {args.folder}")
    return 0


def cmd_restore(args: argparse.Namespace) -> int:
    doc = database_service.restore(args.db, args.folder)
    if args.json:
        emit_json(doc)
    else:
        print(f"restored {args.folder} into {doc['database']} (revision {doc['revision']}, "
              f"{doc['signals']} signals, audit head {doc['audit_head']['seq']}; seal secret "
              f"{doc['secret']})")
    return 0
