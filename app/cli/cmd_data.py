"""CLI verbs for the data: ``init``, ``import``, ``export``, ``list``.

``railval init``
    create or upgrade the database schema to the newest revision (idempotent).
``railval import DIR [--json]``
    validate the campaign folder DIR completely, then store it in one transaction
    (progress on stderr for imports of more than a few files).
``railval import DIR --into CAMPAIGN``
    add a configuration's simulated files (DIR holds ``configuration.json``: one entry of
    campaign.json's ``configurations``) to a stored campaign, with the same checks.
``railval export NAME DIR [--format parquet|csv|h5|mat|mf4|tdms]``
    write a stored campaign as a campaign folder (re-importable, identical hashes).
``railval list [--json]``
    the campaigns with their sections, zones and configurations.
``railval verify [--no-blobs] [--json]``
    check every signal's content hash and seal and every cached result's seal
    (exit 3 when something is not intact).
"""

from __future__ import annotations

import argparse
import time
import os

from railval.app.cli import Progress, authorize, emit_json
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
campaign_data_service = lazy.module("railval.app.services.campaign_data")
catalogue_service = lazy.module("railval.app.services.catalogue")
database_service = lazy.module("railval.app.services.database")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("init", help="create or upgrade the database schema")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_init)

    p = sub.add_parser("import", help="import a campaign folder (validated before writing)")
    p.add_argument("folder", metavar="DIR", help="campaign folder holding campaign.json (or, "
                   "with --into, a configuration folder holding configuration.json)")
    p.add_argument("--into", metavar="CAMPAIGN", default=None,
                   help="add a configuration's simulated files to this stored campaign")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("export", help="export a campaign as a campaign folder")
    p.add_argument("name", metavar="NAME", help="campaign name or id")
    p.add_argument("folder", metavar="DIR", help="output folder (new or empty)")
    p.add_argument("--format", default="parquet",
                   choices=["parquet", "csv", "h5", "mat", "mf4", "tdms"],
                   help="data file format (default parquet)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("verify", help="check every stored signal and cached result against "
                       "its content hash and seal",
                       description="Check the whole database: every signal's and distance "
                       "axis's SHA-256 content hash, every signal's seal and every result-cache "
                       "entry's seal (HMAC-SHA256 with the server secret; docs/database.md, "
                       "Integrity). Exit code 0 when everything is intact, 3 when problems "
                       "were found.")
    p.add_argument("--no-blobs", action="store_true",
                   help="check the seals only, without decoding the samples (faster)")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.set_defaults(func=cmd_verify)

    p = sub.add_parser("list", help="list campaigns with sections, zones and configurations")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.set_defaults(func=cmd_list, authorizes_itself=True)


def _database(args: argparse.Namespace, *, upgrade: bool = True):
    return database_service.open_database(args.db, upgrade=upgrade)


def cmd_init(args: argparse.Namespace) -> int:
    doc = database_service.initialise(args.db)
    if args.json:
        emit_json(doc)
    else:
        state = "already at" if doc["previous_revision"] == doc["revision"] else "migrated to"
        print(f"{doc['database']}: {state} revision {doc['revision']}")
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    database = _database(args)
    bar = Progress()

    def progress(done: int, total: int, what: str) -> None:
        if args.no_progress or total < 4:
            return
        bar("reading", done / total, {"done": done, "total": total})

    t = time.perf_counter()
    if args.into:
        conf = campaign_data_service.import_configuration_folder(database, args.into, args.folder,
                                                         progress=progress)
        doc = {"campaign": args.into, "configuration": conf,
               "seconds": round(time.perf_counter() - t, 3)}
        if args.json:
            emit_json(doc)
        else:
            print(f"imported configuration {conf!r} into campaign {args.into!r} in "
                  f"{doc['seconds']:.1f} s")
        return 0
    name = campaign_data_service.import_folder(database, args.folder, progress=progress)
    elapsed = time.perf_counter() - t
    doc = _summary(database, name)
    doc["seconds"] = round(elapsed, 3)
    if args.json:
        emit_json(doc)
    else:
        print(f"imported campaign {name!r}: {doc['n_sections']} sections (zones "
              f"{_zones_text(doc['zones'])}), {len(doc['configurations'])} configuration(s), "
              f"{doc['n_signals']} signals in {elapsed:.1f} s")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    path = campaign_data_service.export(_database(args, upgrade=False), args.name, args.folder, fmt=args.format)
    if args.json:
        emit_json({"campaign": args.name, "manifest": str(path), "format": args.format})
    else:
        print(f"exported {args.name!r} to {path.parent} ({args.format})")
    return 0


def _summary(database, name_or_campaign) -> dict:
    return campaign_data_service.summary(database, name_or_campaign)


def _zones_text(zones: dict[str, int]) -> str:
    return ", ".join(f"{z}: {n}" for z, n in zones.items()) or "none"


def cmd_list(args: argparse.Namespace) -> int:
    """The catalogue, read with the database driver alone when the case is plain
    (:mod:`railval.app.services.catalogue`: no SQLAlchemy, ORM or migrations imported), else
    through the ordinary path: :func:`railval.app.cli.authorize` (skipped by ``main`` for this
    verb, ``authorizes_itself``), migrations, the ORM's campaign summaries."""
    docs, safe_url = catalogue_service.fast(args.db, args.as_user or os.environ.get("RAILVAL_USER"))
    if docs is None:
        args.authorizes_itself = False
        authorize(args)
        database = _database(args)
        docs = catalogue_service.summaries(database)
        safe_url = database.safe_url
    if args.json:
        emit_json({"database": safe_url, "campaigns": docs})
        return 0
    if not docs:
        print(f"{safe_url}: no campaigns (import one with `railval import DIR`)")
        return 0
    for d in docs:
        lineage = ", ".join(x["name"] + (f" ← {x['parent']}" if x["parent"] else "")
                            for x in d["configurations"]) or "none"
        print(f"{d['name']} (id {d['id']}): {d['n_sections']} sections, zones "
              f"{_zones_text(d['zones'])}; vehicle {d['vehicle']['name'] or d['vehicle']['kind']} "
              f"Q0 {d['vehicle']['Q0_kN']:g} kN; configurations: {lineage}")
    return 0


def cmd_verify(args: argparse.Namespace) -> int:
    database = _database(args, upgrade=False)
    t = time.perf_counter()
    doc = campaign_data_service.verify(database, blobs=not args.no_blobs)
    doc["seconds"] = round(time.perf_counter() - t, 3)
    doc["database"] = database.safe_url
    if args.json:
        emit_json(doc)
        return 0 if doc["ok"] else 3
    n_problems = sum(len(v) for v in doc["campaigns"].values())
    for name, problems in doc["campaigns"].items():
        for p in problems:
            source = (f"configuration {p['configuration']!r}" if p["configuration"]
                      else "measurement")
            print(f"{name}: section {p['section']}, {source}, {p['channel']}: {p['error']}")
    for key in doc["cache_unauthentic"]:
        print(f"result cache entry {key}: fails its seal (never used; recomputed when needed)")
    print(f"{database.safe_url}: {doc['signals']} signals in {len(doc['campaigns'])} "
          f"campaign(s), {doc['cache_entries']} cached results checked in {doc['seconds']:.1f} s: "
          + ("intact" if doc["ok"] else f"{n_problems} signal problem(s), "
             f"{len(doc['cache_unauthentic'])} unauthentic cache entr(ies)"))
    return 0 if doc["ok"] else 3
