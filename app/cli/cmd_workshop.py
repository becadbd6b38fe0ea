"""CLI verbs ``workshop …`` — expert review workshops (docs/workshops.md).

``railval workshop create NAME --campaign C [--configurations …] [--sections …] [--kinds …]
[--scaling zone|workshop] [--blind] [--repeats 0.1] [--auto-share 0] [--twin-scaling auto|zone|workshop]
[--seed 0] [--dry-run] [--json]``
    build the plot set, render every plot once and store it (``--dry-run``: only count);
    ``--json`` reports per kind ``flat_share``, the share of plots whose filtered signal
    spans less than 10 % of its y range. Progress (plots rendered n/N) goes to stderr, with
    and without ``--json``.
``railval workshop kinds [--json]``          the plot kinds (registry).
``railval workshop plots NAME --json``       ``plots``: id, kind, section, configuration,
                                             channel, deviation, image_sha256 (and sg_c,
                                             scaling, twin).
``railval workshop invite NAME --reviewer R [--base-url URL]``  a personal review link for
                                             the panelist R (user name; a new one gets the role
                                             panelist, without password).
``railval workshop status NAME [--json]``    progress per panelist.
``railval workshop close|reopen NAME``
``railval workshop import-answers NAME FILE.csv`` / ``export NAME FILE.csv``
``railval workshop analyse NAME --json``
``railval workshop cards NAME [--groups W2 …] --json``  the plot cards (EN values of measurement and
                                             simulation, shares of Yes per reviewer group,
                                             Sprague–Geers M, P, C, deviation).

Permissions (:data:`railval.core.roles.CLI_ACTIONS`) are checked for the user named by
``railval --as USER`` once the database has users; every change is recorded in the audit
trail under that name.
"""

from __future__ import annotations

import argparse
import sys

from railval.app.cli import Progress, emit_json
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
core_workshop = lazy.module("railval.core.workshop")
database_service = lazy.module("railval.app.services.database")
workshop_admin_service = lazy.module("railval.app.services.workshop_admin")
workshop_cards_service = lazy.module("railval.app.services.workshop_cards")
workshops_service = lazy.module("railval.app.services.workshops")
workshop_answers_service = lazy.module("railval.app.services.workshop_answers")


def _actor() -> str:
    """The acting user of this command (``--as`` / ``$RAILVAL_USER``, checked by the CLI),
    else ``cli:<OS user>``: the name in the audit trail."""
    return database_service.default_actor()


def _list(text: str | None) -> list[str] | None:
    if text is None:
        return None
    return [t.strip() for t in text.split(",") if t.strip()]


#: what ``railval workshop invite --help`` says (the role is panelist; "reviewer" is the
#: independent reviewer who signs off)
_INVITE = ("Print a personal review link of workshop NAME for the panelist R (the role panelist: "
           "answers in the own workshops only). A user name not yet known is created with the role "
           "panelist and no password; an existing user must hold the role panelist. A new link "
           "replaces the panelist's earlier one; the answers stay.")


def register(sub: argparse._SubParsersAction) -> None:
    w = sub.add_parser("workshop", help="expert review workshops (plot sets, panelists, answers)")
    wsub = w.add_subparsers(dest="subverb", metavar="ACTION")
    wsub.required = True

    c = wsub.add_parser("create", help="create a workshop from a campaign (renders every plot once)")
    c.add_argument("name")
    c.add_argument("--campaign", required=True)
    c.add_argument("--configurations", nargs="+", default=None, metavar="NAME",
                   help="configurations (default: all; names may also be comma-separated)")
    c.add_argument("--sections", nargs="+", default=None, metavar="ID", help="sections (default: all)")
    c.add_argument("--kinds", nargs="+", default=None, metavar="KIND",
                   help="plot kinds (default: all; see `railval workshop kinds`)")
    c.add_argument("--scaling", default=None, metavar="zone|workshop",
                   help="one y range per plot kind within each EN 14363 test zone (zone, the default) "
                        "or over the whole workshop (workshop)")
    c.add_argument("--blind", action="store_true", help="no vehicle, configuration or section names")
    c.add_argument("--repeats", type=float, default=0.1, help="share of hidden repeats (default 0.1)")
    c.add_argument("--auto-share", type=float, default=0.0,
                   help="share of plots also shown with per-plot automatic scaling (default 0)")
    c.add_argument("--twin-scaling", default="auto", metavar="auto|zone|workshop",
                   help="how the --auto-share twins are scaled: per plot (auto, default) or with the "
                        "other consistent scaling (pairs zone and workshop scaling on the same plot)")
    c.add_argument("--seed", type=int, default=0, help="seed of the automatic-scaling choice")
    c.add_argument("--dry-run", action="store_true", help="only count the plots, store nothing")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_create)

    k = wsub.add_parser("kinds", help="list the plot kinds")
    k.add_argument("--json", action="store_true")
    k.set_defaults(func=_kinds)

    p = wsub.add_parser("plots", help="list a workshop's plots")
    p.add_argument("name")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_plots)

    i = wsub.add_parser("invite", help="a personal review link for a panelist", description=_INVITE)
    i.add_argument("name", metavar="NAME", help="workshop name")
    i.add_argument("--reviewer", required=True, metavar="R",
                   help="user name of the panelist (created with the role panelist when new)")
    i.add_argument("--base-url", default="http://127.0.0.1:5006",
                   help="address of `railval serve` as the panelists reach it")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_invite)

    s = wsub.add_parser("status", help="progress per panelist")
    s.add_argument("name")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_status)

    for verb, status in (("close", "closed"), ("reopen", "open")):
        x = wsub.add_parser(verb, help=f"{verb} a workshop")
        x.add_argument("name")
        x.set_defaults(func=_set_status, status=status)

    im = wsub.add_parser("import-answers", help="import answers from a CSV (all rows or none)")
    im.add_argument("name")
    im.add_argument("file")
    im.add_argument("--json", action="store_true")
    im.set_defaults(func=_import)

    ex = wsub.add_parser("export", help="export every answer to a CSV")
    ex.add_argument("name")
    ex.add_argument("file")
    ex.set_defaults(func=_export)

    cd = wsub.add_parser("cards", help="the plot cards: EN values, shares of Yes, Sprague–Geers errors per plot")
    cd.add_argument("name")
    cd.add_argument("--groups", nargs="+", default=[], metavar="WORKSHOP",
                    help="further workshops over the same plots (other reviewer groups)")
    cd.add_argument("--json", action="store_true")
    cd.set_defaults(func=_cards)

    a = wsub.add_parser("analyse", help="reviewer strictness, agreement, threshold, Table 1")
    a.add_argument("name")
    a.add_argument("--json", action="store_true")
    a.set_defaults(func=_analyse)


def _database(url: str | None):
    return database_service.open_database(url)


def _flat(values: list[str] | None) -> list[str] | None:
    if values is None:
        return None
    return [x for v in values for x in _list(v) or []]


def _create(args: argparse.Namespace) -> int:
    scaling = core_workshop.check_scaling(args.scaling or core_workshop.DEFAULT_SCALING)
    database = _database(args.db)
    configs, sections, kinds = _flat(args.configurations), _flat(args.sections), _flat(args.kinds)
    planned = workshop_admin_service.plan_counts(database, args.campaign, configs, sections, kinds)
    n_plots, counts = planned["plots"], planned["by_kind"]
    if args.dry_run:
        doc = {"name": args.name, "campaign": args.campaign, "plots": n_plots,
               "by_kind": counts, "stored": False}
        if args.json:
            emit_json(doc)
        else:
            print(f"workshop {args.name}: {n_plots} plots would be created "
                  f"({', '.join(f'{k} {n}' for k, n in counts.items())}); nothing stored")
        return 0
    if not args.json:
        print(f"creating workshop {args.name}: {n_plots} plots "
              f"({', '.join(f'{k} {n}' for k, n in counts.items())})", file=sys.stderr, flush=True)
    out = workshops_service.create(database, args.name, args.campaign, configurations=configs,
                    sections=sections, kinds=kinds, blind=args.blind, repeats=args.repeats,
                    auto_share=args.auto_share, seed=args.seed, scaling=scaling,
                    twin_scaling=args.twin_scaling, actor=_actor(), progress=Progress(),
                    planned_plots=n_plots)
    if args.json:
        emit_json({**out, "stored": True})
    else:
        print(f"workshop {out['name']} created: {out['plots']} plots "
              f"({out['auto_plots']} with automatic scaling), blind={out['blind']}, scaling {scaling}")
        for kind, share in out["flat_share"].items():
            print(f"  {kind:12s} flat plots (signal < 10 % of the y range): {100 * share:.0f} %")
    return 0


def _kinds(args: argparse.Namespace) -> int:
    kinds = workshops_service.describe_kinds()
    if args.json:
        emit_json({"kinds": kinds})
    else:
        for k in kinds:
            print(f"{k['id']:12s} {k['domain']:5s} {k['label']} — positions {', '.join(k['positions'])}")
    return 0


def _plots(args: argparse.Namespace) -> int:
    doc = workshop_admin_service.plots(_database(args.db), args.name)
    if args.json:
        emit_json(doc)
    else:
        for p in doc["plots"]:
            dev = "—" if p["deviation"] is None else f"{p['deviation']:.2f}"
            print(f"{p['id']:6d} {p['kind']:12s} {p['configuration']:12s} {p['section']:8s} "
                  f"{p['channel']:10s} deviation {dev:>6s} {p['scaling']:5s} {p['image_sha256'][:12]}")
    return 0


def _invite(args: argparse.Namespace) -> int:
    token = workshop_admin_service.invite(_database(args.db), args.name, args.reviewer, actor=_actor())
    link = workshops_service.review_link(args.base_url, token)
    if args.json:
        emit_json({"workshop": args.name, "reviewer": args.reviewer, "link": link})
    else:
        print(link)
    return 0


def _status(args: argparse.Namespace) -> int:
    doc = workshop_admin_service.status(_database(args.db), args.name)
    if args.json:
        emit_json(doc)
    else:
        print(f"workshop {doc['workshop']} ({doc['status']}, campaign {doc['campaign']}, "
              f"{doc['plots']} plots, {doc['answers']} answers)")
        for r in doc["reviewers"]:
            state = "finished" if r["finished"] else f"{r['answered']} of {r['total']}"
            print(f"  {r['reviewer']:20s} {state:>12s}  last answer {r['last_answer_at'] or '—'}")
    return 0


def _set_status(args: argparse.Namespace) -> int:
    status = workshop_admin_service.set_status(_database(args.db), args.name, args.status, actor=_actor())
    print(f"workshop {args.name} is {status}")
    return 0


def _import(args: argparse.Namespace) -> int:
    out = workshop_answers_service.import_answers(_database(args.db), args.name, args.file, actor=_actor())
    if args.json:
        emit_json({"workshop": args.name, **out})
    else:
        print(f"imported {out['answers']} answers of {out['reviewers']} reviewers "
              f"({out['new_users']} new reviewer users) into {args.name}")
    return 0


def _export(args: argparse.Namespace) -> int:
    n = workshop_answers_service.export_answers(_database(args.db), args.name, args.file)
    print(f"{n} answers of {args.name} written to {args.file}")
    return 0


def _cards(args: argparse.Namespace) -> int:
    doc = workshop_cards_service.cards(_database(args.db), args.name, groups=_flat(args.groups) or [], actor=_actor())
    if args.json:
        emit_json(doc)
        return 0
    for c in doc["cards"]:
        shares = ", ".join(f"{g['workshop']} " + ("—" if g["yes_share"] is None else f"{100 * g['yes_share']:.0f} %")
                           for g in c["groups"])
        sg = c["sg"] or {}
        print(f"{c['plot']:5d} {c['kind']:11s} {c['section']:6s} zone {c['zone']} {c['configuration']:10s} "
              f"{c['channel']:9s} Yes: {shares}; SG C {sg.get('C') if sg.get('C') is None else round(sg['C'], 3)}")
        for e in c["en"]:
            print(f"        {e['quantity']:8s} M {e['measured']:9.3f}  S {e['simulated']:9.3f}  "
                  f"S−M {e['abs_diff']:+9.3f}")
    return 0


def _analyse(args: argparse.Namespace) -> int:
    doc = workshop_answers_service.analyse(_database(args.db), args.name)
    if args.json:
        emit_json(doc)
    else:
        for row in doc.get("table1", []):
            shares = " … ".join("—" if row.get(f"{e}_yes") is None else
                                f"{100 * row[f'{e}_yes']:5.1f} % ({row[f'{e}_yes_count']} of {row[f'{e}_yes_answers']})"
                                for e in ("min", "max"))
            print(f"{row['kind']:14s} plots {row['plots']:4d}  answers {row.get('answers', 0):5d}  "
                  f"share of Yes {shares}")
        print(_at50_line(doc.get("threshold") or {}))
    return 0


def _at50_line(thr: dict) -> str:
    """The 50 % deviation with its interval and n, where it lies, or "too few answers to
    estimate" — the same statement as the analysis page."""
    n = thr.get("deviation_n") or {}
    n_text = f"{n.get('answers', 0)} answers by {n.get('reviewers', 0)} reviewer(s) on {n.get('plots', 0)} plots"
    head = "deviation at which a typical reviewer says Yes half of the time: "
    status = thr.get("deviation_at_50_status") or "too few answers to estimate"
    if status == "too few answers to estimate":
        return (f"{head}too few answers to estimate ({n_text}; at least {thr.get('min_answers')} answers "
                f"on {thr.get('min_plots')} plots are needed)")
    if status != "estimated":
        return f"{head}{status} (no value extrapolated; {n_text})"
    ci = thr.get("ci")
    interval = (f"interval reaches {thr['ci_status']}" if thr.get("ci_status")
                else f"interval {ci[0]:.2f} … {ci[1]:.2f}" if ci else "no interval")
    return (f"{head}{thr['deviation_at_50']:.2f} ({interval}; {n_text}; limit 1.0; "
            f"{thr.get('method', '').split(':')[0]})")
