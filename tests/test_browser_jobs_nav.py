"""Nobody waits without a word, in a real browser (Playwright driving Debian's Chromium)
against the served app on loopback:

* an organiser creates a workshop from its page: the page shows "being created, n of N"
  while the plots render, can be left (the app's sidebar and the workshop list show the job)
  and found again, and becomes the workshop's page once it is stored;
* an engineer reloads the app during a diagnosis: the reloaded session lists the running job
  and, once done, links to the Diagnose page with the job's campaign and configuration;
* another user's jobs are never listed (sidebar, workshop pages, JSON);
* the navigation is one bar, the same entries in the same look on the app and on the
  workshop pages, for every role.

Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import re
import time

import pytest

from railval.db import users
from tests.browser_support import block_fonts, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 180_000
ROLES = ("admin", "organiser", "engineer", "panelist", "reviewer", "assessor")


def _pw(name: str) -> str:
    return f"{name} password 1"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    import os

    from railval.app.services import workshop_render
    from tests.browser_support import demo_database

    os.environ["RAILVAL_COOKIE_SECRET"] = "z" * 48
    db = demo_database(tmp_path_factory.mktemp("browser-jobs"), n_configs=2)
    with db.session(write=True) as s:
        for role in ROLES:
            users.create_user(s, f"u_{role}", display_name=f"User {role}", password=_pw(role),
                              roles=[role])
        users.create_user(s, "org2", display_name="Other Organiser", password=_pw("org2"),
                          roles=["organiser"])
    # the job list is this process's (the app is served in a thread of the test process):
    # jobs other test modules ran as a user of the same name (test_authz runs a diagnosis as
    # u_engineer from the overview) are not this server's users' jobs
    from railval.app.state import jobs
    with jobs._JOBS_LOCK:
        jobs._JOBS.clear()
    # one render process: the creation takes long enough to watch its progress
    old = workshop_render.RENDER_WORKERS
    workshop_render.RENDER_WORKERS = 1
    with served_app(db) as url:
        yield {"db": db, "base": url.rsplit("/app", 1)[0]}
    workshop_render.RENDER_WORKERS = old
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def sign_in(page, base: str, username: str, password: str, wait: str = ".rv-nav") -> None:
    """Sign in through the app's sign-in form (its anti-forgery token and the page's origin
    sent as the browser sends them), then open the app."""
    block_fonts(page)
    page.set_viewport_size({"width": 1280, "height": 1000})
    page.goto(f"{base}/login")
    token = page.locator("input[name=_xsrf]").first.get_attribute("value")
    resp = page.request.post(f"{base}/login", form={"_xsrf": token, "next": "/app",
                                                     "username": username,
                                                     "password": password},
                             headers={"Origin": base, "Referer": f"{base}/login"},
                             max_redirects=0)
    assert resp.status in (302, 303), resp.text()[:300]
    page.goto(f"{base}/app")
    page.locator(wait).first.wait_for(timeout=TIMEOUT_MS)


def _nav(page) -> list[dict]:
    """Every entry of the one navigation bar: text, tag, marked current, computed look."""
    return page.locator(".rv-nav .rv-nav-link").evaluate_all("""els => els.map(e => {
        const c = getComputedStyle(e);
        return {text: e.textContent.trim(), tag: e.tagName.toLowerCase(),
                current: e.classList.contains('rv-current'),
                look: [c.color, c.backgroundColor, c.fontSize, c.fontFamily, c.paddingTop,
                       c.paddingLeft, c.borderRadius, c.fontWeight].join(' | ')}; })""")


def test_workshop_created_as_a_job_left_and_found_again(page, app):
    base = app["base"]
    sign_in(page, base, "u_organiser", _pw("organiser"))
    page.goto(f"{base}/workshops/new")
    page.fill("input[name=name]", "Job workshop")
    # 3 kinds in 6 sections: 72 plots (the demo has 6 of these channels per section)
    page.locator("#kinds input[type=checkbox]").first.wait_for(timeout=TIMEOUT_MS)
    page.evaluate("""() => {
        for (const b of document.querySelectorAll('#kinds input'))
            b.checked = ['Y_time', 'ay_cb_time', 'az_cb_time'].includes(b.value);
        for (const b of document.querySelectorAll('#secs input'))
            b.checked = ['S01', 'S02', 'S03', 'S04', 'S05', 'S06'].includes(b.value); }""")
    page.click("#create")
    page.wait_for_url(f"{base}/workshops/Job%20workshop", timeout=TIMEOUT_MS)
    text = page.locator("#creation-text")
    text.filter(has_text="being created").wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "jobs-workshop-being-created-start")
    # reading the signals (a first creation also computes the EN 14363 values), then plots:
    # the page shows "being created, n of 72" while they render
    states, deadline = [], time.monotonic() + 900
    while time.monotonic() < deadline:
        job = page.request.get(f"{base}/workshops/Job%20workshop/creation").json()
        states.append((job["state"], job.get("message"), job.get("done"), job.get("total")))
        if job.get("total") or job["state"] in ("done", "failed"):
            break
        page.wait_for_timeout(250)
    assert job["state"] == "running" and job["total"] == 72, states[-5:]
    text.filter(has_text=re.compile(r"being created, \d+ of 72")).wait_for(timeout=60_000)
    screenshot(page, "jobs-workshop-being-created")
    # leave: the app's sidebar lists the job with its progress
    page.goto(f"{base}/app")
    job = page.locator(".rv-jobs .rv-job", has_text="Create workshop Job workshop")
    job.wait_for(timeout=TIMEOUT_MS)
    assert re.search(r"(\d+ of 72|queued|done)", job.inner_text())
    screenshot(page, "jobs-app-sidebar-workshop-job")
    # the workshop list shows it being created (or, if it finished meanwhile, stored)
    page.goto(f"{base}/workshops")
    row = page.locator("tr", has_text="Job workshop")
    row.wait_for(timeout=TIMEOUT_MS)
    if row.get_attribute("class") == "rv-creating":
        assert re.search(r"being created, \d+ of 72", row.inner_text())
        screenshot(page, "jobs-workshop-list-being-created")
    # found again: its page turns into the workshop's page once stored
    row.locator("a").click()
    page.locator("#wstatus").wait_for(timeout=TIMEOUT_MS * 2)
    assert "72 plots" in page.locator("main").inner_text()
    page.locator(".rv-jobs .rv-job[data-state=done]").wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "jobs-workshop-created")


def test_a_refused_choice_starts_no_job_and_says_why(page, app):
    base = app["base"]
    sign_in(page, base, "u_organiser", _pw("organiser"))
    page.goto(f"{base}/workshops/new")
    page.locator("#kinds input[type=checkbox]").first.wait_for(timeout=TIMEOUT_MS)
    page.fill("input[name=name]", "Bad repeats")
    page.fill("input[name=repeats]", "0.9")
    page.click("#create")
    page.locator("p.err", has_text="--repeats must be between 0 and 0.5").wait_for(
        timeout=TIMEOUT_MS)
    jobs = page.request.get(f"{base}/workshops/mine/jobs").json()["jobs"]
    assert not any(j["workshop"] == "Bad repeats" for j in jobs)


def test_reload_during_a_diagnosis_finds_the_job_and_its_result(page, app):
    base = app["base"]
    sign_in(page, base, "u_engineer", _pw("engineer"))
    page.locator(".rv-nav").get_by_role("button", name="Diagnose & model workshop",
                                        exact=True).click()
    conf = page.locator(".rv-main")
    conf.get_by_role("button", name="Run diagnosis").click()
    page.locator(".rv-status", has_text="diagnosis").wait_for(timeout=TIMEOUT_MS)
    page.reload()
    page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
    job = page.locator(".rv-jobs .rv-job", has_text="diagnosis of").first
    job.wait_for(timeout=TIMEOUT_MS)
    screenshot(page, "jobs-after-reload-running")
    # ended (the demo's vehicle and configuration carry the coach template's parameters, so
    # the diagnosis runs to its end): one click to its page
    ended = ".rv-jobs .rv-job[data-state=done]"
    page.locator(ended, has_text="diagnosis of").first.wait_for(timeout=TIMEOUT_MS * 3)
    screenshot(page, "jobs-after-reload-ended")
    link = page.locator(ended, has_text="diagnosis of").first.locator("a")
    href = link.get_attribute("href")
    assert href.startswith("/app?page=diagnose&campaign=demo&configuration=")
    configuration = href.rsplit("=", 1)[1]
    link.click()
    page.wait_for_url(f"{base}{href}", timeout=TIMEOUT_MS)
    current = page.locator(".rv-nav .rv-current")
    current.wait_for(timeout=TIMEOUT_MS)
    assert current.inner_text() == "Diagnose & model workshop"
    page.locator(".rv-main", has_text="diagnosis").first.wait_for(timeout=TIMEOUT_MS)
    assert page.locator("select").nth(1).input_value() == configuration
    screenshot(page, "jobs-diagnosis-result-one-click")


def test_another_users_jobs_are_not_listed(page, app):
    base = app["base"]
    sign_in(page, base, "org2", _pw("org2"))
    page.wait_for_timeout(2500)  # a refresh of the sidebar's job list has run
    assert page.locator(".rv-jobs .rv-job").count() == 0
    assert page.request.get(f"{base}/workshops/mine/jobs").json() == {"jobs": []}
    assert page.request.get(f"{base}/workshops/Job%20workshop/creation").status == 404
    page.goto(f"{base}/workshops")
    assert page.locator(".rv-job").count() == 0
    # the first organiser's list does have them (the check above is not vacuous)
    other = page.context.browser.new_context()
    p2 = other.new_page()
    sign_in(p2, base, "u_organiser", _pw("organiser"))
    p2.locator(".rv-jobs .rv-job", has_text="Create workshop Job workshop").wait_for(
        timeout=TIMEOUT_MS)
    other.close()


@pytest.mark.parametrize("role", ROLES)
def test_one_navigation_in_one_style_on_both_sides(page, app, role):
    base = app["base"]
    wait = ".rv-no-pages" if role == "panelist" else ".rv-nav"
    sign_in(page, base, f"u_{role}", _pw(role), wait=wait)
    page.goto(f"{base}/app")
    page.locator(".rv-nav").wait_for(timeout=TIMEOUT_MS)
    in_app = _nav(page)
    screenshot(page, f"nav-app-{role}")
    page.goto(f"{base}/workshops" if role != "panelist" else f"{base}/workshops/mine")
    page.locator("header .rv-nav").wait_for(timeout=TIMEOUT_MS)
    in_ws = _nav(page)
    screenshot(page, f"nav-workshops-{role}")
    assert [e["text"] for e in in_app] == [e["text"] for e in in_ws]
    assert len(in_app) >= 1
    # the same look for every entry not marked current, on both sides
    looks = {e["look"] for e in in_app + in_ws if not e["current"]}
    assert len(looks) == 1, looks
    marked_app = [e["text"] for e in in_app if e["current"]]
    marked_ws = [e["text"] for e in in_ws if e["current"]]
    if role == "panelist":
        assert marked_ws == ["My workshops"] and marked_app == []
    else:
        assert len(marked_app) == 1
        assert marked_ws == (["Workshops"] if "Workshops" in [e["text"] for e in in_ws] else [])
    current_looks = {e["look"] for e in in_app + in_ws if e["current"]}
    assert len(current_looks) <= 1
