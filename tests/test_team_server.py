"""The production topology on loopback, without containers (docs/app.md, "Team server"):
PostgreSQL, two ``railval serve`` processes behind real nginx (TLS, sticky route cookie,
websocket upgrade; ``deploy/nginx/railval.conf.template`` rendered as a site renders it),
Chromium signing in through the proxy.

One module-scoped topology serves all tests here (starting it costs ~10 s on 2 cores).
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import time
import urllib.error
import urllib.request
import uuid

import pytest
from sqlalchemy import func, select

from railval.app.bench.bench_workshop import xsrf_headers, xsrf_of
from railval.app.bench.topology import insecure_context
from tests.browser_support import block_fonts
from tests.topology_support import demo_topology

pytestmark = [pytest.mark.browser, pytest.mark.postgres]
TIMEOUT_MS = 60_000
REVIEWERS = 6


def _workshop(db) -> dict[str, str]:
    """Workshop W on the demo campaign with an invitation per reviewer: name → token."""
    from railval.app.services import workshops as wsvc
    from railval.db import workshops as wsdb

    wsvc.create(db, "W", "demo", kinds=["Y_time"], repeats=0.0, actor="admin")
    with db.session(write=True) as s:
        w = wsdb.get_workshop(s, "W")
        return {f"r{k}": wsdb.invite(s, w, f"r{k}", seed=k) for k in range(REVIEWERS)}


@pytest.fixture(scope="module")
def team(tmp_path_factory):
    accounts = [("admin", "admin password 1", "admin"), ("eng", "engineer password", "engineer")]
    with demo_topology(tmp_path_factory.mktemp("team"), n_sections=4, accounts=accounts,
                       prepare=_workshop) as (topo, db, tokens):
        yield topo, db, tokens


def _sign_in(context, base: str, username: str, password: str, *, route_fonts: bool = True):
    """Sign in on a new page of ``context``; ``route_fonts=False`` where the browser fails the font
    hosts itself (``topology.NO_FONT_HOSTS``): a routed page reads nothing from the browser's cache."""
    page = context.new_page()
    if route_fonts:
        block_fonts(page)
    page.goto(f"{base}/app")
    page.fill("#username", username)
    page.fill("#password", password)
    page.click("#signin")
    page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
    return page


def _process(page) -> int:
    """The app process this browser's route cookie leads to (its /health through nginx)."""
    return page.evaluate("() => fetch('/health').then(r => r.json()).then(d => d.process)")


def _post_answer(base: str, token: str, position: int, answer: bool, submission: str) -> tuple[int, float]:
    """POST one answer through the proxy until the server confirms it (like the review page,
    which repeats an answer the server did not confirm); returns (attempts, seconds)."""
    body = json.dumps({"position": position, "answer": "yes" if answer else "no",
                       "seconds": 1.0, "submission": submission}).encode()
    t0, attempts = time.perf_counter(), 0
    xsrf = None
    while True:
        attempts += 1
        try:
            if xsrf is None:  # the review page hands out the anti-forgery token
                with urllib.request.urlopen(f"{base}/review/{token}", timeout=20,
                                            context=insecure_context()) as r:
                    xsrf = xsrf_of(", ".join(r.headers.get_all("Set-Cookie") or []), r.read())
                assert xsrf is not None, "the review page gave no anti-forgery token"
        except (urllib.error.URLError, OSError):
            if attempts > 50:
                raise
            time.sleep(0.1)
            continue
        req = urllib.request.Request(f"{base}/review/{token}/answer", data=body, method="POST",
                                     headers={"Content-Type": "application/json",
                                              **xsrf_headers(xsrf)})
        try:
            with urllib.request.urlopen(req, timeout=20, context=insecure_context()) as r:
                doc = json.loads(r.read())
                assert doc["position"] == position
                return attempts, time.perf_counter() - t0
        except (urllib.error.URLError, OSError):
            if attempts > 50:
                raise
            time.sleep(0.1)


def test_sticky_sessions_failover_and_no_answer_lost(team, browser):
    from railval.db.models import WorkshopAnswer

    topo, db, tokens = team
    base = topo.url
    ctx1 = browser.new_context(ignore_https_errors=True, viewport={"width": 1280, "height": 900})
    page = _sign_in(ctx1, base, "eng", "engineer password")
    first = _process(page)
    assert first in {p.pid for p in topo.apps.values()}
    cookies = {c["name"]: c for c in ctx1.cookies()}
    assert cookies["railval_route"]["secure"] and cookies["railval_route"]["httpOnly"]
    # a reload lands in the same process, and its websocket session works there
    for _ in range(2):
        page.reload()
        page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
        assert _process(page) == first
    page.locator(".rv-nav").get_by_role("button", name="Compare signals", exact=True).click()
    page.locator("canvas").first.wait_for(state="attached", timeout=TIMEOUT_MS)

    # Panel's admin page: admins only
    assert ctx1.request.get(f"{base}/admin").status == 403
    ctx_admin = browser.new_context(ignore_https_errors=True)
    _sign_in(ctx_admin, base, "admin", "admin password 1")
    assert ctx_admin.request.get(f"{base}/admin").status == 200
    ctx_admin.close()

    # reviewers answer through the proxy while the engineer's process is killed
    per_reviewer = 8
    jobs = [(tokens[f"r{k}"], i, (i + k) % 2 == 0, f"{k}-{i}-{uuid.uuid4().hex[:6]}")
            for i in range(per_reviewer) for k in range(REVIEWERS)]
    with cf.ThreadPoolExecutor(REVIEWERS) as pool:
        futures = [pool.submit(_post_answer, base, *job) for job in jobs[: len(jobs) // 3]]
        cf.wait(futures)
        topo.kill(topo.port_of(first))
        futures += [pool.submit(_post_answer, base, *job) for job in jobs[len(jobs) // 3:]]
        results = [f.result() for f in futures]
    with db.session() as s:
        stored = s.scalar(select(func.count()).select_from(WorkshopAnswer))
    assert stored == len(jobs) == REVIEWERS * per_reviewer  # 0 answers lost

    # the killed process's browser and a new one both continue on the other process
    (other,) = [p.pid for p in topo.apps.values()]
    page.reload()
    page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)  # signed cookie valid on every process
    assert _process(page) == other
    ctx2 = browser.new_context(ignore_https_errors=True)
    page2 = _sign_in(ctx2, base, "eng", "engineer password")
    assert _process(page2) == other
    page2.locator(".rv-nav").get_by_role("button", name="Compare signals", exact=True).click()
    page2.locator("canvas").first.wait_for(state="attached", timeout=TIMEOUT_MS)
    retried = sum(a > 1 for a, _ in results)
    print(f"answers {len(results)}, repeated after a refused connection {retried}")
    ctx1.close()
    ctx2.close()


def test_upload_through_the_proxy_equals_cli_import(team, browser, tmp_path):
    """An engineer uploads a campaign zip on the Import page through nginx; the stored signals
    are identical (content hashes per section, configuration and channel) to the same folder
    imported by ``railval import``, and the audit row names the engineer."""
    from railval.app.cli import main
    from railval.db.engine import connect
    from railval.db.models import AuditEvent
    from tests.factories import write_demo_campaign
    from tests.test_web_import import signal_hashes, zip_folder

    topo, db, _ = team
    folder = tmp_path / "upl"
    write_demo_campaign(folder, n_sections=4, fs=50.0, n_configs=2, name="upl", seed=3)
    archive = tmp_path / "upl.zip"
    archive.write_bytes(zip_folder(folder, "upl"))

    ctx = browser.new_context(ignore_https_errors=True, viewport={"width": 1280, "height": 1000})
    page = _sign_in(ctx, topo.url, "eng", "engineer password")
    page.locator(".rv-nav").get_by_role("button", name="Import", exact=True).click()
    page.get_by_text("Largest upload: 100 MB").wait_for(timeout=TIMEOUT_MS)
    page.locator(".rv-import-file input[type=file]").set_input_files(str(archive))
    page.wait_for_timeout(500)  # the file reaches the server over the websocket
    page.locator(".rv-import-go button").click()
    page.locator(".rv-import-ok").wait_for(timeout=TIMEOUT_MS)
    from tests.browser_support import screenshot

    screenshot(page, "team-import-page")
    ctx.close()

    cli_url = f"sqlite:///{tmp_path / 'cli.db'}"
    assert main(["--db", cli_url, "import", str(folder), "--no-progress"]) == 0
    cli = connect(cli_url)
    try:
        assert signal_hashes(db, "upl") == signal_hashes(cli, "upl")
    finally:
        cli.dispose()
    with db.session() as s:
        ev = s.scalars(select(AuditEvent).where(AuditEvent.object == "campaign:upl")).one()
        assert ev.actor == "eng" and ev.action == "campaign.import"


def test_batch_validation_on_a_dask_cluster_equals_local(team):
    """The topology's batch side: a Dask LocalCluster (2 worker processes) validates the
    campaign from the same PostgreSQL database; the verdict equals the local run's."""
    distributed = pytest.importorskip("dask.distributed")
    from railval.app.services.validation import validate_configurations
    from railval.db.models import ResultCache

    _, db, _ = team
    local = validate_configurations(db, "demo", ["baseline"], n_boot=100)
    with db.session(write=True) as s:  # the cluster computes everything again
        s.query(ResultCache).delete()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        dask = validate_configurations(db, "demo", ["baseline"], n_boot=100,
                                       scheduler=cluster.scheduler_address, chunk_sections=2)
    def verdict(result) -> dict:  # without the cache counts (provenance, not the verdict)
        doc = result.to_dict()
        doc["info"] = {k: v for k, v in doc["info"].items()
                       if k not in ("sections_measured", "sections_simulated")}
        return doc

    assert dask["baseline"].info["sections_measured"] == {"cached": 0, "computed": 4}
    assert verdict(dask["baseline"]) == verdict(local["baseline"])


def test_a_returning_engineers_tab_reads_the_browser_cache(team, playwright):
    """What ``bench team --during-cached`` measures is a real cache (docs/app.md "A returning
    engineer's first page"): with the topology's certificate trusted by its key
    (:func:`railval.app.bench.topology.browser_trust`) and no request interception, a second tab
    of a signed-in engineer's browser takes the versioned static files (nginx: immutable) from
    the cache — 0 bytes over the wire — where the first tab fetched them."""
    from railval.app.bench.topology import browser_trust
    from tests.browser_support import CHROMIUM, CHROMIUM_ARGS

    topo, _db, _tokens = team
    browser = playwright.chromium.launch(executable_path=CHROMIUM,
                                         args=[*CHROMIUM_ARGS, *browser_trust(topo.workdir / "tls.crt")])
    try:
        ctx = browser.new_context(viewport={"width": 1280, "height": 900})  # no certificate error passed over
        page = _sign_in(ctx, topo.url, "eng", "engineer password", route_fonts=False)
        versioned = """() => performance.getEntriesByType('resource')
            .filter(r => r.name.includes('/static/') && r.name.includes('?v='))
            .map(r => [r.name, r.transferSize])"""
        first = page.evaluate(versioned)
        tab = ctx.new_page()
        tab.goto(f"{topo.url}/app")
        tab.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
        second = tab.evaluate(versioned)
    finally:
        browser.close()
    assert len(first) >= 5 and all(size > 0 for _, size in first), first
    assert {name for name, _ in second} == {name for name, _ in first}
    assert [name for name, size in second if size != 0] == [], second

