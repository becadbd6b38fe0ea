"""Revocation in open tabs and no session token for same-site pages, in Chromium
(docs/security.md, threat model).

* a page on another loopback port (same site: the SameSite=Lax cookie is sent) includes the
  app's ``autoload.js`` as a script: it gets a 404 with no Bokeh session token and no cookie;
* an engineer's open tab after ``railval user disable`` cannot calibrate or simulate:
  "Your access has ended", nothing stored;
* a reviewer's open sign-off form after the reviewer role is changed cannot sign (the role
  change ended the session).
"""

from __future__ import annotations

import http.server
import os
import threading

import pytest

from railval.app.cli import main
from railval.db import audit, repo, users
from railval.db import signoff as db_signoff
from tests.browser_support import require_browser, screenshot, served_app, sign_in

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    from tests.browser_support import demo_database

    os.environ["RAILVAL_COOKIE_SECRET"] = "r" * 48
    db = demo_database(tmp_path_factory.mktemp("browser-revocation"))
    with db.session(write=True) as s:
        users.create_user(s, "adm", password="admin password", roles=["admin"])
        users.create_user(s, "eng", display_name="Erik Engineer", password="engineer password",
                          roles=["engineer"])
        users.create_user(s, "rev", display_name="Rita Reviewer", password="reviewer password",
                          roles=["reviewer"])
    with served_app(db) as url:
        yield db, url.rsplit("/app", 1)[0]
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def cli(db, *argv) -> int:
    return main(["--db", db.url, "--as", "adm", *argv])


def test_autoload_from_another_port_gets_no_token(page, app):
    db, base = app
    sign_in(page, base, "eng", "engineer password")
    cookies = {c["name"]: c["value"] for c in page.context.cookies()}
    assert "railval_session" in cookies
    html = (f'<html><body><div id="x"></div><script src="{base}/app/autoload.js?'
            'bokeh-autoload-element=x&bokeh-absolute-url=' + base + '/app"></script>'
            '<p id="done">attacker page</p></body></html>').encode()

    class Evil(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(html)))
            self.end_headers()
            self.wfile.write(html)

        def log_message(self, *a):
            pass

    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Evil)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    seen = []
    page.on("response", lambda r: seen.append(r) if "autoload.js" in r.url else None)
    try:
        page.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
        page.locator("#done").wait_for(timeout=TIMEOUT_MS)
        page.wait_for_timeout(500)
    finally:
        evil.shutdown()
    assert seen, "the browser did not request autoload.js"
    resp = seen[0]
    assert "railval_session=" in resp.request.headers.get("cookie", "")  # it was sent …
    body = resp.text()  # what the browser received (empty: a refused cross-site script)
    assert resp.status == 404  # … and nothing came back
    assert "token" not in body.lower() and cookies["railval_session"] not in body
    assert page.evaluate("typeof window.Bokeh") == "undefined"
    # the same request outside the browser, with the cookie and a foreign Referer
    import urllib.error
    import urllib.request

    req = urllib.request.Request(
        f"{base}/app/autoload.js?bokeh-autoload-element=x",
        headers={"Cookie": "; ".join(f"{k}={v}" for k, v in cookies.items()),
                 "Referer": f"http://127.0.0.1:{evil.server_address[1]}/",
                 "Sec-Fetch-Site": "same-site"})
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(req, timeout=60)
    raw = err.value.read().decode()
    assert err.value.code == 404 and "not embeddable" in raw
    assert "token" not in raw.lower() and cookies["railval_session"] not in raw


def test_disabled_engineers_open_tab_can_do_nothing(page, app):
    db, base = app
    sign_in(page, base, "eng", "engineer password")
    page.locator(".rv-nav").get_by_role("button", name="Diagnose & model workshop",
                                        exact=True).click()
    main_area = page.locator(".rv-main")
    main_area.get_by_role("button", name="Add with these parameters & re-simulate").wait_for(
        timeout=TIMEOUT_MS)
    with db.session() as s:
        before = len(repo.list_configurations(s, repo.get_campaign(s, "demo")))
        rows_before = audit.count(s)
    assert cli(db, "user", "disable", "eng", "--reason", "left the project") == 0
    for name in ("Add with these parameters & re-simulate", "Add, calibrate & re-simulate",
                 "Run diagnosis"):
        main_area.get_by_role("button", name=name).click()
        page.locator(".rv-status", has_text="Your access has ended").wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "revocation-engineer-disabled")
    page.wait_for_timeout(1500)
    with db.session() as s:
        assert len(repo.list_configurations(s, repo.get_campaign(s, "demo"))) == before
        new = [r for r in audit.iter_rows(s) if r["seq"] > rows_before]
        assert [r["action"] for r in new] == ["user.disable"]  # the engineer did nothing more


def test_reviewer_form_after_role_removed_cannot_sign(page, app):
    db, base = app
    sign_in(page, base, "rev", "reviewer password")
    page.locator(".rv-nav").get_by_role("button", name="Sign-off", exact=True).click()
    main_area = page.locator(".rv-main")
    main_area.locator(".rv-statement textarea").wait_for(timeout=TIMEOUT_MS)
    assert cli(db, "user", "role", "rev", "assessor") == 0
    main_area.locator(".rv-statement textarea").fill("Evidence reviewed.")
    main_area.locator(".rv-sign-password input").fill("reviewer password")
    main_area.locator(".rv-sign button").click()
    # the role change ended the session on the server (docs/security.md, "Sessions")
    page.locator(".rv-status", has_text="Your access has ended").wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "revocation-reviewer-role-removed")
    with db.session() as s:
        assert db_signoff.list_signoffs(s) == []
