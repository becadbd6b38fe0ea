"""Cookie tossing from another loopback port, in Chromium (docs/security.md, threat model:
"same-site page with cookie tossing"), and the review page's sign-out and changed answers.

Browsers do not separate cookies by port: a page served from ``127.0.0.1:<other port>`` may
set cookies that the app on ``127.0.0.1:<app port>`` receives. The attacker's page sets
``_xsrf`` (defeats Tornado's double-submit token) and ``railval_presession`` (the
attacker's own signed pre-session cookie, fetched from the server) and auto-submits, with the
matching token, a request to **every** ``POST`` endpoint of the served app — enumerated from
the handlers of ``app/auth.py``, ``app/main.py`` and ``app/workshop_web`` — against victims
signed in (organiser, panelist), a visitor who opened a review link without signing in, and
a browser that never visited the app (the sign-in and invitation forgeries: signing the
victim in as the attacker). Each is refused (403) and the database — users, sessions,
workshops, links, answers, invitations and the audit trail — is unchanged.

Also: the review page's sign-out ends the session on the server (a copy of the cookie is
refused afterwards); two tabs of one panelist on the same plot — the second tab's answer
says which answer it replaced and when. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import html
import json
import os
import threading
import urllib.parse
import urllib.request
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from sqlalchemy import func, select

from railval.db import users
from tests.browser_support import block_fonts, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000
PW = {"org": "organiser pw", "pan": "panelist pw", "pan2": "panelist2 pw",
      "mallory": "mallory pw 1"}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    from railval.app.services import workshops as ws
    from railval.db import workshops as wsdb
    from tests.browser_support import demo_database

    os.environ["RAILVAL_COOKIE_SECRET"] = "k" * 48
    db = demo_database(tmp_path_factory.mktemp("browser-tossing"), n_configs=1)
    ws.create(db, "W1", "demo", sections=["S01"], kinds=["Y_time"], repeats=0.0)
    with db.session(write=True) as s:
        users.create_user(s, "org", display_name="Olga Organiser", password=PW["org"],
                          roles=["organiser"])
        for name in ("pan", "pan2"):
            users.create_user(s, name, display_name=f"Paul {name}", password=PW[name],
                              roles=["panelist"])
        users.create_user(s, "mallory", password=PW["mallory"], roles=["panelist"])
        w = wsdb.get_workshop(s, "W1")
        token = wsdb.invite(s, w, "pan", seed=1)
        token2 = wsdb.invite(s, w, "pan2", seed=2)
        _inv, inv_token = users.create_invitation(s, role="panelist", workshop_ref="W1",
                                                  actor="org")
    with served_app(db) as url:
        yield {"db": db, "base": url.rsplit("/app", 1)[0], "token": token, "token2": token2,
               "invitation": inv_token}
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def sign_in(page, base: str, username: str) -> None:
    block_fonts(page)
    page.set_viewport_size({"width": 1280, "height": 1000})
    page.goto(f"{base}/login")
    page.fill("#username", username)
    page.fill("#password", PW[username])
    page.click("#signin")
    page.wait_for_url(lambda url: "/login" not in url, timeout=TIMEOUT_MS)
    page.wait_for_load_state("load", timeout=TIMEOUT_MS)


def post_endpoints(db) -> set[str]:
    """Every URL pattern of the served app whose handler takes a ``POST``: the sign-in's
    (app/auth.py: login, logout, invitation), the workshop pages' (app/workshop_web) and
    whatever app/main.py adds; Bokeh's and Panel's own handlers take none."""
    from tornado.web import RequestHandler

    from railval.app.auth import LOGIN_URL, LOGOUT_URL, RailvalAuth
    from railval.app.workshop_web import routes

    from railval.app.health import HealthHandler

    auth = RailvalAuth(db, "k" * 48)
    patterns = [(LOGIN_URL, auth.login_handler), (LOGOUT_URL, auth.logout_handler),
                (r"/health", HealthHandler),
                *[(p, h) for p, h, *_ in auth.extra_patterns()],
                *[(p, h) for p, h, *_ in routes(db, auth)]]
    return {p for p, h in patterns if getattr(h, "post", None) is not RequestHandler.post}


def _snapshot(db) -> dict:
    from railval.db.models import (
        AppSession,
        AppUser,
        AuditEvent,
        Invitation,
        Workshop,
        WorkshopAnswer,
        WorkshopReviewer,
    )

    with db.session() as s:
        def n(model):
            return s.scalar(select(func.count()).select_from(model))
        return {"audit": n(AuditEvent), "users": n(AppUser), "workshops": n(Workshop),
                "sessions": sorted(s.execute(select(AppSession.id, AppSession.ended_at)).all()),
                "answers": n(WorkshopAnswer),
                "open": sorted(s.scalars(select(Workshop.name).where(Workshop.status == "open"))),
                "invitations_used": s.scalar(select(func.count()).select_from(Invitation)
                                             .where(Invitation.used_at.is_not(None))),
                "links": sorted(map(str, s.scalars(select(WorkshopReviewer.token_sha256)))),
                "disabled": sorted(s.scalars(select(AppUser.username).where(AppUser.disabled)))}


class _Attacker(BaseHTTPRequestHandler):
    pages: dict[str, str] = {}

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        body = self.pages.get(self.path, "<p>nothing</p>").encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args) -> None:
        pass


def _toss(cookies: dict[str, str]) -> str:
    """Script lines setting cookies for the host 127.0.0.1 (every port of it)."""
    return "".join(f"document.cookie = {json.dumps(f'{k}={v}; path=/')};" for k, v in cookies.items())


def _form_page(action: str, fields: dict[str, str], cookies: dict[str, str]) -> str:
    inputs = "".join(f"<input name='{html.escape(k)}' value='{html.escape(v)}'>"
                     for k, v in fields.items())
    return (f"<form method='post' action='{html.escape(action)}'>{inputs}</form>"
            f"<script>{_toss(cookies)} document.forms[0].submit();</script>")


def _fetch_page(action: str, body: dict, cookies: dict[str, str]) -> str:
    return (f"<script>{_toss(cookies)} fetch({json.dumps(action)}, {{method: 'POST', "
            f"mode: 'no-cors', credentials: 'include', body: JSON.stringify({json.dumps(body)})}})"
            ".finally(() => { window.__sent = 1; });</script>")


def _attacker_presession(base: str) -> tuple[str | None, str]:
    """What the attacker fetches from the server for themselves: a signed pre-session cookie
    (None from a server that hands out none) and its anti-forgery token (the sign-in
    form's)."""
    import re

    with urllib.request.urlopen(f"{base}/login", timeout=60) as r:
        cookie = re.search(r"railval_presession=([^;]+)", r.headers.get("Set-Cookie", ""))
        token = re.search(r'name="_xsrf" value="([^"]+)"', r.read().decode())
    assert token
    return (cookie.group(1).strip('"') if cookie else None), token.group(1)


def test_cookie_tossing_from_another_port_changes_nothing_on_every_post_endpoint(browser, app):
    from railval.app.main import free_port

    db, base, token = app["db"], app["base"], app["token"]
    pre_cookie, pre_token = _attacker_presession(base)
    # _xsrf = the attacker's token: Tornado's double-submit and the pre-session both match
    tossed = {"_xsrf": pre_token, **({"railval_presession": pre_cookie} if pre_cookie else {})}
    q = urllib.parse.quote(pre_token)
    attacks = {  # endpoint pattern → (victim, attack path, form or JSON body)
        "/login": ("fresh", "/login", {"username": "mallory", "password": PW["mallory"],
                                       "next": "/app"}),
        "/logout": ("org", "/logout", {}),
        "/invite": ("fresh", "/invite", {"token": app["invitation"], "username": "mallory2",
                                        "display_name": "M", "password": "mallory pw 2",
                                        "password2": "mallory pw 2"}),
        "/workshops/new": ("org", "/new", {"name": "EVIL", "campaign": "demo",
                                           "configurations": "baseline", "sections": "S01",
                                           "kinds": "Y_time"}),
        "/workshops/([^/]+)/status": ("org", "/close", {"status": "close"}),
        "/workshops/([^/]+)/invite": ("org", "/invite-w", {"reviewer": "mallory"}),
        "/workshops/([^/]+)": ("org", "/workshop", {"status": "close"}),
        "/workshops/mine/([^/]+)/open": ("pan", "/open", {}),
        "/workshops/mine": ("pan", "/mine", {}),
        r"/review/([A-Za-z0-9_\-]{20,100})/answer": ("pan", "/answer", None),
        r"/review/([A-Za-z0-9_\-]{20,100})/finish": ("pan", "/finish", None),
    }
    endpoints = post_endpoints(db)
    assert endpoints == set(attacks), f"POST endpoints without an attack: {endpoints ^ set(attacks)}"
    targets = {"/login": "/login", "/logout": "/logout", "/invite": "/invite",
               "/new": "/workshops/new", "/close": "/workshops/W1/status",
               "/invite-w": "/workshops/W1/invite", "/workshop": "/workshops/W1",
               "/open": "/workshops/mine/W1/open", "/mine": "/workshops/mine"}
    pages = {}
    for _pattern, (_who, path, fields) in attacks.items():
        if fields is not None:
            pages[path] = _form_page(base + targets[path], {"_xsrf": pre_token, **fields}, tossed)
    # the review link's JSON endpoints: no-cors fetches (token in the query), and the answer
    # also as a plain form, and both against the link opened without a session ("anon")
    pages["/answer"] = _fetch_page(f"{base}/review/{token}/answer?_xsrf={q}",
                                   {"position": 0, "answer": "yes", "seconds": 1}, tossed)
    pages["/finish"] = _fetch_page(f"{base}/review/{token}/finish?_xsrf={q}", {}, tossed)
    pages["/answer-form"] = _form_page(f"{base}/review/{token}/answer",
                                       {"_xsrf": pre_token, "position": "0", "answer": "yes"},
                                       tossed)
    port = free_port()
    evil = f"http://127.0.0.1:{port}"
    _Attacker.pages = pages
    server = ThreadingHTTPServer(("127.0.0.1", port), _Attacker)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        victims = {}
        for who in ("org", "pan", "link", "fresh"):
            ctx = browser.new_context()
            page = ctx.new_page()
            block_fonts(page)
            if who == "link":  # not signed in: the review link opened by itself
                page.goto(f"{base}/review/{token}")
            elif who != "fresh":  # "fresh": has never visited the app (no cookie at all)
                sign_in(page, base, who)
            victims[who] = (ctx, page)
        victims["pan"][1].goto(f"{base}/review/{token}")  # the panelist's own review page
        before = _snapshot(db)
        assert before["open"] == ["W1"]
        runs = [(who, path) for who, path, _ in attacks.values()]
        runs += [("link", "/answer"), ("link", "/finish"), ("pan", "/answer-form"),
                 ("link", "/answer-form")]
        statuses: dict[tuple[str, str], list[int]] = {}
        for who, path in runs:
            page = victims[who][1]
            seen: list[int] = []

            def listen(r, seen=seen):
                if r.url.startswith(base) and r.request.method == "POST":
                    seen.append(r.status)
            page.on("response", listen)
            page.goto(f"{evil}{path}")
            if path in ("/answer", "/finish"):
                page.wait_for_function("() => window.__sent === 1", timeout=TIMEOUT_MS)
            else:
                page.wait_for_url(f"{base}/**", timeout=TIMEOUT_MS)
            page.wait_for_timeout(200)
            page.remove_listener("response", listen)
            statuses[(who, path)] = seen
            # the tossed cookies reach the app (same site, any port); a script cannot replace
            # an HttpOnly cookie the app set, so the pre-session is the attacker's only for
            # a browser that had none (the sign-in forgery's victim)
            if who == "fresh":
                jar = {c["name"]: c["value"].strip('"') for c in page.context.cookies(base)}
                assert jar.get("_xsrf") == pre_token and jar.get("railval_presession") == pre_cookie
        # a no-cors fetch's response is opaque: the database shows what it did
        through = {(who, path): seen for (who, path), seen in statuses.items()
                   if path not in ("/answer", "/finish") and (not seen or set(seen) != {403})}
        after = _snapshot(db)
        changed = {k: (before[k], after[k]) for k in before if before[k] != after[k]}
        assert not through and not changed, (through, changed)
        screenshot(victims["org"][1], "cookie-tossing-refused")
        # the victims are still signed in, the visitors are not signed in as mallory
        assert victims["org"][1].request.get(f"{base}/workshops/W1").status == 200
        for who in ("link", "fresh"):
            assert "railval_session" not in {c["name"] for c in victims[who][0].cookies(base)}
        for ctx, _ in victims.values():
            ctx.close()
    finally:
        server.shutdown()


def test_review_page_sign_out_ends_the_session_on_the_server(page, app):
    db, base = app["db"], app["base"]
    sign_in(page, base, "pan2")
    page.goto(f"{base}/workshops/mine")
    page.locator("button.rv-open-review").click()
    page.wait_for_url(f"{base}/review/**")
    page.locator("body[data-ready='1']").wait_for(timeout=TIMEOUT_MS)
    app["token2"] = page.url.rsplit("/review/", 1)[1]
    copied = next(c["value"] for c in page.context.cookies(base) if c["name"] == "railval_session")
    signout = page.locator("#review-signout")
    assert signout.is_visible()
    screenshot(page, "review-page-sign-out")
    signout.click()
    page.wait_for_url(f"{base}/login?out=1", timeout=TIMEOUT_MS)
    assert page.locator(".ok", has_text="You are signed out.").is_visible()
    # a copy of the cookie taken before is refused: the session ended on the server
    req = urllib.request.Request(f"{base}/workshops/mine",
                                 headers={"Cookie": f"railval_session={copied}"})
    with urllib.request.urlopen(req, timeout=60) as r:
        assert "/login?next=" in r.geturl()
    from railval.db.models import AppSession, AppUser

    with db.session() as s:
        reasons = s.scalars(select(AppSession.end_reason).join(AppUser, AppUser.id == AppSession.user_id)
                            .where(AppUser.username == "pan2")).all()
        assert reasons and set(reasons) == {"logout"}


def test_two_tabs_on_one_plot_show_the_answer_they_replaced(browser, app):
    from railval.db.models import WorkshopAnswer, WorkshopReviewer

    db, base, token = app["db"], app["base"], app["token2"]
    ctx = browser.new_context(viewport={"width": 1280, "height": 1000})
    tab_a, tab_b = ctx.new_page(), ctx.new_page()
    for tab in (tab_a, tab_b):
        block_fonts(tab)
        tab.goto(f"{base}/review/{token}")
        tab.locator("body[data-ready='1']").wait_for(timeout=TIMEOUT_MS)
    plot = tab_a.locator("#progress").inner_text()
    assert tab_b.locator("#progress").inner_text() == plot
    tab_a.locator("#yes").click()
    tab_a.locator("#progress").filter(has_not_text=plot).wait_for(timeout=TIMEOUT_MS)
    tab_b.locator("#no").click()  # tab B still shows the plot unanswered
    note = tab_b.locator("#changed")
    note.filter(has_text="you changed your answer from Yes to No at").wait_for(timeout=TIMEOUT_MS)
    import re

    assert re.search(r"Plot 1: you changed your answer from Yes to No at \d\d:\d\d \(the answer "
                     r"Yes was stored at \d\d:\d\d\)\.", note.inner_text()), note.inner_text()
    screenshot(tab_b, "review-two-tabs-changed-answer")
    from railval.db.models import AppUser

    with db.session() as s:
        row = s.scalar(select(WorkshopAnswer)
                       .join(WorkshopReviewer, WorkshopReviewer.id == WorkshopAnswer.reviewer_id)
                       .join(AppUser, AppUser.id == WorkshopReviewer.user_id)
                       .where(AppUser.username == "pan2", WorkshopAnswer.position == 0))
        assert row.answer is False and row.changes == 1  # one row: the change, not a loss
    # back in tab A (brought to the front): the stored answer and that it was changed
    tab_a.bring_to_front()
    tab_a.evaluate("document.dispatchEvent(new Event('visibilitychange'))")
    tab_a.locator("#backbtn").click()
    tab_a.locator("#prevnote", has_text="Your answer: no (changed, last at").wait_for(
        timeout=TIMEOUT_MS)
    ctx.close()
