"""The served app under attack (Playwright + Debian's Chromium, and plain HTTP/websocket
clients): hostile configuration names stay text, every response carries the security
headers, the page requests nothing from another host, forged session ids and foreign
websocket origins are refused, and '*' is never an allowed origin."""

from __future__ import annotations

import urllib.error
import urllib.request
from urllib.parse import urlparse

import pytest
from sqlalchemy import update

from railval.app.security import CSP
from tests.browser_support import nav, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
PAYLOAD = '"><img src=x onerror="window.__xss=(window.__xss||0)+1">'
TRACKER = "http://tracker.example/pixel.png"
#: LaTeX in user text: MathJax's \href made a javascript: link of it while Markdown panes
#: typeset math (app/main.py, no_math_typesetting)
MATH = r"$$\href{javascript:window.__xss=(window.__xss||0)+1}{\text{the report}}$$"


@pytest.fixture(scope="module")
def app_url(tmp_path_factory):
    require_browser()
    from railval.db.models import Campaign, Configuration
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("browser-sec"))
    # names stored before the safe set existed (or written behind railval's back)
    with db.session(write=True) as s:
        s.execute(update(Configuration).where(Configuration.name == "baseline")
                  .values(name=PAYLOAD))
        s.execute(update(Campaign).values(
            description=f"tracked ![pixel]({TRACKER}) <img src='{TRACKER}'> {MATH}"))
    with served_app(db) as url:
        yield url
    db.dispose()


def test_hostile_names_stay_text_and_nothing_leaves_the_host(page, app_url):
    hosts: set[str] = set()
    blocked: list[str] = []

    def host(url: str) -> str:
        return urlparse(url[5:] if url.startswith("blob:") else url).hostname or url

    page.on("requestfinished", lambda req: hosts.add(host(req.url)))
    page.on("requestfailed", lambda req: blocked.append(req.url)
            if host(req.url) != "127.0.0.1" else None)
    dialogs: list[str] = []
    page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
    page.set_viewport_size({"width": 1280, "height": 1200})
    response = page.goto(app_url)
    assert response.headers["content-security-policy"] == CSP
    assert response.headers["x-content-type-options"] == "nosniff"
    page.locator("canvas, .rv-zone-chart").first.wait_for(state="attached", timeout=120_000)
    page.locator(".rv-main h2", has_text="Campaign overview").wait_for(timeout=120_000)
    nav(page, "Compare signals")
    page.locator(".rv-main h2", has_text="Compare").wait_for(timeout=120_000)
    page.wait_for_timeout(3000)
    # the MultiChoice (Choices.js renders labels as HTML) shows the name as text
    choices = page.locator(".choices")
    assert choices.count() >= 1
    choices.first.click()
    page.wait_for_timeout(1500)
    screenshot(page, "security-compare-hostile-name")
    assert page.evaluate("window.__xss || 0") == 0
    assert not dialogs
    assert page.locator(".choices").first.get_by_text(PAYLOAD, exact=False).count() >= 1
    assert hosts <= {"127.0.0.1"}, f"requests to other hosts: {sorted(hosts - {'127.0.0.1'})}"
    # the description's raw <img> is escaped and its Markdown image replaced: not even tried
    assert not blocked, blocked


_LINKS_JS = """() => { const out = []; const walk = (n) => { if (n.shadowRoot) walk(n.shadowRoot);
  for (const c of n.children || []) { const h = c.getAttribute && c.getAttribute('href');
    if (h) out.push(h); if (c.tagName && c.tagName.toLowerCase().startsWith('mjx')) out.push('mjx');
    walk(c); } }; walk(document.body); return out; }"""


def test_latex_in_a_description_stays_text(page, app_url):
    """A campaign description holding ``$$\\href{javascript:…}{…}$$`` is shown as those
    characters: no MathJax output, no javascript: link (it used to be one, running script in
    the app's origin when clicked), and MathJax's bundle is not even loaded."""
    scripts: list[str] = []
    page.on("requestfinished", lambda req: scripts.append(req.url) if req.resource_type == "script" else None)
    page.set_viewport_size({"width": 1280, "height": 1000})
    page.goto(app_url)
    desc = page.locator(".rv-main", has_text="tracked").first
    desc.wait_for(timeout=120_000)
    page.wait_for_timeout(2000)
    screenshot(page, "security-latex-description")
    found = page.evaluate(_LINKS_JS)
    assert "mjx" not in found
    assert not [h for h in found if h.strip().lower().startswith("javascript:")], found
    assert page.locator(".rv-main").get_by_text(MATH).count() == 1
    # the raw <img> beside it shows as typed too, not as a link holding escaped characters
    assert page.locator(".rv-main").get_by_text(f"<img src='{TRACKER}'>").count() == 1
    assert not [h for h in found if "tracker.example" in h], found
    assert scripts and not [u for u in scripts if "mathjax" in u.lower()], scripts
    assert page.evaluate("window.__xss || 0") == 0


def test_every_response_carries_the_headers(app_url):
    base = app_url.rsplit("/app", 1)[0]
    for path in ("/app", "/static/js/bokeh.min.js", "/no-such-page"):
        try:
            resp = urllib.request.urlopen(base + path, timeout=60)
        except urllib.error.HTTPError as exc:
            resp = exc
        assert resp.headers["Content-Security-Policy"] == CSP, path
        assert resp.headers["X-Content-Type-Options"] == "nosniff", path
        assert "frame-ancestors 'none'" in resp.headers["Content-Security-Policy"]


def test_forged_session_id_refused(app_url):
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(app_url + "?bokeh-session-id=forged-by-evil-example", timeout=60)
    assert info.value.code == 403


def test_foreign_websocket_origin_refused(app_url):
    import asyncio

    from tornado.httpclient import HTTPClientError, HTTPRequest
    from tornado.websocket import websocket_connect

    ws_url = app_url.replace("http://", "ws://") + "/ws"

    async def attempt():
        req = HTTPRequest(ws_url, headers={"Origin": "http://evil.example"})
        conn = await websocket_connect(req)
        conn.close()

    import threading

    outcome: list[BaseException | None] = []

    def run():
        try:
            asyncio.run(attempt())
            outcome.append(None)
        except BaseException as exc:  # noqa: BLE001 - reported below
            outcome.append(exc)

    th = threading.Thread(target=run)
    th.start()
    th.join(120)
    assert isinstance(outcome[0], HTTPClientError), outcome
    assert outcome[0].code == 403


def test_any_origin_is_refused(tmp_path):
    from railval.app.main import serve
    from railval.core.errors import InvalidParameter
    from railval.db.engine import connect

    db = connect(f"sqlite:///{tmp_path / 'x.db'}")
    with pytest.raises(InvalidParameter, match="cross-site websocket hijacking"):
        serve(db, port=0, allow_websocket_origin=["*"])
    dockerfile = (__import__("pathlib").Path(__file__).parent.parent / "deploy" / "Dockerfile")
    assert "'*'" not in dockerfile.read_text() and '"*"' not in dockerfile.read_text()
