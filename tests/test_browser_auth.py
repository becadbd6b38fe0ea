"""Sign-in, roles and user text in the real served app, in a browser (Playwright + Chromium).

* every role signs in through the login form and sees exactly its pages in the navigation;
  a page it may not open shows the refusal, not a traceback;
* a reviewer signs a configuration off on the Sign-off page (password asked again);
* HTML/JS payloads in user names, statements, restrictions and audit reasons are shown as
  text: no script runs, no element or ``javascript:`` link is created from them.
Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import pytest

from railval.core.roles import ROLES
from railval.db import users
from tests.browser_support import block_fonts, require_browser, screenshot, served_app, sign_in

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000
PAYLOADS = {
    "name": '<img src=x onerror="window.__xss=1">[Eve](javascript:window.__xss=5)',
    "statement": "<script>window.__xss=2</script>Looks right",
    "restrictions": '<a href="javascript:window.__xss=3">only zone 1</a>',
    "reason": "<b onmouseover=window.__xss=4>onboarding</b>",
}
NAV = {
    "overview": "Campaign overview", "compare": "Compare signals",
    "dashboard": "Validation dashboard", "metrics": "Curve metrics",
    "diagnose": "Diagnose & model workshop", "report": "Report", "signoff": "Sign-off",
    "audit": "Audit trail", "import": "Import",
}
READ = ["overview", "compare", "dashboard", "metrics", "diagnose", "report", "signoff"]
EXPECTED_PAGES = {"admin": READ + ["audit"], "organiser": READ, "engineer": READ + ["import"],
                  "panelist": [], "reviewer": READ, "assessor": READ + ["audit"]}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    import os

    from tests.browser_support import demo_database

    os.environ["RAILVAL_COOKIE_SECRET"] = "x" * 48
    db = demo_database(tmp_path_factory.mktemp("browser-auth"))
    with db.session(write=True) as s:
        for role in ROLES:
            users.create_user(s, f"u_{role}", display_name=f"User {role}",
                              password=f"{role} password", roles=[role])
        users.create_user(s, "eve", display_name=PAYLOADS["name"], password="eve password",
                          roles=["reviewer", "assessor"], reason=PAYLOADS["reason"])
    with served_app(db) as url:
        yield db, url.rsplit("/app", 1)[0]
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def nav_titles(page) -> list[str]:
    return [b.inner_text().strip() for b in page.locator(".rv-nav button").all()]


@pytest.mark.parametrize("role", list(ROLES))
def test_each_role_sees_exactly_its_pages(page, app, role):
    db, base = app
    sign_in(page, base, f"u_{role}", f"{role} password")
    if role == "panelist":  # no app page: lands on "My workshops" (workshop header)
        assert page.url.endswith("/workshops/mine") and nav_titles(page) == []
        user = page.locator("header .rv-who")
    else:
        assert nav_titles(page) == [NAV[p] for p in EXPECTED_PAGES[role]]
        user = page.locator(".rv-user")
    assert f"User {role}" in user.inner_text() and "Sign out" in user.inner_text()
    screenshot(page, f"auth-{role}")
    page.click("a.rv-logout")
    page.click("#signout")  # the sign-out link asks to confirm (a POST with its token)
    page.locator("#signin").wait_for(timeout=TIMEOUT_MS)
    assert "You are signed out." in page.content()


def test_wrong_password_in_the_browser(page, app):
    db, base = app
    block_fonts(page)
    page.goto(f"{base}/login")
    page.fill("#username", "u_engineer")
    page.fill("#password", "not it")
    page.click("#signin")
    assert page.locator(".msg").inner_text() == "Wrong user name or password."
    screenshot(page, "auth-wrong-password")


def test_reviewer_signs_off_and_payloads_stay_text(page, app):
    db, base = app
    sign_in(page, base, "eve", "eve password")
    page.locator(".rv-nav").get_by_role("button", name="Sign-off", exact=True).click()
    page.locator(".rv-main h2", has_text="Sign-off").wait_for(timeout=TIMEOUT_MS)
    main = page.locator(".rv-main")
    main.get_by_role("combobox").first.select_option(label="validated with restrictions")
    main.locator(".rv-restrictions textarea").fill(PAYLOADS["restrictions"])
    main.locator(".rv-statement textarea").fill(PAYLOADS["statement"])
    main.locator(".rv-sign-password input").fill("eve password")
    main.locator(".rv-sign button").click()
    card = main.locator(".rv-signoff").first
    card.wait_for(timeout=TIMEOUT_MS)
    text = card.inner_text()
    assert PAYLOADS["statement"] in text and PAYLOADS["restrictions"] in text
    assert PAYLOADS["name"] in text  # the printed name, as typed
    assert "VALID" in text and "Meaning of the signature" in text and "(UTC)" in text
    screenshot(page, "auth-signoff")
    page.locator(".rv-nav").get_by_role("button", name="Audit trail", exact=True).click()
    table = main.locator("table.rv-audit-table")
    table.wait_for(timeout=TIMEOUT_MS)
    assert PAYLOADS["reason"] in table.inner_text()
    main.get_by_text("Hash chain intact", exact=False).first.wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "auth-audit")
    assert PAYLOADS["name"] in page.locator(".rv-user").inner_text()
    # nothing ran, nothing was created from the payloads
    assert page.evaluate("() => window.__xss === undefined")
    assert page.locator(".rv-main img[src='x'], .rv-user img[src='x']").count() == 0
    assert page.locator("a[href^='javascript:']").count() == 0
    assert page.locator(".rv-main script").count() == 0
    table.get_by_text(PAYLOADS["reason"]).first.hover()
    assert page.evaluate("() => window.__xss === undefined")
