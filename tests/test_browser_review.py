"""The independent reviewer, the panelist, the one navigation and cross-site forgery, in a
real browser (Playwright driving Debian's Chromium) against the served app on loopback.

* the reviewer's Sign-off page shows what is signed (verdict, 12 quantities, coverage,
  diagnosis, workshops, earlier sign-offs, links) before the password; a decision contrary
  to the objective verdict is refused without a justification and marked with it;
* one navigation: an organiser goes from the Panel app to the workshops and back; a
  panelist lands on "My workshops" and opens the own review from there;
* a page served from another loopback port (same *site* for the browser: the session
  cookies go along) submits every state-changing request of the app while the victims are
  signed in — each is refused (403) and nothing in the database changes.

Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import html
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from sqlalchemy import func, select

from railval.db import users
from tests.browser_support import block_fonts, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000
PW = {"org": "organiser pw", "rev": "reviewer pw", "pan": "panelist pw", "ass": "assessor pw"}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    import os

    from railval.app.services import workshops as ws
    from railval.db import workshops as wsdb
    from tests.browser_support import demo_database

    os.environ["RAILVAL_COOKIE_SECRET"] = "y" * 48
    db = demo_database(tmp_path_factory.mktemp("browser-review"), n_configs=1)
    ws.create(db, "W1", "demo", sections=["S01"], kinds=["Y_time"], repeats=0.0)
    with db.session(write=True) as s:
        users.create_user(s, "org", display_name="Olga Organiser", password=PW["org"],
                          roles=["organiser"])
        users.create_user(s, "rev", display_name="Rita Reviewer", password=PW["rev"],
                          roles=["reviewer"])
        users.create_user(s, "pan", display_name="Paul Panelist", password=PW["pan"],
                          roles=["panelist"])
        users.create_user(s, "ass", display_name="Anna Assessor", password=PW["ass"],
                          roles=["assessor"])
        token = wsdb.invite(s, wsdb.get_workshop(s, "W1"), "pan", seed=1)
        _inv, inv_token = users.create_invitation(s, role="panelist", workshop_ref="W1",
                                                  actor="org")
    with served_app(db) as url:
        yield {"db": db, "base": url.rsplit("/app", 1)[0], "token": token,
               "invitation": inv_token}
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def sign_in(page, base: str, username: str, wait: str = ".rv-nav") -> None:
    block_fonts(page)
    page.set_viewport_size({"width": 1280, "height": 1400})
    page.goto(f"{base}/login")
    page.fill("#username", username)
    page.fill("#password", PW[username])
    page.click("#signin")
    page.locator(wait).first.wait_for(timeout=TIMEOUT_MS)


def test_reviewer_sees_what_is_signed_and_a_contrary_decision_needs_a_justification(page, app):
    db, base = app["db"], app["base"]
    sign_in(page, base, "rev")
    # the reviewer reads every page of the evidence (and the workshop results)
    titles = [b.inner_text().strip() for b in page.locator(".rv-nav button").all()]
    assert titles == ["Campaign overview", "Compare signals", "Validation dashboard",
                      "Curve metrics", "Diagnose & model workshop", "Report", "Sign-off"]
    assert page.locator(".rv-areas a", has_text="Workshops").count() == 1
    page.locator(".rv-nav").get_by_role("button", name="Sign-off", exact=True).click()
    main = page.locator(".rv-main")
    summary = main.locator(".rv-summary")
    summary.wait_for(timeout=TIMEOUT_MS)
    text = summary.inner_text()
    assert "Objective verdict (DynoTRAIN, EN 14363): VALIDATED" in text
    for q in ("Y_qst", "Q_qst", "YQ_qst", "SumY_qst", "Y_max", "Q_max", "YQ_max", "SumY_max",
              "ay_rms", "az_rms", "ay_max", "az_max"):
        assert q in text, q
    assert "Coverage: complete" in text and "Newest diagnosis: never run" in text
    assert "workshop W1 (open)" in text
    hrefs = [a.get_attribute("href") for a in summary.locator("a.rv-evidence-link").all()]
    assert hrefs[0] == "/app?campaign=demo&configuration=baseline&page=dashboard"
    # the summary comes before the password field
    assert summary.bounding_box()["y"] < main.locator(".rv-sign-password").bounding_box()["y"]
    # "not validated" on a VALIDATED configuration contradicts the objective verdict
    main.get_by_role("combobox").first.select_option(label="not validated")
    warn = main.locator(".rv-contrary-warning")
    warn.wait_for(timeout=TIMEOUT_MS)
    assert "rejects the model while the objective verdict is VALIDATED" in warn.inner_text()
    main.locator(".rv-statement textarea").fill("ride comfort not credible")
    main.locator(".rv-sign-password input").fill(PW["rev"])
    main.locator(".rv-sign button").click()
    page.locator(".rv-status", has_text="needs a justification").first.wait_for(
        timeout=TIMEOUT_MS)
    with db.session() as s:
        from railval.db.models import Signoff

        assert s.scalar(select(func.count()).select_from(Signoff)) == 0
    why = "car body accelerations were measured with a loose sensor mount (report 12)"
    main.locator(".rv-justification textarea").fill(why)
    main.locator(".rv-sign-password input").fill(PW["rev"])
    main.locator(".rv-sign button").click()
    card = main.locator(".rv-signoff").first
    card.wait_for(timeout=TIMEOUT_MS)
    text = card.inner_text()
    assert "CONTRARY TO THE OBJECTIVE VERDICT" in text and why in text
    assert "Objective verdict\tVALIDATED" in text or "Objective verdict VALIDATED" in text
    page.locator(".rv-signoff-summary").scroll_into_view_if_needed()
    screenshot(page, "review-signoff-summary")
    card.scroll_into_view_if_needed()
    screenshot(page, "review-signoff-contrary")
    # the dashboard says it too
    page.locator(".rv-nav").get_by_role("button", name="Validation dashboard", exact=True).click()
    banner = page.locator(".rv-signoff-banner")
    banner.wait_for(timeout=TIMEOUT_MS)
    assert "CONTRARY TO THE OBJECTIVE VERDICT" in banner.inner_text() and why in banner.inner_text()
    # … and the report the reviewer opens (any campaign's evidence is theirs to read)
    page.locator(".rv-nav").get_by_role("button", name="Compare signals", exact=True).click()
    page.locator(".rv-main h2", has_text="Compare signals").wait_for(timeout=TIMEOUT_MS)
    page.locator(".rv-nav").get_by_role("button", name="Report", exact=True).click()
    frame = page.frame_locator("iframe[title='report preview']")
    label = frame.locator(".rv-contrary").first
    label.wait_for(timeout=TIMEOUT_MS)
    row = frame.locator("tr", has=frame.locator(".rv-contrary")).first
    assert why in row.inner_text() and "VALIDATED" in row.inner_text()
    label.scroll_into_view_if_needed()
    screenshot(page, "review-report-contrary")


def test_one_navigation_between_the_app_and_the_workshops(page, app):
    base = app["base"]
    sign_in(page, base, "org")
    areas = page.locator(".rv-areas a")
    areas.filter(has_text="Workshops").first.wait_for(timeout=TIMEOUT_MS)
    assert [a.inner_text() for a in areas.all()] == ["Workshops"]
    screenshot(page, "navigation-app")
    areas.first.click()
    page.wait_for_url(f"{base}/workshops")
    header = page.locator("header .rv-nav a")
    titles = [a.inner_text() for a in header.all()]
    assert titles == ["Campaign overview", "Compare signals", "Validation dashboard",
                      "Curve metrics", "Diagnose & model workshop", "Report", "Sign-off",
                      "Workshops"]
    assert "Olga Organiser" in page.locator("header .rv-who").inner_text()
    screenshot(page, "navigation-workshops")
    # back to the app, on the page chosen in the header
    page.locator("header .rv-nav a", has_text="Validation dashboard").click()
    page.locator(".rv-main h2", has_text="Validation dashboard").wait_for(timeout=TIMEOUT_MS)
    # sign-out from the workshop header ends the one session
    page.goto(f"{base}/workshops")
    page.locator("header a.rv-logout").click()
    page.locator("#signout").click()
    page.locator("#signin").wait_for(timeout=TIMEOUT_MS)
    page.goto(f"{base}/workshops")
    assert "/login" in page.url


def test_assessor_reaches_workshop_results_not_the_organiser_pages(page, app):
    base = app["base"]
    sign_in(page, base, "ass")
    page.locator(".rv-areas a", has_text="Workshops").click()
    page.wait_for_url(f"{base}/workshops")
    assert page.locator("a.btn", has_text="New workshop").count() == 0
    page.locator("table a", has_text="W1").click()
    page.wait_for_url(f"{base}/workshops/W1/analysis")
    assert page.request.get(f"{base}/workshops/W1").status == 403


def test_panelist_lands_on_my_workshops_and_opens_the_review(page, app):
    base = app["base"]
    sign_in(page, base, "pan", wait="#mine")
    assert page.url == f"{base}/workshops/mine"
    assert [a.inner_text() for a in page.locator("header .rv-nav a").all()] == ["My workshops"]
    assert "Paul Panelist" in page.locator("header .rv-who").inner_text()
    screenshot(page, "navigation-panelist")
    # no app page is theirs: /app shows the way to the workshops only
    page.goto(f"{base}/app")
    page.locator(".rv-no-pages .rv-areas a", has_text="My workshops").wait_for(timeout=TIMEOUT_MS)
    assert page.locator(".rv-nav button").count() == 0
    page.goto(f"{base}/workshops/mine")
    page.locator("button.rv-open-review").click()
    page.wait_for_url(f"{base}/review/**")
    page.locator("#plot").wait_for(timeout=TIMEOUT_MS)
    # the new link replaced the one sent earlier (the fixture's token is for the forgery test)
    app["token"] = page.url.rsplit("/review/", 1)[1]
    for path in ("/workshops", "/workshops/W1", "/workshops/W1/analysis"):
        assert page.request.get(f"{base}{path}").status == 403, path


# ---------------------------------------------------------------- cross-site forgery
class _Attacker(BaseHTTPRequestHandler):
    """Pages of another origin (another loopback port): each auto-submits one request."""

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


def _form(action: str, fields: dict[str, str]) -> str:
    inputs = "".join(f"<input name='{html.escape(k)}' value='{html.escape(v)}'>"
                     for k, v in fields.items())
    return (f"<form method='post' action='{html.escape(action)}'>{inputs}</form>"
            "<script>document.forms[0].submit()</script>")


def _fetch(action: str, body: dict) -> str:
    return (f"<script>fetch({json.dumps(action)}, {{method: 'POST', mode: 'no-cors', "
            f"credentials: 'include', body: JSON.stringify({json.dumps(body)})}})"
            ".finally(() => { window.__sent = 1; });</script>")


def _state(db) -> dict:
    from railval.db.models import (
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
                "participants": n(WorkshopReviewer), "answers": n(WorkshopAnswer),
                "open": sorted(s.scalars(select(Workshop.name).where(Workshop.status == "open"))),
                "invitations_used": s.scalar(select(func.count()).select_from(Invitation)
                                             .where(Invitation.used_at.is_not(None))),
                "links": sorted(s.scalars(select(WorkshopReviewer.token_sha256)))}


def test_requests_from_another_port_are_refused_and_change_nothing(browser, app):
    from railval.app.main import free_port

    db, base, token = app["db"], app["base"], app["token"]
    port = free_port()
    evil = f"http://127.0.0.1:{port}"
    forms = {
        "/close": (f"{base}/workshops/W1/status", {"status": "close"}),
        "/invite": (f"{base}/workshops/W1/invite", {"reviewer": "mallory"}),
        "/new": (f"{base}/workshops/new", {"name": "EVIL", "campaign": "demo",
                                           "configurations": "baseline", "sections": "S01",
                                           "kinds": "Y_time"}),
        "/login": (f"{base}/login", {"username": "pan", "password": PW["pan"], "next": "/app"}),
        "/logout": (f"{base}/logout", {}),
        "/redeem": (f"{base}/invite", {"token": app["invitation"], "username": "mallory",
                                       "display_name": "M", "password": "mallory pw 1",
                                       "password2": "mallory pw 1"}),
        "/open": (f"{base}/workshops/mine/W1/open", {}),
        "/answer-form": (f"{base}/review/{token}/answer", {"position": "0", "answer": "yes"}),
    }
    fetches = {
        "/answer": (f"{base}/review/{token}/answer", {"position": 0, "answer": "yes", "seconds": 1}),
        "/finish": (f"{base}/review/{token}/finish", {}),
    }
    _Attacker.pages = {p: _form(a, f) for p, (a, f) in forms.items()}
    _Attacker.pages.update({p: _fetch(a, b) for p, (a, b) in fetches.items()})
    server = ThreadingHTTPServer(("127.0.0.1", port), _Attacker)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        victims = {}
        for who in ("org", "pan"):
            ctx = browser.new_context()
            page = ctx.new_page()
            sign_in(page, base, who, wait="header, .rv-nav")
            victims[who] = (ctx, page)
        # the reviewer's own page sets its anti-forgery cookie too
        victims["pan"][1].goto(f"{base}/review/{token}")
        before = _state(db)
        assert before["open"] == ["W1"]
        statuses: dict[str, list[int]] = {}
        for path in [*forms, *fetches]:
            who = "pan" if path in ("/open", "/answer-form", "/answer", "/finish") else "org"
            page = victims[who][1]
            seen: list[int] = []

            def listen(r, seen=seen):
                if r.url.startswith(base) and r.request.method == "POST":
                    seen.append(r.status)
            page.on("response", listen)
            page.goto(f"{evil}{path}")
            if path in fetches:
                page.wait_for_function("() => window.__sent === 1", timeout=TIMEOUT_MS)
            else:
                page.wait_for_url(f"{base}/**", timeout=TIMEOUT_MS)
            page.wait_for_timeout(200)
            page.remove_listener("response", listen)
            statuses[path] = seen
        # every forged POST reached the server with the victim's cookies and was refused
        # (the no-cors fetches' responses are opaque to the page; the database shows them)
        for path in forms:
            assert statuses[path] and set(statuses[path]) == {403}, (path, statuses[path])
        after = _state(db)
        assert after == before
        # the victims are still signed in (the forged sign-out did nothing)
        assert victims["org"][1].request.get(f"{base}/workshops/W1").status == 200
        # the real pages still work: the organiser closes the workshop from its own page
        page = victims["org"][1]
        page.goto(f"{base}/workshops/W1")
        page.locator("#toggle").click()
        page.get_by_role("button", name="Reopen workshop").wait_for(timeout=TIMEOUT_MS)
        assert _state(db)["open"] == []
        page.get_by_role("button", name="Reopen workshop").click()
        page.get_by_role("button", name="Close workshop").wait_for(timeout=TIMEOUT_MS)
        for ctx, _ in victims.values():
            ctx.close()
    finally:
        server.shutdown()
