"""Review workshop under load: N concurrent reviewers × M answers against `railval serve`.

Set-up: a database holding the demo campaign (``railval.app.services.synth.ensure_demo``, or
``--url URL`` of an existing one with ``--campaign``), one workshop of ``--plots`` plots
rendered once (its creation time is reported), ``--reviewers`` invited reviewers. Then
``railval serve --no-demo`` is started as a separate process on a free loopback port and
every reviewer runs in its own thread with its own keep-alive HTTP connection, as the
review page does: load the page and its state, then for every place of the sequence fetch
the plot image ("next plot shown": request → last byte of the PNG) and post the answer
("answer round trip": request → the server's confirmation that the row is committed).
``--resend`` of the answers are posted a second time with the same submission id (a
client retry), which must change nothing.

Figures: answers expected / stored / lost / duplicated (from the database afterwards),
answer round trip and next plot shown p50/p95/max in ms, answers per second, server
resident memory (VmRSS of the server process) before the first and after the last answer,
analysis time of all answers (``railval.core.review.analyse``), and ``railval audit verify
--quick`` of the trail afterwards (every answer is a signed audit row: its time, rows, signed
rows and whether it holds). With ``--url`` of a database
that already holds the workshop ``bench``, it is reused (new reviewers) instead of rendered
again. ``--think`` adds a reviewer's look at each plot before the answer.

``--create-only N`` times only the creation of a ``--plots`` workshop, N times each way and
alternating (other work on the machine then weighs on both alike): A renders a figure made
for every plot, one after the other in this process (the renderer before figure reuse and the
render pool), B the current renderer (:func:`railval.app.services.workshop_render.render_many`);
each run reports its total and rendering time (from the render's start — "0 of N plots
rendered" — to the end of the creation: the pool's start, the plots and their storing) and
the 1-minute load average at its end. Then N times C: the same creation by ``railval workshop
create`` in a fresh process, timed from launch to exit (the interpreter, the imports — scipy.signal,
matplotlib, SQLAlchemy, numba —, the render pool's start and the creation): what a user of the
command line waits, where A and B time a process that has created a workshop before.
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import io
import json
import os
import random
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from sqlalchemy import select

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs (matplotlib only for way A's plots)
workshops_service = lazy.module("railval.app.services.workshops")
workshop_render = lazy.module("railval.app.services.workshop_render")
workshop_canvas = lazy.module("railval.app.services.workshop_canvas")
synth_service = lazy.module("railval.app.services.synth")
analyse = lazy.function("railval.app.services.workshop_answers", "analyse")
verify_database = lazy.function("railval.app.services.audit", "verify_database")
free_port = lazy.function("railval.app.main", "free_port")
wsdb = lazy.module("railval.db.workshops")
models = lazy.module("railval.db.models")
connect = lazy.function("railval.db.engine", "connect")
matplotlib = lazy.module("matplotlib")
Figure = lazy.function("matplotlib.figure", "Figure")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--reviewers", type=int, default=50, help="concurrent reviewers (default 50)")
    parser.add_argument("--plots", type=int, default=120,
                        help="places per reviewer = plots of the workshop, no repeats (default 120)")
    parser.add_argument("--resend", type=float, default=0.05,
                        help="share of answers posted twice with the same submission id (default 0.05)")
    parser.add_argument("--url", default=None, help="database URL (default: a fresh SQLite file)")
    parser.add_argument("--campaign", default=None, help="campaign (default: the demo campaign)")
    parser.add_argument("--think", type=float, default=0.0,
                        help="mean seconds a reviewer looks at a plot before answering "
                             "(uniform 0.5–1.5 × this; default 0: back-to-back requests)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder")
    parser.add_argument("--create-only", type=int, default=0, metavar="N",
                        help="only time the creation of a --plots workshop, N times each way, "
                             "alternating: A = one figure per plot in this process (the renderer "
                             "before figure reuse and the pool), B = the current renderer; then "
                             "N times `railval workshop create` in a fresh process (C: what a "
                             "user of the command line waits, imports and render pool start "
                             "included); no server, no reviewers")


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def _pct(values: list[float], p: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(p / 100 * (len(s) - 1))))]


def _summary(ms: list[float]) -> dict[str, float]:
    return {"n": len(ms), "p50_ms": round(_pct(ms, 50), 1), "p95_ms": round(_pct(ms, 95), 1),
            "max_ms": round(max(ms), 1), "mean_ms": round(statistics.fmean(ms), 1)}


def _setup(url: str, campaign: str | None, n_plots: int, n_reviewers: int) -> dict[str, Any]:
    db = connect(url)
    db.init()
    if campaign is None:
        synth_service.ensure_demo(db)
        campaign = synth_service.DEMO_NAME
    tag = f"{int(time.time()) % 100000:05d}"
    with db.session(write=True) as s:
        existing = s.scalar(select(models.Workshop).where(models.Workshop.name == "bench"))
        if existing is not None:  # reuse the rendered workshop, new reviewers
            n = len(wsdb.plots(s, existing))
            tokens = {f"bench{tag}-{i:02d}": wsdb.invite(s, existing, f"bench{tag}-{i:02d}", seed=i)
                      for i in range(n_reviewers)}
            return {"tokens": tokens, "plots": n, "create_s": None, "campaign": campaign,
                    "planned": n}
        planned = workshops_service.plan(s, campaign)
    if len(planned) < n_plots:
        raise SystemExit(f"campaign {campaign} gives only {len(planned)} plots, {n_plots} asked")
    # the first n plots in plan order: whole (configuration, section) plot sets
    chosen = planned[:n_plots]
    sections = sorted({p.section for p in chosen})
    configs = sorted({p.configuration for p in chosen})
    kinds = sorted({p.kind for p in chosen})
    with db.session() as s:
        n_all = len(workshops_service.plan(s, campaign, configs, sections, kinds))
    t0 = time.perf_counter()
    summary = workshops_service.create(db, "bench", campaign, configurations=configs, sections=sections,
                        kinds=kinds, repeats=0.0)
    create_s = time.perf_counter() - t0
    tokens = {}
    with db.session(write=True) as s:
        w = wsdb.get_workshop(s, "bench")
        for i in range(n_reviewers):
            tokens[f"bench{tag}-{i:02d}"] = wsdb.invite(s, w, f"bench{tag}-{i:02d}", seed=i)
    db.dispose()
    return {"tokens": tokens, "plots": summary["plots"], "create_s": create_s,
            "campaign": campaign, "planned": n_all}


def xsrf_of(set_cookie: str | None, page: bytes) -> dict[str, str] | None:
    """The pre-session cookie and anti-forgery token a review page hands out (its signed
    ``railval_presession`` cookie and the ``xsrf-token`` meta element,
    :class:`railval.app.security.SessionBoundXsrf`), as the browser sends them with an
    answer: POST with ``Cookie: railval_presession=<cookie>`` (:func:`xsrf_headers`) and
    ``X-XSRFToken: <token>``; ``None`` when either is missing."""
    cookie = re.search(r"railval_presession=([^;]+)", set_cookie or "")
    token = re.search(rb'name="xsrf-token" content="([^"]+)"', page)
    if cookie and token:
        return {"cookie": cookie.group(1), "token": token.group(1).decode()}
    return None


def xsrf_headers(xsrf: dict[str, str]) -> dict[str, str]:
    """The headers of a ``POST`` carrying what :func:`xsrf_of` found."""
    return {"Cookie": f"railval_presession={xsrf['cookie']}", "X-XSRFToken": xsrf["token"]}


class _Reviewer(threading.Thread):
    def __init__(self, port: int, name: str, token: str, index: int, resend: float, think: float,
                 start: threading.Event):
        super().__init__(daemon=True)
        self.port, self.token, self.index, self.resend = port, token, index, resend
        self.name, self.think = name, think
        self.start_event = start
        self.answer_ms: list[float] = []
        self.image_ms: list[float] = []
        self.sent: dict[int, bool] = {}
        self.errors: list[str] = []
        self.xsrf: dict[str, str] = {}  # the review page's anti-forgery cookie and token

    def _req(self, conn, method: str, path: str, body: bytes | None = None) -> tuple[int, bytes]:
        headers = {"Content-Type": "application/json"} if body is not None else {}
        if method == "POST" and self.xsrf:  # as the review page's script sends it
            headers.update(xsrf_headers(self.xsrf))
        conn.request(method, path, body=body, headers=headers)
        resp = conn.getresponse()
        raw = resp.read()
        if method == "GET" and not self.xsrf:
            self.xsrf = xsrf_of(resp.getheader("Set-Cookie"), raw) or {}
        return resp.status, raw

    def run(self) -> None:
        rng = random.Random(self.index)
        base = f"/review/{self.token}"
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
        self.start_event.wait()
        try:
            status, _ = self._req(conn, "GET", base)
            status, raw = self._req(conn, "GET", f"{base}/state")
            total = json.loads(raw)["total"]
            for pos in range(total):
                t = time.perf_counter()
                status, img = self._req(conn, "GET", f"{base}/image/{pos}")
                self.image_ms.append(1000 * (time.perf_counter() - t))
                if status != 200 or not img.startswith(b"\x89PNG"):
                    self.errors.append(f"image {pos}: HTTP {status}")
                if self.think > 0:
                    time.sleep(self.think * rng.uniform(0.5, 1.5))
                yes = rng.random() < 0.3 + 0.4 * (self.index % 5) / 4
                body = json.dumps({"position": pos, "answer": "yes" if yes else "no",
                                   "seconds": 1.0, "comment": "",
                                   "submission": f"{self.token[:8]}-{pos}"}).encode()
                t = time.perf_counter()
                status, raw = self._req(conn, "POST", f"{base}/answer", body)
                self.answer_ms.append(1000 * (time.perf_counter() - t))
                if status != 200:
                    self.errors.append(f"answer {pos}: HTTP {status} {raw[:100]!r}")
                    continue
                self.sent[pos] = yes
                if rng.random() < self.resend:
                    status, raw = self._req(conn, "POST", f"{base}/answer", body)
                    if status != 200 or json.loads(raw)["stored"] != "repeated":
                        self.errors.append(f"resend {pos}: {status} {raw[:100]!r}")
        except Exception as exc:  # noqa: BLE001 - reported as a figure
            self.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            conn.close()


def _choice(db, campaign: str, n_plots: int) -> dict[str, list[str]]:
    """Configurations, sections and kinds of the first ``n_plots`` planned plots."""
    with db.session() as s:
        chosen = workshops_service.plan(s, campaign)[:n_plots]
    return {"configurations": sorted({p.configuration for p in chosen}),
            "sections": sorted({p.section for p in chosen}),
            "kinds": sorted({p.kind for p in chosen})}


def legacy_png(x_meas, y_meas, x_sim, y_sim, scale, *, title: str, x_label: str,
               y_label: str) -> bytes:
    """A review plot as render version 1 drew it (way A): a new figure for the plot, the
    whole figure drawn, saved with matplotlib's PNG writer (RGBA, zlib level 6); with the
    current :data:`STYLE` (margins of version 3), so its pixels are the reference of the
    current renderer's."""
    st, m, s = workshop_render.STYLE, workshop_render.STYLE["measurement"], workshop_render.STYLE["simulation"]
    with matplotlib.rc_context(workshop_canvas._RC):
        fig = Figure(figsize=(st["width_in"], st["height_in"]), dpi=st["dpi"])
        ax = fig.add_subplot(1, 1, 1)
        ax.set_axisbelow(True)
        ax.grid(True, color=st["grid_color"], linewidth=0.6)
        for x, y, look in ((x_meas, y_meas, m), (x_sim, y_sim, s)):
            ax.plot(x, y, color=look["color"], linewidth=look["linewidth"],
                    zorder=look["zorder"], label=look["label"])
        if scale.y.log:
            ax.set_yscale("log")
        else:
            ax.set_yticks(workshop_canvas._ticks(scale.y.lo, scale.y.hi, scale.y.step))
        ax.set_xticks(workshop_canvas._ticks(scale.x.lo, scale.x.hi, scale.x.step))
        ax.set_xlim(scale.x.lo, scale.x.hi)
        ax.set_ylim(scale.y.lo, scale.y.hi)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.set_title(title, loc="left")
        ax.legend(loc=st["legend"], frameon=True, framealpha=0.9)
        fig.subplots_adjust(**st["margins"])
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=st["dpi"], metadata={"Software": None})
    return buf.getvalue()


def _timed_create(db, name: str, campaign: str, choice: dict, legacy: bool) -> dict[str, Any]:
    """One creation, timed, with the renderer of ``legacy`` (A) or the current one (B);
    the render cache is emptied first so that both render every plot."""
    workshop_render.clear_cache()
    # legacy: a figure made for every plot, one plot after the other in this process
    way = workshop_render.serial_renderer(legacy_png) if legacy else contextlib.nullcontext()
    marks: dict[str, float] = {}
    t0 = time.perf_counter()

    def progress(stage: str, fraction: float, info: dict | None = None) -> None:
        marks.setdefault(stage, time.perf_counter() - t0)
    with way:
        out = workshops_service.create(db, name, campaign, **choice, repeats=0.0,
                                       progress=progress)
    total = time.perf_counter() - t0
    return {"way": "A" if legacy else "B", "plots": out["plots"], "create_s": round(total, 2),
            "render_s": round(total - marks.get("rendering plots", 0.0), 2),
            "loadavg_1min": round(os.getloadavg()[0], 2)}


def _timed_cli_create(url: str, name: str, campaign: str, choice: dict) -> dict[str, Any]:
    """One ``railval workshop create`` of the same plots in a fresh process (way C), timed
    from launch to exit: the interpreter's start, the imports, the render pool's start and the
    creation — what a user of the command line waits."""
    argv = [sys.executable, "-m", "railval.app", "--db", url, "workshop", "create", name,
            "--campaign", campaign, "--configurations", *choice["configurations"],
            "--sections", *choice["sections"], "--kinds", *choice["kinds"], "--repeats", "0"]
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=600, check=False)
    total = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"railval workshop create {name} exited {proc.returncode}: {proc.stderr[-2000:]}")
    made = re.search(r"created: (\d+) plots", proc.stdout)
    return {"way": "C", "plots": int(made.group(1)) if made else None, "create_s": round(total, 2),
            "loadavg_1min": round(os.getloadavg()[0], 2)}


def run_create_only(args: argparse.Namespace) -> dict[str, Any]:
    """``--create-only N``: A and B alternately N times each on one database (a first,
    untimed creation fills the validation results' cache both then read), then N creations
    by the command line in fresh processes (C)."""
    folder = Path(tempfile.mkdtemp(prefix="railval-bench-wsc-"))
    db = connect(args.url or f"sqlite:///{folder / 'bench.db'}")
    db.init()
    campaign = args.campaign
    if campaign is None:
        synth_service.ensure_demo(db)
        campaign = synth_service.DEMO_NAME
    choice = _choice(db, campaign, args.plots)
    tag = f"{int(time.time()) % 100000:05d}"
    warm = _timed_create(db, f"bench-warm-{tag}", campaign, choice, legacy=False)
    runs = []
    for i in range(args.create_only):
        for legacy in (True, False):
            runs.append(_timed_create(db, f"bench-{'a' if legacy else 'b'}{i}-{tag}", campaign,
                                      choice, legacy))
    url = str(db.engine.url.render_as_string(hide_password=False))
    db.dispose()
    for i in range(args.create_only):
        runs.append(_timed_cli_create(url, f"bench-c{i}-{tag}", campaign, choice))
    a = [r["create_s"] for r in runs if r["way"] == "A"]
    b = [r["create_s"] for r in runs if r["way"] == "B"]
    c = [r["create_s"] for r in runs if r["way"] == "C"]
    return {"plots": runs[0]["plots"] if runs else warm["plots"], "render_workers": workshop_render.RENDER_WORKERS,
            "warm_up": warm, "runs": runs, "A_create_s": [min(a), max(a)] if a else None,
            "B_create_s": [min(b), max(b)] if b else None,
            "C_cli_create_s": [min(c), max(c)] if c else None, "cpu_count": os.cpu_count(),
            "database": str(db.engine.url).split(":")[0]}


def run(args: argparse.Namespace) -> dict[str, Any]:
    if getattr(args, "create_only", 0):
        return run_create_only(args)

    folder = Path(tempfile.mkdtemp(prefix="railval-bench-ws-"))
    url = args.url or f"sqlite:///{folder / 'bench.db'}"
    setup = _setup(url, args.campaign, args.plots, args.reviewers)
    port = free_port()
    log = open(folder / "serve.log", "wb")  # noqa: SIM115 - closed below
    proc = subprocess.Popen([sys.executable, "-m", "railval.app", "--db", url, "serve",
                             "--no-demo", "--port", str(port)], stdout=log, stderr=log)
    try:
        deadline = time.monotonic() + 300
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/workshops/login", timeout=10):
                    break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit(f"railval serve did not start: {folder / 'serve.log'}") from None
                time.sleep(0.3)
        rss_before = _rss_kib(proc.pid)
        go = threading.Event()
        threads = [_Reviewer(port, name, tok, i, args.resend, args.think, go)
                   for i, (name, tok) in enumerate(setup["tokens"].items())]
        for t in threads:
            t.start()
        t0 = time.perf_counter()
        go.set()
        for t in threads:
            t.join()
        wall = time.perf_counter() - t0
        rss_after = _rss_kib(proc.pid)
    finally:
        proc.terminate()
        proc.wait(30)
        log.close()
    stored, lost, duplicated, wrong = _check(url, threads)
    answer_ms = [x for t in threads for x in t.answer_ms]
    image_ms = [x for t in threads for x in t.image_ms]
    t = time.perf_counter()
    db = connect(url)
    doc = analyse(db, "bench")  # every answer of the workshop (earlier runs included)
    analyse_s = time.perf_counter() - t
    check = verify_database(db, signals=False, full=False)  # every answer is a signed row
    db.dispose()
    out = {
        "reviewers": args.reviewers, "places_per_reviewer": setup["plots"],
        "workshop_create_s": None if setup["create_s"] is None else round(setup["create_s"], 1),
        "think_s": args.think, "database": url.split(":")[0],
        "answers_expected": args.reviewers * setup["plots"], "answers_stored": stored,
        "lost": lost, "duplicated": duplicated, "wrong_value": wrong,
        "errors": sum(len(t.errors) for t in threads),
        "first_errors": [e for t in threads for e in t.errors][:5],
        "answer_round_trip": _summary(answer_ms), "next_plot_shown": _summary(image_ms),
        "wall_s": round(wall, 1), "answers_per_s": round(len(answer_ms) / wall, 1),
        "server_rss_mib_before": round(rss_before / 1024, 1),
        "server_rss_mib_after": round(rss_after / 1024, 1),
        "analyse_s": round(analyse_s, 2), "analysed_reviewers": len(doc["reviewers"]),
        "audit_verify_quick_s": round(check.seconds, 2), "audit_rows": check.rows,
        "audit_signed_rows": check.signed_rows, "audit_ok": check.ok,
        "cpu_count": os.cpu_count(), "loadavg_1min": round(os.getloadavg()[0], 2),
    }
    if not args.keep and args.url is None:
        shutil.rmtree(folder, ignore_errors=True)
    else:
        out["folder"] = str(folder)
    return out


def _check(url: str, threads: list[_Reviewer]) -> tuple[int, int, int, int]:
    """(stored, lost, duplicated, wrong value) from the database against what was sent."""
    db = connect(url)
    with db.session() as s:
        rows = s.execute(select(models.AppUser.username, models.WorkshopAnswer.position, models.WorkshopAnswer.answer)
                         .join(models.WorkshopReviewer, models.WorkshopAnswer.reviewer_id == models.WorkshopReviewer.id)
                         .join(models.AppUser, models.WorkshopReviewer.user_id == models.AppUser.id)).all()
    db.dispose()
    names = {t.name for t in threads}
    rows = [r for r in rows if r[0] in names]
    seen: dict[tuple[str, int], list[bool]] = {}
    for u, pos, ans in rows:
        seen.setdefault((u, pos), []).append(bool(ans))
    duplicated = sum(len(v) - 1 for v in seen.values())
    lost = wrong = 0
    for t in threads:
        for pos, yes in t.sent.items():
            got = seen.get((t.name, pos))
            if not got:
                lost += 1
            elif got[0] != yes:
                wrong += 1
    return len(rows), lost, duplicated, wrong
