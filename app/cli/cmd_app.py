"""CLI verbs ``serve`` and ``report`` (docs/design.md §1, §8).

``railval serve [--port 5006] [--address 127.0.0.1] [--no-demo] [--allow-websocket-origin H]
[--cookie-secret-file FILE] [--behind-proxy] [--admin]``
    migrate the database, seed the demo campaign (``railval.app.services.synth.ensure_demo``) into an
    empty database unless ``--no-demo``, and serve the web app until interrupted. A child
    process at low priority loads the validation's compiled kernels meanwhile, compiling them
    on a fresh installation (:mod:`railval.app.services.warmup`; ``RAILVAL_NO_WARMUP=1`` skips it),
    and once it has ended the forkserver of the background jobs' process pools starts with the
    simulator's and EN chain's kernels loaded (:func:`railval.app.services.batch.start_forkserver`). With users in
    the database every page needs sign-in (:mod:`railval.app.auth`); without users it serves
    open single-user mode on a loopback address only and refuses any other address.
``railval nginx-static DIR [--in-place]``
    copy Bokeh's and Panel's static folders into DIR with a ``.gz`` beside each text file,
    write the snippet nginx's static locations include (the app's security headers, MIME
    types, cache lifetime, gzip) and print the values of ``RAILVAL_STATIC_CONF``,
    ``RAILVAL_BOKEH_STATIC`` and ``RAILVAL_PANEL_STATIC`` for ``deploy/nginx/railval.conf.template``
    (``NAME=VALUE`` lines, or ``--json``); ``--in-place``: nginx reads the installed packages'
    folders and compresses every response itself (:mod:`railval.app.nginx_static`).
``railval report CAMPAIGN --config NAME --out FILE.html|FILE.pdf [--worst N] [--json]
[--workshop W --cards PLOT … [--groups W2 …]]``
    write the validation report of a configuration (the same builder as the Report page),
    optionally with chosen plot cards of an expert review workshop (docs/workshops.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from railval.app.cli import emit_json
from railval.core import lazy
from railval.core.errors import InvalidParameter

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
app_auth = lazy.module("railval.app.auth")
app_backend = lazy.module("railval.app.state.backend")
app_main = lazy.module("railval.app.main")
nginx_static = lazy.module("railval.app.nginx_static")
app_report = lazy.module("railval.app.report")
batch_service = lazy.module("railval.app.services.batch")
campaign_data_service = lazy.module("railval.app.services.campaign_data")
database_service = lazy.module("railval.app.services.database")
users_service = lazy.module("railval.app.services.users")
warmup_service = lazy.module("railval.app.services.warmup")
workshop_cards_service = lazy.module("railval.app.services.workshop_cards")
workshop_render = lazy.module("railval.app.services.workshop_render")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("serve", help="serve the web app (migrates the database, seeds the demo campaign)")
    p.add_argument("--port", type=int, default=5006, help="TCP port (default 5006)")
    p.add_argument("--address", default="127.0.0.1", help="listen address (default 127.0.0.1)")
    p.add_argument("--no-demo", action="store_true", help="do not seed the demo campaign into an empty database")
    p.add_argument("--allow-websocket-origin", action="append", default=None, metavar="HOST[:PORT]",
                   help="extra allowed websocket origin: the host[:port] users' browsers connect "
                   "to, e.g. behind a proxy (repeatable; '*' is refused)")
    p.add_argument("--show", action="store_true", help="open a browser tab")
    p.add_argument("--cookie-secret-file", metavar="FILE", default=None,
                   help="file holding the session cookie secret (else $RAILVAL_COOKIE_SECRET, "
                   "$RAILVAL_COOKIE_SECRET_FILE, else a random one per start)")
    p.add_argument("--behind-proxy", action="store_true",
                   help="client addresses from the proxy's X-Forwarded-For header (rate limit per client)")
    p.add_argument("--admin", action="store_true",
                   help="Panel's admin page at /admin (sessions, memory, logs), admins only")
    p.set_defaults(func=_cmd_serve)

    n = sub.add_parser("nginx-static", help="copy the static files for nginx (with .gz files), write "
                       "its snippet of the app's security headers, print the template's values")
    n.add_argument("dir", help="folder for the copies and the snippet")
    n.add_argument("--in-place", action="store_true",
                   help="no copies: nginx reads the installed packages' folders and compresses "
                   "every response itself (≈ 0.26 CPU-s per new browser, docs/app.md)")
    n.add_argument("--json", action="store_true", help="print the values as JSON")
    n.set_defaults(func=_cmd_nginx_static)

    r = sub.add_parser("report", help="write the HTML or PDF validation report of a configuration")
    r.add_argument("campaign", help="campaign name or id")
    r.add_argument("--config", required=True, help="configuration name")
    r.add_argument("--out", required=True, help="output file, .html or .pdf")
    r.add_argument("--worst", type=int, default=3, help="worst cases plotted (default 3)")
    r.add_argument("--workshop", default=None, metavar="NAME",
                   help="expert review workshop whose plot cards go into the report (with --cards)")
    r.add_argument("--cards", nargs="+", type=int, default=[], metavar="PLOT",
                   help="plot ids of the cards (`railval workshop cards NAME --json`)")
    r.add_argument("--groups", nargs="+", default=[], metavar="WORKSHOP",
                   help="further reviewer groups (workshops over the same plots) shown on the cards")
    r.add_argument("--json", action="store_true", help="print the report metadata as JSON")
    r.set_defaults(func=_cmd_report)


def _database(url: str | None, upgrade: bool):
    return database_service.open_database(url, upgrade=upgrade)


def seed_demo(database) -> str:
    """Seed the demo campaign into an empty database (H4's synth service); returns a message."""
    if campaign_data_service.has_campaigns(database):
        return "database holds campaigns; demo not seeded"
    try:
        from railval.app.services.synth import ensure_demo
    except ImportError as exc:
        return f"demo campaign not available (app.services.synth: {exc}); import one with `railval import DIR`"
    result = ensure_demo(database)
    return f"demo campaign seeded: {result}" if result else "demo campaign seeded"


def _cmd_serve(args: argparse.Namespace) -> int:
    database = _database(args.db, upgrade=True)
    has_users = app_auth.check_startup(database, args.address)

    # compiles the validation kernels on a fresh installation (≈ 25 s of one core) while the
    # demo is seeded and the server starts, instead of during the first Validate
    warming = warmup_service.start_background()
    if has_users:
        _secret, origin = app_auth.cookie_secret(args.cookie_secret_file)
        print(f"railval serve: sign-in required (a user has a password); cookie secret: {origin}",
              file=sys.stderr, flush=True)
    else:
        print("railval serve: open single-user mode (no user with a password; loopback requests only)",
              file=sys.stderr, flush=True)
    if not args.no_demo:
        print(f"railval serve: {seed_demo(database)}", file=sys.stderr, flush=True)
    # the forkserver of the background jobs' pools, with the simulator's and EN chain's kernels
    # loaded and the workshop drawing imported, started once the warm-up child has compiled or
    # loaded the kernels: the first diagnosis, calibration or workshop does not wait for it,
    # and on a fresh installation it does not compile beside the server's first pages
    batch_service.start_forkserver([workshop_render.CANVAS], after=warming)
    origins = None
    if args.allow_websocket_origin:
        origins = list(args.allow_websocket_origin) + [f"{args.address}:{args.port}", f"localhost:{args.port}"]
    print(f"railval serve: http://{args.address}:{args.port}/app (database {database.safe_url})",
          file=sys.stderr, flush=True)
    app_main.serve(database, port=args.port, address=args.address, show=args.show, allow_websocket_origin=origins,
                   cookie_secret_file=args.cookie_secret_file, behind_proxy=args.behind_proxy,
                   admin=args.admin)
    return 0


def _cmd_nginx_static(args: argparse.Namespace) -> int:
    values = nginx_static.prepare(Path(args.dir), copy=not args.in_place)
    if args.json:
        emit_json(values)
    else:
        for name, value in values.items():
            print(f"{name}={value}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    if Path(args.out).suffix.lower() not in (".html", ".htm", ".pdf"):
        raise app_report.ReportError(f"--out {args.out}: extension must be .html or .pdf")
    database = _database(args.db, upgrade=False)
    cards = None
    if args.cards or args.workshop:
        if not (args.cards and args.workshop):
            raise InvalidParameter("--workshop and --cards go together: the workshop and its plot ids")
        # the cards show answers: the workshop.results permission
        actor = users_service.principal_of(database, database_service.default_actor())
        cards = workshop_cards_service.report_cards(database, args.workshop, args.config, args.cards, groups=args.groups,
                                                    actor=actor)
    rep = app_report.build_report(app_backend.Backend(database), args.campaign, args.config, worst_cases=args.worst, cards=cards)
    path = rep.write(args.out)
    if args.json:
        emit_json({**rep.to_dict(), "file": str(path)})
    else:
        print(f"report of {args.campaign}/{args.config} "
              f"({'validated' if rep.validated else 'not validated'}) written to {path}")
    return 0
