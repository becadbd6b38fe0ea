"""nginx answers Bokeh's and Panel's static files (railval.app.nginx_static, issue 41): real
nginx rendered from deploy/nginx/railval.conf.template in front of a real app process on
loopback, PostgreSQL, Chromium signing in through the proxy (as tests/test_team_server.py).

* the static responses through nginx carry exactly the app's security headers, Content-Type
  and bytes (compared with the app's own answer to the same URL, header by header);
* a static request is never proxied (nginx's log: no upstream), and the app's log has none;
* ``..`` and percent-encoded traversal under /static/ never reads a file outside the folders;
* Chromium signs in through nginx and sees the overview with no CSP violation and no failed
  request.
"""

from __future__ import annotations

import gzip
import http.client
import re
import time

import pytest

from railval.app import nginx_static, security
from railval.app.bench.topology import TEMPLATE, insecure_context
from tests.browser_support import block_fonts
from tests.topology_support import demo_topology

pytestmark = [pytest.mark.browser, pytest.mark.postgres]
TIMEOUT_MS = 60_000

#: URLs as the app's pages request them (versioned and not), and unknown ones
STATIC_URLS = [
    "/static/js/bokeh.min.js?v=1",
    "/static/js/bokeh-widgets.min.js",
    "/static/extensions/panel/panel.min.js?v=1",
    "/static/extensions/panel/css/markdown.css?v=1.9.4",
    "/static/extensions/panel/bundled/fast/js/fast_design.js",
    "/static/extensions/panel/bundled/reactiveesm/es-module-shims@%5E1.10.0/dist/es-module-shims.min.js",
]
MISSING_URLS = ["/static/js/no-such-file.js", "/static/extensions/panel/no-such.css",
                "/static/extensions/other/x.js", "/static/js/", "/static/extensions/panel/"]
#: attempts to read outside the static folders (the package's own code, the system's files)
TRAVERSALS = [
    "/static/../../../../../../etc/passwd",
    "/static/js/../../../../../../../../etc/passwd",
    "/static/js/..%2f..%2f..%2f..%2f..%2f..%2f..%2fetc%2fpasswd",
    "/static/%2e%2e/%2e%2e/%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
    "/static/%2e%2e/__init__.py",
    "/static/..%2f__init__.py",
    "/static..%2f__init__.py",
    "/static../server/__init__.py",
    "/static/extensions/panel/..%2f__init__.py",
    "/static/extensions/panel/%2e%2e/__init__.py",
    "/static/extensions/panel/..%252f__init__.py",
    "/static/extensions/panel%2f..%2f..%2f..%2f__init__.py",
]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    with demo_topology(tmp_path_factory.mktemp("nginx_static"), n_sections=2, n_apps=1, admin=False,
                       accounts=[("eng", "engineer password", "engineer")]) as (topo, _db, _):
        yield topo


def _get(conn_factory, path: str, gzip_ok: bool = True):
    conn = conn_factory()
    try:
        conn.request("GET", path, headers={"Accept-Encoding": "gzip"} if gzip_ok else {})
        r = conn.getresponse()
        body = r.read()
        if r.getheader("Content-Encoding") == "gzip":
            body = gzip.decompress(body)
        return r.status, {k.lower(): v for k, v in r.getheaders()}, body
    finally:
        conn.close()


def _via_nginx(topo):
    return lambda: http.client.HTTPSConnection("127.0.0.1", topo.port, timeout=30,
                                               context=insecure_context())


def _direct(topo):
    port = next(iter(topo.apps))
    return lambda: http.client.HTTPConnection("127.0.0.1", port, timeout=30)


def _log(topo) -> list[tuple[str, str, str]]:
    """nginx's access log: (status, upstream address or '-', request line) per request."""
    text = (topo.workdir / "nginx" / "logs" / "access.log").read_text()
    return re.findall(r'^(\d+) (\S+) "([^"]*)"$', text, flags=re.MULTILINE)


def security_differences(app: dict[str, str], proxy: dict[str, str]) -> list[str]:
    """Every security header of the app whose value through nginx is not the app's own."""
    return [f"{name}: app {app.get(name.lower())!r}, nginx {proxy.get(name.lower())!r}"
            for name in security.HEADERS if proxy.get(name.lower()) != app.get(name.lower())]


def test_static_files_through_nginx_are_the_apps_and_carry_its_headers(site):
    before = len(_log(site))
    for path in STATIC_URLS:
        a_status, app, a_body = _get(_direct(site), path)
        n_status, ngx, n_body = _get(_via_nginx(site), path)
        assert (a_status, n_status) == (200, 200), path
        assert security_differences(app, ngx) == [], path
        assert all(app.get(name.lower()) == value for name, value in security.HEADERS.items())
        assert ngx["content-type"] == app["content-type"], path
        assert n_body == a_body, path
        assert ngx["strict-transport-security"] == "max-age=31536000"
        versioned = "?v=" in path
        assert ngx["cache-control"] == (nginx_static.CACHE_VERSIONED if versioned
                                        else nginx_static.CACHE_UNVERSIONED), path
    # compressed for a browser, whole for a client without gzip
    _status, ngx, body = _get(_via_nginx(site), STATIC_URLS[0])
    assert ngx.get("content-encoding") == "gzip"
    _status, plain, plain_body = _get(_via_nginx(site), STATIC_URLS[0], gzip_ok=False)
    assert "content-encoding" not in plain and plain_body == body
    for path in MISSING_URLS:
        a_status, app, _ = _get(_direct(site), path)
        n_status, ngx, _ = _get(_via_nginx(site), path)
        assert n_status == 404, (path, n_status)
        assert a_status in (403, 404), (path, a_status)  # Tornado: 403 for a folder
        assert security_differences(app, ngx) == [], path
    # none of them reached the app process through nginx
    mine = _log(site)[before:]
    static = [row for row in mine if " /static/" in row[2]]
    assert len(static) == len(STATIC_URLS) + 2 + len(MISSING_URLS), mine
    assert [row for row in static if row[1] != "-"] == []


def _app_log(topo) -> str:
    return "".join(p.read_text(errors="replace") for p in sorted(topo.workdir.glob("app-*.log")))


def test_the_app_process_never_sees_a_static_request(site):
    """The app logs every 4xx it answers (Tornado's access log, WARNING): the unknown static
    paths asked through nginx leave no line there; asked of the app directly, they do (the
    check can fail)."""
    start = len(_app_log(site))
    for path in MISSING_URLS[:3]:
        assert _get(_via_nginx(site), path)[0] == 404
    time.sleep(0.5)
    assert "/static/" not in _app_log(site)[start:]
    for path in MISSING_URLS[:3]:
        assert _get(_direct(site), path)[0] == 404
    deadline = time.monotonic() + 5
    while _app_log(site)[start:].count("404 GET /static/") < 3 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _app_log(site)[start:].count("404 GET /static/") == 3


def test_a_dropped_header_is_caught():
    """The comparison above fails when the rendering leaves a header out (the snippet rendered
    without X-Frame-Options, as a careless edit would)."""
    app = {k.lower(): v for k, v in security.HEADERS.items()}
    planted = {k: v for k, v in security.HEADERS.items() if k != "X-Frame-Options"}
    lines = nginx_static.snippet({"js": "text/javascript"}, headers=planted)
    proxy = {m[0].lower(): m[1] for m in re.findall(r'^add_header (\S+) "([^"]*)" always;$', lines,
                                                     flags=re.MULTILINE)}
    assert security_differences(app, proxy) == ["X-Frame-Options: app 'DENY', nginx None"]
    full = nginx_static.snippet({"js": "text/javascript"})
    proxy = {m[0].lower(): m[1] for m in re.findall(r'^add_header (\S+) "([^"]*)" always;$', full,
                                                     flags=re.MULTILINE)}
    assert security_differences(app, proxy) == []
    with pytest.raises(ValueError, match="cannot be written"):
        nginx_static.snippet({}, headers={"X-Test": 'a"; add_header X-Evil "1'})


def test_every_static_location_includes_the_snippet():
    """nginx does not inherit add_header into a location that sets its own: each location
    under /static/ must include the snippet itself, and alias a folder ending in '/'."""
    text = TEMPLATE.read_text()
    blocks = re.findall(r"location\s+(/static\S*)\s*\{(.*?)\n    \}", text, flags=re.DOTALL)
    assert {b[0] for b in blocks} == {"/static/", "/static/extensions/", "/static/extensions/panel/"}
    for where, body in blocks:
        assert "include ${RAILVAL_STATIC_CONF};" in body, where
    assert re.search(r"alias \$\{RAILVAL_BOKEH_STATIC\};", text)
    assert re.search(r"alias \$\{RAILVAL_PANEL_STATIC\};", text)


def test_the_app_serves_only_panels_extension():
    """nginx answers /static/extensions/panel/ only: the app process has no other Bokeh
    extension folder (a new one would be 404 through nginx)."""
    import railval.app.main  # noqa: F401  (Panel registers its extension)

    assert nginx_static.extension_dirs() == {"panel": nginx_static.folders()["panel"]}


def test_traversal_never_leaves_the_static_folders(site):
    """nginx resolves ``..`` (also percent-encoded) before it chooses a location: a path that
    climbs out of /static/ is refused (400) or is no longer a static path and goes to the app,
    which answers it as any unknown path; no file outside the folders is ever read (each
    target here, the packages' ``__init__.py`` and /etc/passwd, holds these words)."""
    before = len(_log(site))
    for path in TRAVERSALS:
        status, _headers, body = _get(_via_nginx(site), path)
        assert status in (400, 403, 404), (path, status)
        assert b"root:" not in body and b"import" not in body, path
    for status, upstream, request in _log(site)[before:]:
        if upstream == "-":  # answered by nginx itself
            assert status in ("400", "404"), request


#: the one CSP report of the app's page, through nginx or not: es-module-shims (Panel's
#: ReactiveESM loader) probes whether the browser runs a ``blob:`` module script; the CSP's
#: script-src refuses it and the shim does without (nothing on the page uses it)
KNOWN_CSP_REPORTS = ["script-src-elem blob"]


def _sign_in_and_watch(browser, base: str) -> tuple[list[str], list[str], list[str]]:
    """Sign in as the engineer at ``base`` in a fresh browser context and wait for the
    overview: (CSP violations, failed requests, responses >= 400)."""
    context = browser.new_context(ignore_https_errors=True)
    context.add_init_script("""
        window.__csp = [];
        document.addEventListener('securitypolicyviolation',
            e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));
    """)
    failed, bad = [], []
    page = context.new_page()
    block_fonts(page)
    page.on("requestfailed", lambda r: failed.append(f"{r.url} {r.failure}"))
    page.on("response", lambda r: bad.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    page.goto(f"{base}/app")
    page.fill("#username", "eng")
    page.fill("#password", "engineer password")
    page.click("#signin")
    page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
    page.locator(".rv-zone-chart, canvas").first.wait_for(timeout=TIMEOUT_MS)
    page.wait_for_timeout(500)
    csp = page.evaluate("window.__csp")
    context.close()
    # the refused probe (KNOWN_CSP_REPORTS) is also a failed request: counted once, as a report
    failed = [f for f in failed if not (f.startswith("blob:") and f.endswith(" csp"))]
    return csp, failed, bad


def test_signed_in_engineer_through_nginx_no_csp_violation_no_failed_request(site, browser):
    before = len(_log(site))
    csp, failed, bad = _sign_in_and_watch(browser, site.url)
    assert failed == [] and bad == []
    assert csp == KNOWN_CSP_REPORTS
    # the same page straight from the app process reports the same
    direct = f"http://127.0.0.1:{next(iter(site.apps))}"
    assert _sign_in_and_watch(browser, direct) == (KNOWN_CSP_REPORTS, [], [])
    static = [row for row in _log(site)[before:] if " /static/" in row[2]]
    assert len(static) >= 15, static
    assert [row for row in static if row[1] != "-" or row[0] not in ("200", "304")] == []
