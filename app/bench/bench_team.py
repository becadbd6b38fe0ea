"""Team server under load: reviewers and engineers through nginx on two app processes.

The production topology on loopback (:mod:`railval.app.bench.topology`): PostgreSQL (a fresh
schema in ``--pg``), ``--apps`` ``railval serve`` processes behind real nginx with TLS and
sticky sessions. Set-up: the synthetic campaign (``railval synth``, 12 sections), a workshop
of its Y time plots, ``--reviewers`` invited reviewers, one engineer account.

Phases:

1. ``--engineers`` Panel sessions, one Chromium page each (all in one headless browser),
   opened one after another and kept open: sign-in through the proxy, then the time until the
   app's navigation shows ("first Panel page", ms);
2. with those sessions open, every reviewer in its own thread posts ``--answers`` answers
   through the proxy over its own keep-alive HTTPS connection ("answer round trip": request
   → the server's confirmation that the row is committed; ``--think`` seconds before each);
   answers lost counted from the database. With ``--during-answers N``, up to N further
   sessions of the signed-in engineers open one after another meanwhile ("first Panel page
   while reviewers answer": only those that started and ended with answers coming in), each
   in a new browser context with an empty cache; ``--during-cached`` adds after each one a new
   tab of a first-wave engineer's browser, whose cache holds the static files (a returning
   engineer);
3. the sessions are closed; after ``--settle`` seconds (Bokeh discards a disconnected session
   after ``unused-session-lifetime``, 15 s by default) the memory is read again;
4. a second wave of as many sessions is opened by the same users, already signed in (each
   browser context starts with the cookies of one of the first wave's): the memory it adds
   shows whether the first wave's memory is reused, and its first pages and CPU are a new
   session's alone — without the sign-in's argon2id hash, a deliberate cost paid once per
   sign-in (docs/security.md), which the first wave's figures include.

Memory: resident set (RSS) of every app process before phase 1, with one session open (the
first loads modules, caches and the campaign's data once), with all sessions open, and after
they closed; "per further Panel session" = (all open − one open) / (engineers − 1). Closed
sessions are discarded by Bokeh after ``unused-session-lifetime`` (15 s) at its next check
(every 17 s); the app then collects and trims the heap (``railval.app.upkeep.release_memory``).
The app processes run with the deployment's environment (``railval.app.upkeep.SERVE_ENV``:
Python objects in glibc's heap, so the trim returns them); ``--pymalloc`` runs them with
Python's own allocator instead, for comparison.

Length: one benchmark — the phases above, driven in one browser, and the figures they print —
in steps of ≤ 60 lines; the topology it runs on is :mod:`railval.app.bench.topology`.
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import io
import json
import os
import ssl
import statistics
import subprocess
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import func, select

from railval.app.bench.bench_workshop import xsrf_headers, xsrf_of
from railval.app.bench.topology import REPO, TEMPLATE, Topology, browser_trust
from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.db.catalogue import head_revision

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs (the CLI's ``main`` also because the
#: command line imports this module)
#: the migration scripts, relative to a checkout: one database schema per set of them
MIGRATIONS = Path("db") / "migrations" / "versions"
psutil = lazy.module("psutil")
psycopg = lazy.module("psycopg")
playwright_sync = lazy.module("playwright.sync_api")
cli_main = lazy.function("railval.app.cli", "main")
workshops_service = lazy.module("railval.app.services.workshops")
users = lazy.module("railval.db.users")
wsdb = lazy.module("railval.db.workshops")
connect = lazy.function("railval.db.engine", "connect")
report = lazy.module("railval.app.report")
models = lazy.module("railval.db.models")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--reviewers", type=int, default=50)
    parser.add_argument("--engineers", type=int, default=20)
    parser.add_argument("--answers", type=int, default=20, help="answers per reviewer")
    parser.add_argument("--apps", type=int, default=2, help="app processes behind nginx")
    parser.add_argument("--think", type=float, default=0.0, metavar="S",
                        help="seconds each reviewer looks at a plot before answering (default 0: "
                        "answers back to back)")
    parser.add_argument("--during-answers", type=int, default=0, metavar="N",
                        help="also open up to N sessions of the signed-in engineers while the "
                        "reviewers answer, and time their first pages (use --think so that the "
                        "answering lasts)")
    parser.add_argument("--during-cached", action="store_true",
                        help="with --during-answers: after each such session in a new browser "
                        "context (empty cache), one in a new tab of a first-wave engineer's "
                        "browser context, whose cache holds the app's static files from its first "
                        "visit (a returning engineer), timed the same way and printed apart")
    parser.add_argument("--settle", type=float, default=60.0,
                        help="seconds after the sessions closed before memory is read again")
    parser.add_argument("--admin", action="store_true",
                        help="run the app processes with Panel's admin page (it keeps every session's record)")
    parser.add_argument("--pymalloc", action="store_true",
                        help="app processes with Python's own allocator instead of the "
                        "deployment's PYTHONMALLOC=malloc (railval.app.upkeep.SERVE_ENV), to compare")
    parser.add_argument("--pg", default="postgresql://postgres@127.0.0.1:5432/test",
                        help="PostgreSQL database in which a fresh schema is used")
    parser.add_argument("--nginx-template", default=None, metavar="FILE",
                        help="nginx site template instead of deploy/nginx/railval.conf.template "
                        "(an older one, to compare; e.g. `git show COMMIT:deploy/nginx/"
                        "railval.conf.template > FILE`)")
    parser.add_argument("--static-in-place", action="store_true",
                        help="nginx reads the packages' static folders and compresses each "
                        "response (railval nginx-static --in-place) instead of copies with .gz "
                        "files beside them (the default, as deployed)")
    parser.add_argument("--ref", default=None, metavar="COMMIT",
                        help="A/B in one run: the first app process runs the code of COMMIT (git "
                        "archive, first on its PYTHONPATH), the others the working tree's; the "
                        "first page and the CPU per new session are also printed per code")


def _rss_mb(pids: list[int]) -> dict[int, float]:
    return {p: round(psutil.Process(p).memory_info().rss / 1048576, 1) for p in pids}


def _pct(values: list[float], q: float) -> float:
    return round(statistics.quantiles(values, n=100, method="inclusive")[int(q) - 1], 1) if len(values) > 1 else values[0]


def _reviewer(host: str, port: int, token: str, n: int, out: list[float], errors: list[str],
              think: float = 0.0) -> None:
    ctx = ssl._create_unverified_context()  # the run's self-signed certificate
    conn = http.client.HTTPSConnection(host, port, context=ctx, timeout=30)
    conn.request("GET", f"/review/{token}")  # the page hands out the anti-forgery token
    resp = conn.getresponse()
    xsrf = xsrf_of(resp.getheader("Set-Cookie"), resp.read())
    if xsrf is None:
        errors.append(f"no anti-forgery token on /review/… (HTTP {resp.status})")
        return
    headers = {"Content-Type": "application/json", **xsrf_headers(xsrf)}
    for i in range(n):
        time.sleep(think)  # the reviewer looks at the plot
        body = json.dumps({"position": i, "answer": "yes" if i % 2 else "no", "seconds": 1.0,
                           "submission": uuid.uuid4().hex})
        t0 = time.perf_counter()
        for _attempt in range(5):
            try:
                conn.request("POST", f"/review/{token}/answer", body, headers)
                resp = conn.getresponse()
                resp.read()
                if resp.status == 200:
                    out.append((time.perf_counter() - t0) * 1000)
                    break
                errors.append(f"HTTP {resp.status}")
            except OSError as exc:
                errors.append(type(exc).__name__)
                conn.close()
                conn = http.client.HTTPSConnection(host, port, context=ctx, timeout=30)
    conn.close()


def _cpu_s(pids: list[int]) -> float:
    """CPU time (user + system) the app processes have used so far."""
    return sum(sum(psutil.Process(p).cpu_times()[:2]) for p in pids)


def _group_cpu_s(leader: int) -> float:
    """CPU time (user + system) of nginx: its master process and workers (one process group)."""
    lead = psutil.Process(leader)
    return sum(sum(p.cpu_times()[:2]) for p in [lead, *lead.children(recursive=True)])


def _serving_pid(page) -> int:
    """The app process that serves ``page``'s session (nginx keeps a browser on one process)."""
    return int(page.evaluate("() => fetch('/health').then(r => r.json()).then(d => d.process)"))


def _open_sessions(browser, base: str, n: int, times: list[float], cpu: list | None = None,
                   served_by: list | None = None, states: list | None = None,
                   signed_in: list | None = None):
    """``n`` engineer sessions, one browser context each, opened one after another; returns
    the pages and the RSS after the first (modules, caches and campaign data loaded).
    ``cpu``: per session, the app processes' CPU seconds from the sign-in click until the
    navigation shows plus 0.5 s (the websocket's last messages) — the server's cost of one new
    session (the sign-in's password hash included; the first session, which loads modules and
    caches once, left out), as (raw CPU-s, background CPU-s per s, window s): the background is
    what the processes burn with the sessions already open (their periodic refreshes, the
    reviewers' answers), read over 1 s before the click, so that ``raw − background × window``
    is the new session's own cost; with the serving process's own CPU-s (``own``) last.
    ``served_by``: per session, the process that served it (after the CPU is read).
    ``states``: receives each context's cookies once its page shows (Playwright's
    ``storage_state``); ``signed_in``: such cookies, one per session — the session then opens
    ``/app`` directly, without signing in, timed from the request."""
    pages, warm = [], None
    for k in range(n):
        ctx = browser.new_context(viewport={"width": 1280, "height": 900},
                                  storage_state=signed_in[k] if signed_in else None)
        page = ctx.new_page()
        if not signed_in:
            page.goto(f"{base}/login")
            page.fill("#username", "eng")
            page.fill("#password", "engineer password")
        b0, tb = _cpu_s(_PIDS), time.perf_counter()
        time.sleep(1.0)
        c0, each0 = _cpu_s(_PIDS), {p: _cpu_s([p]) for p in _PIDS}
        t0 = time.perf_counter()
        background = (c0 - b0) / (t0 - tb)
        if signed_in:
            page.goto(f"{base}/app")
        else:
            page.click("#signin")
        page.locator(".rv-nav").wait_for(timeout=120_000)
        times.append((time.perf_counter() - t0) * 1000)
        time.sleep(0.5)
        if cpu is not None and k > 0:
            each = {p: _cpu_s([p]) - each0[p] for p in _PIDS}
            cpu.append((_cpu_s(_PIDS) - c0, background, time.perf_counter() - t0, each))
        if served_by is not None:
            served_by.append(_serving_pid(page))
        if states is not None:
            states.append(ctx.storage_state())
        pages.append(page)
        if warm is None:
            time.sleep(2.0)
            warm = _rss_mb(_PIDS)
    return pages, warm


_PIDS: list[int] = []


def _export(commit: str, work: Path) -> str:
    """The code of ``commit`` (``git archive`` of this checkout) laid out as the ``railval``
    namespace (``railval/app``, ``railval/core``, ``railval/db``) in ``work``; returns the
    folder to put first on ``PYTHONPATH``. The database schema must be the same as the tree's."""
    src, pkg = work / "ref-src", work / "ref-pkg"
    src.mkdir(parents=True)
    (pkg / "railval").mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    check_same_schema(commit, src)
    for part in ("app", "core", "db"):
        (pkg / "railval" / part).symlink_to(src / part)
    return str(pkg)


def check_same_schema(commit: str, ref_src: Path, tree: Path = REPO) -> None:
    """Refuse ``--ref COMMIT`` when its database schema is not the working tree's: both codes
    serve one database, so their migration scripts (``db/migrations/versions``) must be the
    same files with the same content. Raises :class:`InvalidParameter` naming the scripts that
    differ and both heads."""
    def scripts(root: Path) -> dict[str, bytes]:
        return {p.name: p.read_bytes() for p in (root / MIGRATIONS).glob("*.py")}

    ref, ours = scripts(ref_src), scripts(tree)
    differ = sorted(n for n in ref.keys() | ours.keys() if ref.get(n) != ours.get(n))
    if differ:
        raise InvalidParameter(
            f"--ref {commit}: its database migrations differ from the working tree's in "
            f"{', '.join(differ)} (head {head_revision(ref_src / MIGRATIONS)} against "
            f"{head_revision(tree / MIGRATIONS)}); the two codes cannot share one database")


@dataclass
class _RefTopology(Topology):
    """The team topology whose first app process runs the code at ``ref_path`` (``--ref``)."""

    ref_path: str = ""

    def _env(self) -> dict[str, str]:
        env = super()._env()
        if self.ref_path and not self.apps:  # start_app: the first app process
            env["PYTHONPATH"] = self.ref_path
        return env


def run(args: argparse.Namespace) -> dict[str, Any]:
    schema = f"bench_{uuid.uuid4().hex[:10]}"
    with psycopg.connect(args.pg, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    url = f"{args.pg.replace('postgresql://', 'postgresql+psycopg://')}?options=-csearch_path%3D{schema}"
    work = Path(tempfile.mkdtemp(prefix="railval-bench-team-"))
    figures: dict[str, Any] = {"reviewers": args.reviewers, "engineers": args.engineers,
                               "app_processes": args.apps, "answers_per_reviewer": args.answers,
                               "allocator": "pymalloc" if args.pymalloc else "malloc", "admin_page": args.admin}
    topo = _RefTopology(url, work / "site", n_apps=args.apps, app_env={} if args.pymalloc else None,
                        admin=args.admin, ref_path=_export(args.ref, work) if args.ref else "",
                        template=Path(args.nginx_template) if args.nginx_template else TEMPLATE,
                        static_copy=not args.static_in_place)
    figures["nginx_template"] = str(topo.template.name if topo.template == TEMPLATE
                                    else topo.template)
    if args.ref:
        figures["ref"] = args.ref
    try:
        db, tokens, answers = _seed(args, url, topo)
        figures["answers_per_reviewer"] = answers
        topo.start()
        nginx0 = _group_cpu_s(topo.nginx.pid)
        m = _drive(args, topo, tokens, answers)
        figures.update(_figures(args, m, _stored_answers(db), answers))
        # nginx's CPU over the whole run (static files, TLS, proxying): not in the app's figures
        figures["nginx_cpu_s"] = round(_group_cpu_s(topo.nginx.pid) - nginx0, 2)
        if args.ref:
            figures["per_code"] = _per_code(m, next(iter(topo.apps.values())).pid)
        db.dispose()
        with open("/proc/loadavg") as fh:
            figures["loadavg_at_end"] = fh.read().split()[:3]
    finally:
        topo.stop()
        with psycopg.connect(args.pg, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')
    return figures


def _seed(args: argparse.Namespace, url: str, topo: Any) -> tuple[Any, list[str], int]:
    """A fresh database with the synthetic campaign, an engineer and a workshop of Y plots with
    one invitation per reviewer: (database, the reviewers' tokens, answers per reviewer)."""
    topo.workdir.mkdir(parents=True)
    topo._secrets()
    os.environ["RAILVAL_SECRET_KEY_FILE"] = str(topo.workdir / "secrets" / "railval_secret_key")
    with contextlib.redirect_stdout(io.StringIO()):  # stdout is the figures' JSON
        assert cli_main(["--db", url, "init"]) == 0
        assert cli_main(["--db", url, "synth", "--name", "demo", "--sections", "12"]) == 0
    db = connect(url)
    with db.session(write=True) as s:
        users.create_user(s, "eng", password="engineer password", roles=["engineer"])
    workshops_service.create(db, "W", "demo", kinds=["Y_time"], repeats=0.0)
    with db.session(write=True) as s:
        w = wsdb.get_workshop(s, "W")
        tokens = [wsdb.invite(s, w, f"r{k}", seed=k) for k in range(args.reviewers)]
        n_plots = len(wsdb.plots(s, w))
    return db, tokens, min(args.answers, n_plots)


def _drive(args: argparse.Namespace, topo: Any, tokens: list[str], answers: int) -> dict[str, Any]:
    """Engineers' Panel sessions in Chromium, reviewers answering over their own connections,
    the sessions closed and a second wave opened; the raw timings and memory readings."""
    pids = [p.pid for p in topo.apps.values()]
    _PIDS[:] = pids
    m: dict[str, Any] = {"before": _rss_mb(pids), "first_page": [], "rtt": [], "errors": [],
                         "cpu": [], "first_page_signed_in": [], "cpu_signed_in": []}
    states: list = []
    with playwright_sync.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium",
                                     args=[*report.CHROMIUM_ARGS, *browser_trust(topo.workdir / "tls.crt")])
        m["served_by"] = []
        pages, m["warm"] = _open_sessions(browser, topo.url, args.engineers, m["first_page"], m["cpu"],
                                          m["served_by"], states=states)
        m["per_process"] = {}
        for pid in m["served_by"]:
            m["per_process"][pid] = m["per_process"].get(pid, 0) + 1
        m["open"] = _rss_mb(pids)
        threads = [threading.Thread(target=_reviewer, args=("127.0.0.1", topo.port, t, answers,
                                                            m["rtt"], m["errors"],
                                                            getattr(args, "think", 0.0)))
                   for t in tokens]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        m["during_phases"] = {}
        m["first_page_during"], m["during_open"], m["first_page_during_cached"] = _open_during(
            browser, topo.url, states, threads, getattr(args, "during_answers", 0),
            pages if getattr(args, "during_cached", False) else None, m["during_phases"])
        for t in threads:
            t.join()
        m["wall"] = time.perf_counter() - t0
        m["loaded"] = _rss_mb(pids)
        for page in pages:
            page.context.close()
        time.sleep(args.settle)
        m["after"] = _rss_mb(pids)
        # a second wave of the same number of sessions, the same users signed in already: is
        # the memory reused, and what does a new session cost without the password hash?
        _open_sessions(browser, topo.url, args.engineers, m["first_page_signed_in"],
                       m["cpu_signed_in"], signed_in=states)
        m["second"] = _rss_mb(pids)
        browser.close()
    return m


#: where a first page's time went, read in the browser once the navigation shows (Navigation and
#: Resource Timing, ms from the request): the HTML's response end, the scripts run
#: (DOMContentLoaded's end), the static files' bytes over the wire and how many came from the
#: browser's cache (0 bytes over the wire: fresh; fewer than the body's: revalidated, a 304)
_PHASES_JS = """() => { const n = performance.getEntriesByType('navigation')[0];
  const r = performance.getEntriesByType('resource').filter(x => x.name.includes('/static/'));
  return {html_ms: n.responseEnd, scripts_run_ms: n.domContentLoadedEventEnd,
          static_files: r.length, static_bytes: r.reduce((a, x) => a + x.transferSize, 0),
          from_cache: r.filter(x => x.transferSize === 0).length,
          revalidated: r.filter(x => x.transferSize > 0 && x.transferSize < x.encodedBodySize).length}; }"""


def _open_during(browser, base: str, states: list, threads: list, n: int, visited: list | None = None,
                 phases: dict | None = None) -> tuple[list[float], int, list[float]]:
    """While the reviewers' ``threads`` answer: up to ``n`` sessions of the signed-in engineers
    (their cookies ``states``, in turn), one after another, each in a new browser context (an
    empty cache: every static file fetched and every script compiled afresh), timed from its
    ``/app`` request until the navigation shows and closed again; stops when the reviewers are
    done. ``visited``: the first wave's pages; after each such session one more opens in a new
    tab of one of their contexts (a returning engineer: the browser's cache holds the static
    files, served immutable, from the first visit), timed the same way. Returns the first pages
    (ms) of the sessions that started while answers were still coming in, how many sessions
    were open at the time (the first wave's), and the cached tabs' first pages (ms). ``phases``
    receives, per kind (``empty_cache``, ``cached``), each timed page's :data:`_PHASES_JS`
    reading."""
    phases = {} if phases is None else phases
    times: list[float] = []
    cached: list[float] = []

    def timed(page, out: list[float], kind: str) -> None:
        t0 = time.perf_counter()
        page.goto(f"{base}/app")
        page.locator(".rv-nav").wait_for(timeout=120_000)
        if any(t.is_alive() for t in threads):  # the answers went on throughout
            out.append((time.perf_counter() - t0) * 1000)
            phases.setdefault(kind, []).append(page.evaluate(_PHASES_JS))

    for k in range(n):
        if not any(t.is_alive() for t in threads):
            break
        ctx = browser.new_context(viewport={"width": 1280, "height": 900}, storage_state=states[k % len(states)])
        timed(ctx.new_page(), times, "empty_cache")
        ctx.close()
        if visited and any(t.is_alive() for t in threads):
            tab = visited[k % len(visited)].context.new_page()
            timed(tab, cached, "cached")
            tab.close()
    return times, len(states), cached


def _stored_answers(db: Any) -> int:
    with db.session() as s:
        return int(s.scalar(select(func.count()).select_from(models.WorkshopAnswer)))


def _stats(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    return {"p50": round(statistics.median(values), 3), "mean": round(statistics.fmean(values), 3),
            "max": round(max(values), 3)}


def _per_code(m: dict[str, Any], ref_pid: int) -> dict[str, Any]:
    """``--ref``: the first page and the CPU per new session split by the code that served the
    session (``ref``: the first app process; ``tree``: the others). A process's first session
    (its imports and caches) is left out of both; ``own_cpu_s`` is the serving process's CPU
    alone, ``all_cpu_s`` both processes' (as ``server_cpu_per_new_session_s``)."""
    seen: set[int] = set()
    out: dict[str, dict[str, list[float]]] = {c: {"first_page_ms": [], "own_cpu_s": [], "all_cpu_s": []}
                                              for c in ("ref", "tree")}
    for k, pid in enumerate(m["served_by"]):
        if pid not in seen:
            seen.add(pid)
            continue
        code = out["ref" if pid == ref_pid else "tree"]
        code["first_page_ms"].append(m["first_page"][k])
        raw, _bg, _w, each = m["cpu"][k - 1]  # no CPU reading for the very first session
        code["own_cpu_s"].append(each[pid])
        code["all_cpu_s"].append(raw)
    return {c: {"sessions": len(v["own_cpu_s"]), **{key: _stats(vals) for key, vals in v.items()}}
            for c, v in out.items()}


def _figures(args: argparse.Namespace, m: dict[str, Any], stored: int, answers: int) -> dict[str, Any]:
    """The printed figures from the raw readings of :func:`_drive`."""
    total = lambda key: round(sum(m[key].values()), 1)
    return {
        "first_panel_page_ms": {"p50": _pct(m["first_page"], 50), "p95": _pct(m["first_page"], 95),
                                "max": round(max(m["first_page"]), 1)},
        "server_cpu_per_new_session_s": _stats([raw for raw, *_ in m["cpu"]]),
        "background_cpu_s_per_s": _stats([bg for _, bg, *_ in m["cpu"]]),
        "server_cpu_per_new_session_net_s": _stats([raw - bg * w for raw, bg, w, _ in m["cpu"]]),
        # the second wave: the same users opening the app again, signed in (no password hash)
        "first_panel_page_signed_in_ms": {"p50": _pct(m["first_page_signed_in"], 50),
                                          "p95": _pct(m["first_page_signed_in"], 95),
                                          "max": round(max(m["first_page_signed_in"]), 1)},
        "server_cpu_per_new_session_signed_in_s": _stats([raw for raw, *_ in m["cpu_signed_in"]]),
        "server_cpu_per_new_session_signed_in_net_s": _stats(
            [raw - bg * w for raw, bg, w, _ in m["cpu_signed_in"]]),
        **({"first_panel_page_during_answers_ms": {
            "sessions": len(m["first_page_during"]), "engineers_open": m["during_open"],
            "p50": _pct(m["first_page_during"], 50), "p95": _pct(m["first_page_during"], 95),
            "max": round(max(m["first_page_during"]), 1)}} if m.get("first_page_during") else {}),
        # where those first pages' time went (medians; _PHASES_JS)
        **({"first_page_during_answers_phases": {kind: {key: round(statistics.median(r[key] for r in rows), 1)
                                                        for key in rows[0]}
                                                 for kind, rows in m["during_phases"].items()}}
           if m.get("during_phases") else {}),
        # the same, in a new tab of a browser that visited the app before (its cache warm)
        **({"first_panel_page_during_answers_cached_ms": {
            "sessions": len(m["first_page_during_cached"]),
            "p50": _pct(m["first_page_during_cached"], 50), "p95": _pct(m["first_page_during_cached"], 95),
            "max": round(max(m["first_page_during_cached"]), 1)}} if m.get("first_page_during_cached") else {}),
        "panel_sessions_per_process": sorted(m["per_process"].values()),
        "answer_round_trip_ms": {"p50": _pct(m["rtt"], 50), "p95": _pct(m["rtt"], 95),
                                 "max": round(max(m["rtt"]), 1)},
        "answers": {"sent": args.reviewers * answers, "confirmed": len(m["rtt"]), "stored": stored,
                    "lost": args.reviewers * answers - stored, "retried_errors": len(m["errors"])},
        "answers_per_s": round(len(m["rtt"]) / m["wall"], 1),
        "rss_mb": {"before": total("before"), "one_session_open": total("warm"),
                   "sessions_open": total("open"), "after_answers": total("loaded"),
                   f"after_close_{args.settle:g}s": total("after"), "second_wave_open": total("second")},
        # the first session loads modules and caches once; the others cost this each
        "rss_per_further_panel_session_mb": round(
            (sum(m["open"].values()) - sum(m["warm"].values())) / max(1, args.engineers - 1), 1),
    }
