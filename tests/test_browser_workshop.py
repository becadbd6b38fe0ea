"""Review workshops in a real browser (Playwright driving Debian's Chromium).

``railval serve --no-demo`` runs as a separate process on a free loopback port over a
SQLite database holding the demo campaign and two workshops, so that the server can really
be stopped and started again mid-workshop. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest
from sqlalchemy import func, select

from tests.browser_support import ARTIFACTS, VIEWPORT, element_screenshot, require_browser, screenshot

pytestmark = [pytest.mark.browser]
TIMEOUT_MS = 60_000
KINDS = ["Y_time", "ay_cb_psd"]


class ServerProcess:
    """``railval serve`` in a child process (started, stopped, started again)."""

    def __init__(self, db_url: str, log_path):
        from railval.app.main import free_port

        self.db_url = db_url
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.log_path = log_path
        self.proc: subprocess.Popen | None = None

    def start(self, timeout_s: float = 180.0) -> None:
        log = open(self.log_path, "ab")  # noqa: SIM115 - closed with the process
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "railval.app", "--db", self.db_url, "serve", "--no-demo",
             "--port", str(self.port)], stdout=log, stderr=log,
            env={**os.environ, "RAILVAL_COOKIE_SECRET": "browser-test-secret-0123456789abcdef"})
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with urllib.request.urlopen(f"{self.base}/workshops/login", timeout=10) as r:
                    if r.status == 200:
                        return
            except OSError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"railval serve did not start; see {self.log_path}") from None
                time.sleep(0.3)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.proc = None


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    require_browser()
    from railval.app.services import workshop_answers as wa
    from railval.app.services import workshops as ws
    from railval.db import users
    from railval.db import workshops as wsdb

    from tests.browser_support import demo_database

    folder = tmp_path_factory.mktemp("wsbrowser")
    db = demo_database(folder, n_configs=1)
    ws.create(db, "BW", "demo", sections=["S01", "S02"], kinds=KINDS, repeats=0.25)
    ws.create(db, "BB", "demo", sections=["S01"], kinds=["Y_time"], blind=True, repeats=0.0)
    # a second reviewer group over the same plots (the cards show both shares)
    ws.create(db, "BX", "demo", sections=["S01", "S02"], kinds=KINDS, repeats=0.0)
    with db.session() as s:
        bx = [p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "BX"))]
    answers = folder / "bx.csv"
    answers.write_text("reviewer,plot,answer,seconds,comment\n"
                       + "".join(f"expert{r},{p},{'yes' if r == 0 else 'no'},3,\n" for r in range(2) for p in bx))
    wa.import_answers(db, "BX", answers)
    tokens = {}
    with db.session(write=True) as s:
        users.create_user(s, "orga", password="organiser-pass", roles=["organiser"])
        users.create_user(s, "rpw", password="reviewer-pass", roles=["panelist"])
        bw, bb = wsdb.get_workshop(s, "BW"), wsdb.get_workshop(s, "BB")
        for i, name in enumerate(("ra", "rb", "rc", "rd", "re", "rpw")):
            tokens[name] = wsdb.invite(s, bw, name, seed=100 + i)
        tokens["blind"] = wsdb.invite(s, bb, "rblind", seed=1)
    server = ServerProcess(db.url, folder / "serve.log")
    server.start()
    yield {"db": db, "server": server, "tokens": tokens}
    server.stop()
    db.dispose()


def _link(env, who: str) -> str:
    return f"{env['server'].base}/review/{env['tokens'][who]}"


def _open(browser, url: str):
    ctx = browser.new_context(viewport=VIEWPORT)
    page = ctx.new_page()
    page.goto(url)
    page.wait_for_selector("body[data-ready='1']", timeout=TIMEOUT_MS)
    return ctx, page


def _place(page) -> int:
    """1-based place shown (from "37 of 120")."""
    return int(page.locator("#progress").inner_text().split(" of ")[0])


def _total(page) -> int:
    return int(page.locator("#progress").inner_text().split(" of ")[1])


def _answer_key(page, key: str) -> None:
    before = page.locator("#answered").inner_text()
    page.keyboard.press(key)
    page.wait_for_function(f"document.getElementById('answered').textContent !== '{before}'",
                           timeout=TIMEOUT_MS)


def _answers(env, who: str) -> list[tuple[int, bool, int]]:
    from railval.db.models import AppUser, WorkshopAnswer, WorkshopReviewer

    with env["db"].session() as s:
        return [tuple(r) for r in s.execute(
            select(WorkshopAnswer.position, WorkshopAnswer.answer, WorkshopAnswer.plot_id)
            .join(WorkshopReviewer, WorkshopAnswer.reviewer_id == WorkshopReviewer.id)
            .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
            .where(AppUser.username == who).order_by(WorkshopAnswer.position))]


def _sequence(env, who: str) -> list[list]:
    from railval.db.models import AppUser, WorkshopReviewer

    with env["db"].session() as s:
        return s.scalar(select(WorkshopReviewer.sequence).join(AppUser)
                        .where(AppUser.username == who))


def test_three_reviewers_answer_the_same_workshop_at_once(browser, env):
    people = ["ra", "rb", "rc"]
    opened = {p: _open(browser, _link(env, p)) for p in people}
    total = _total(opened["ra"][1])
    assert total == len(_sequence(env, "ra")) == 8 + 2  # 8 plots + 25 % hidden repeats
    expected: dict[str, dict[int, bool]] = {p: {} for p in people}
    for i in range(total):  # interleaved: every reviewer's answer i before anyone's i+1
        for k, p in enumerate(people):
            page = opened[p][1]
            assert _place(page) == i + 1
            yes = (i + k) % 3 != 0
            _answer_key(page, "y" if yes else "n")
            expected[p][i] = yes
    for p in people:
        got = _answers(env, p)
        assert [(pos, ans) for pos, ans, _ in got] == sorted(expected[p].items())
        seq = _sequence(env, p)
        assert [pid for _, _, pid in got] == [s[0] for s in seq]
    page = opened["ra"][1]
    page.get_by_role("button", name="Finish").click()
    page.get_by_text("You have finished this review").wait_for(timeout=TIMEOUT_MS)
    for ctx, _ in opened.values():
        ctx.close()


def test_previous_answer_can_be_changed_and_comment_kept(browser, env):
    ctx, page = _open(browser, _link(env, "rd"))
    _answer_key(page, "y")
    page.locator("#comment").fill("measurement <b>noisy</b>")
    page.locator("#comment").blur()  # keys typed in the comment box are text, not answers
    _answer_key(page, "n")
    page.get_by_role("button", name="← previous").click()
    assert _place(page) == 2 and "Your answer: no" in page.locator("#prevnote").inner_text()
    assert page.locator("#comment").input_value() == "measurement <b>noisy</b>"
    page.get_by_role("button", name="Yes — validated (y)").click()
    page.wait_for_function("document.getElementById('progress').textContent.startsWith('3 of')",
                           timeout=TIMEOUT_MS)
    got = _answers(env, "rd")
    assert [(p, a) for p, a, _ in got] == [(0, True), (1, True)]
    screenshot(page, "workshop-reviewer")
    ctx.close()


def test_reviewer_closes_the_page_and_resumes_at_the_next_unanswered_plot(browser, env):
    ctx, page = _open(browser, _link(env, "rd"))
    assert _place(page) == 3  # answered 2 in the previous test
    _answer_key(page, "n")
    _answer_key(page, "y")
    ctx.close()  # browser closed midway
    ctx, page = _open(browser, _link(env, "rd"))
    assert _place(page) == 5
    assert page.locator("#answered").inner_text() == "4"
    ctx.close()
    assert len(_answers(env, "rd")) == 4


def test_server_restart_mid_workshop_loses_nothing(browser, env):
    before = {p: _answers(env, p) for p in ("ra", "rb", "rc", "rd")}
    ctx, page = _open(browser, _link(env, "re"))
    _answer_key(page, "y")
    _answer_key(page, "n")
    env["server"].stop()
    page.keyboard.press("y")  # given while the server is down: the page keeps retrying
    page.locator("#msg", has_text="retrying").wait_for(timeout=TIMEOUT_MS)
    env["server"].start()
    page.wait_for_function("document.getElementById('answered').textContent === '3'",
                           timeout=120_000)
    assert [(p, a) for p, a, _ in _answers(env, "re")] == [(0, True), (1, False), (2, True)]
    for p, rows in before.items():
        assert _answers(env, p) == rows
    ctx.close()
    ctx, page = _open(browser, _link(env, "re"))
    assert _place(page) == 4
    ctx.close()


def test_axis_ranges_of_a_kind_identical_and_images_are_the_stored_bytes(browser, env):
    from railval.db import workshops as wsdb

    with env["db"].session() as s:
        w = wsdb.get_workshop(s, "BW")
        plots = {p.id: p for p in wsdb.plots(s, w)}
        for kind in KINDS:            # zone scaling: S01 in zone 1, S02 in zone 2
            for sec, zone in (("S01", 1), ("S02", 2)):
                ranges = {json.dumps(p.render["scale"], sort_keys=True) for p in plots.values()
                          if p.kind == kind and p.section == sec}
                assert len(ranges) == 1 and json.loads(ranges.pop()) == w.scales[f"{kind} zone {zone}"]
    seq = _sequence(env, "rc")
    ctx, page = _open(browser, _link(env, "rc"))  # rc answered everything: the end screen
    page.get_by_role("button", name="← go back").click()
    for i in reversed(range(len(seq))):  # every image the page shows, hashed in the browser
        page.wait_for_function(
            f"document.getElementById('plot').dataset.position === '{i}' && "
            f"document.getElementById('plot').complete && "
            f"document.getElementById('plot').naturalWidth > 0", timeout=TIMEOUT_MS)
        digest = page.evaluate("""async () => {
            const r = await fetch(document.getElementById('plot').src);
            const b = await crypto.subtle.digest('SHA-256', await r.arrayBuffer());
            return Array.from(new Uint8Array(b)).map(x => x.toString(16).padStart(2, '0')).join('');
        }""")
        assert digest == plots[seq[i][0]].image_sha256
        # every plot the same size (10 in × 100 dpi)
        assert page.evaluate("document.getElementById('plot').naturalWidth") == 1000
        page.keyboard.press("ArrowLeft")
    ctx.close()


def test_blind_mode_shows_no_names(browser, env):
    from railval.db import repo
    from railval.db import workshops as wsdb

    with env["db"].session() as s:
        w = wsdb.get_workshop(s, "BB")
        vehicle = repo.vehicle_info(s, "demo")["name"]
        names = [vehicle, "demo", "baseline", "S01", "BB"]
        for p in wsdb.plots(s, w):
            assert not any(n in p.render["title"] for n in names), p.render["title"]
    ctx, page = _open(browser, _link(env, "blind"))
    text = page.locator("body").inner_text()
    assert not any(n in text for n in names), text
    assert json.loads(page.evaluate("fetch(location.pathname + '/state').then(r => r.text())"))[
        "workshop"] is None
    screenshot(page, "workshop-reviewer-blind")
    ctx.close()


def _status(url: str, cookie: str = "") -> int:
    req = urllib.request.Request(url, headers={"Cookie": cookie} if cookie else {})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status
    except urllib.error.HTTPError as exc:
        return exc.code


def test_reviewer_reaches_neither_other_answers_nor_the_analysis(browser, env):
    base = env["server"].base
    ctx, page = _open(browser, _link(env, "rb"))
    state = json.loads(page.evaluate("fetch(location.pathname + '/state').then(r => r.text())"))
    own = _answers(env, "rb")
    assert {int(k): v["answer"] == "yes" for k, v in state["answers"].items()} == \
        {p: a for p, a, _ in own}
    # no way from a reviewer's page to the organiser or analysis pages: sign-in asked
    page.goto(f"{base}/workshops/BW/analysis")
    assert "/login?next=" in page.url  # the app's one sign-in
    # a panelist who can sign in is refused the analysis and the organiser pages
    page.fill("input[name=username]", "rpw")
    page.fill("input[name=password]", "reviewer-pass")
    page.get_by_role("button", name="Sign in").click()
    page.get_by_text("may not open this page").wait_for(timeout=TIMEOUT_MS)
    for path in ("/workshops/BW/analysis", "/workshops/BW", "/workshops/BW/status", "/workshops"):
        resp = page.request.get(f"{base}{path}")
        assert resp.status == 403, path
    # with a valid anti-forgery token, the role check itself refuses
    xsrf = page.locator("meta[name=xsrf-token]").get_attribute("content")
    resp = page.request.post(f"{base}/workshops/BW/status", form={"status": "close", "_xsrf": xsrf})
    assert resp.status == 403 and "may not open this page" in resp.text()
    # another reviewer's link is not guessable from one's own; a wrong token is refused
    assert _status(f"{base}/review/{'x' * 43}/state") == 404
    assert _status(f"{base}/review/{env['tokens']['rb']}/image/999") == 404
    ctx.close()


def test_organiser_page_live_progress_invite_close_and_analysis(browser, env):
    base = env["server"].base
    ctx = browser.new_context(viewport=VIEWPORT)
    page = ctx.new_page()
    page.goto(f"{base}/workshops/BW")
    page.fill("input[name=username]", "orga")
    page.fill("input[name=password]", "organiser-pass")
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_selector("body[data-refreshed]", timeout=TIMEOUT_MS)
    rows = page.locator("#progress tr")
    assert rows.count() == 6
    ra_row = page.locator("#progress tr", has_text="ra").inner_text()
    assert "10 of 10" in ra_row
    # the total counts the hidden repeats: the page says so next to it (8 plots + 2 repeats)
    plots = int(page.locator("h2 + p").inner_text().split(" plots")[0].rsplit("·", 1)[1])
    assert f"({plots} plots + {10 - plots} hidden repeats)" in ra_row, ra_row
    # live: an answer given elsewhere shows up without reloading
    rctx, rpage = _open(browser, _link(env, "rpw"))
    _answer_key(rpage, "y")
    page.wait_for_function(
        "Array.from(document.querySelectorAll('#progress tr')).some("
        "tr => tr.textContent.startsWith('rpw1 of'))", timeout=TIMEOUT_MS)
    page.fill("input[name=reviewer]", "newcomer")
    page.get_by_role("button", name="Create personal link").click()
    link = page.locator("#link").inner_text()
    assert re.match(rf"{re.escape(base)}/review/[A-Za-z0-9_-]{{40,}}$", link)
    screenshot(page, "workshop-organiser")
    page.get_by_role("button", name="Close workshop").click()
    page.get_by_role("button", name="Reopen workshop").wait_for(timeout=TIMEOUT_MS)
    rpage.reload()
    rpage.get_by_text("This workshop is closed").wait_for(timeout=TIMEOUT_MS)
    xsrf = rpage.locator("meta[name=xsrf-token]").get_attribute("content")
    resp = rpage.request.post(f"{link.rsplit('/review/', 1)[0]}/review/{env['tokens']['rpw']}/answer",
                              data=json.dumps({"position": 1, "answer": "yes", "seconds": 1}),
                              headers={"Content-Type": "application/json", "X-XSRFToken": xsrf})
    assert resp.status == 409
    page.get_by_role("button", name="Reopen workshop").click()
    page.get_by_role("button", name="Close workshop").wait_for(timeout=TIMEOUT_MS)
    rctx.close()
    page.goto(f"{base}/workshops/BW/analysis")
    page.get_by_text("Table 1").wait_for(timeout=120_000)
    assert page.locator("table").first.locator("tr").count() == 1 + len(KINDS)
    assert page.get_by_text("validation limit is 1.0").is_visible()
    screenshot(page, "workshop-analysis")
    # the plot cards: one per fixed plot, the stored image, filters, a second reviewer group
    with env["db"].session() as s:
        from railval.db import workshops as wsdb

        fixed = [p for p in wsdb.plots(s, wsdb.get_workshop(s, "BW")) if p.scaling == "fixed"]
    cards = page.locator(".card")
    assert cards.count() == len(fixed)
    first = cards.first.locator("img")
    first.scroll_into_view_if_needed()
    page.wait_for_function("document.querySelector('.card img').complete && "
                           "document.querySelector('.card img').naturalWidth === 1000", timeout=TIMEOUT_MS)
    page.select_option("#cardfilter select[name=kind]", "ay_cb_psd")
    n_psd = sum(p.kind == "ay_cb_psd" for p in fixed)
    assert page.locator("#cardcount").inner_text() == str(n_psd)
    assert page.locator(".card:visible").count() == n_psd
    page.select_option("#cardfilter select[name=kind]", "")
    page.select_option("#cardfilter select[name=zone]", "2")
    assert page.locator(".card:visible").count() == sum(p.section == "S02" for p in fixed)
    page.select_option("#cardfilter select[name=zone]", "")
    page.check("#groupform input[value=BX]")
    page.get_by_role("button", name="Show their shares").click()
    page.get_by_text("Plot cards").wait_for(timeout=120_000)
    card = page.locator(".card[data-kind=Y_time]").first
    assert "BX" in card.inner_text() and "50.0 %" in card.inner_text()   # the experts: 1 of 2 Yes
    assert "Sprague–Geers: M" in card.inner_text() and "Y_qst" in card.inner_text()
    card.scroll_into_view_if_needed()
    element_screenshot(page.locator(".card").nth(0), "workshop-card")
    screenshot(page, "workshop-analysis-cards")
    page.goto(f"{base}/workshops/new")
    page.wait_for_function("/^\\d+ plots/.test(document.getElementById('count').textContent)",
                           timeout=TIMEOUT_MS)
    from railval.app.services import workshops as ws

    with env["db"].session() as s:
        n_all = len(ws.plan(s, "demo"))
    assert page.locator("#count").inner_text().startswith(f"{n_all} plots")
    screenshot(page, "workshop-new")
    # the scaling preview: ranges per kind and zone, the share of flat plots, both scalings
    for box in page.locator("#secs input").all()[4:]:
        box.uncheck()
    page.get_by_role("button", name="Preview ranges").click()
    page.wait_for_selector("table.preview[data-scaling=workshop]", timeout=120_000)
    assert page.locator("table.preview[data-scaling=zone] tr").count() > \
        page.locator("table.preview[data-scaling=workshop] tr").count()
    assert "Share of flat plots per kind" in page.locator("#preview").inner_text()
    assert page.locator("select[name=scaling]").input_value() == "zone"
    screenshot(page, "workshop-new-preview")
    ctx.close()
    assert (ARTIFACTS / "workshop-analysis.png").exists()
    with env["db"].session() as s:
        from railval.db.models import AuditEvent

        actions = set(s.scalars(select(AuditEvent.action)))
        assert {"workshop.create", "workshop.invite", "workshop.close", "workshop.reopen"} <= actions
        assert s.scalar(select(func.count()).select_from(AuditEvent)) > 0


def test_validation_report_shows_the_chosen_cards(browser, env, tmp_path):
    """Two cards chosen into the report of the configuration: shown in Chromium with their
    embedded images (the reviewed bytes) beside the EN values and both groups' shares."""
    from railval.app.report import build_report
    from railval.app.services.workshop_cards import report_cards
    from railval.app.state.backend import Backend
    from railval.db import workshops as wsdb

    with env["db"].session() as s:
        ids = [p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "BW")) if p.scaling == "fixed"][:2]
    cards = report_cards(env["db"], "BW", "baseline", ids, groups=["BX"])
    path = build_report(Backend(env["db"]), "demo", "baseline", worst_cases=0, cards=cards).write(
        tmp_path / "report.html")
    ctx = browser.new_context(viewport=VIEWPORT)
    page = ctx.new_page()
    page.goto(path.as_uri())
    cards_el = page.locator(".card")
    assert cards_el.count() == 2
    page.wait_for_function("Array.from(document.querySelectorAll('.card img')).every("
                           "i => i.complete && i.naturalWidth === 1000)", timeout=TIMEOUT_MS)
    assert "BX" in cards_el.first.inner_text()
    page.get_by_text("Expert review: plot cards").scroll_into_view_if_needed()
    element_screenshot(page.locator(".card").first, "report-card")
    ctx.close()
