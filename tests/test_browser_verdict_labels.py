"""Verdicts that say when they are in-sample, a sign-off form without a default decision,
labels that cannot be misread, a readable signature chart and the whole quantity table — in a
real browser (Playwright driving Debian's Chromium) against the served app on loopback.

* Diagnose page: "Add with these parameters & re-simulate" with the values the diagnosis
  fitted on every section gives a configuration whose verdict is labelled in-sample, with the
  note that no held-out check is possible and how to get one (here and on the dashboard);
* the signature chart is a grouped bar chart: one before/after pair per quantity, labels in
  their own rows, the axis saying it is normalised and dimensionless, the same height at two
  window widths;
* Sign-off form: no decision is chosen until the reviewer chooses; a missing decision and a
  contrary decision without justification are refused next to the form in the page's words;
  the status reads "SIGNATURE VALID"; the audit row of the sign-off carries the contrary mark;
* dashboard: all 12 quantity rows in view without scrolling inside the table, numbers as
  people write them; the workshop form explains "hidden repeats" and the automatic-scaling
  share.

A 12-section synthetic coach campaign (the demo's hidden effect: the baseline is NOT
VALIDATED) diagnosed on one candidate beforehand. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import os
import re

import pytest
from sqlalchemy import func, select

from tests.browser_support import block_fonts, element_screenshot, nav, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000
JOB_MS = 600_000
EFFECT = "parasitic_yaw_stiffness"
PW = {"eng": "engineer pw 39", "rev": "reviewer pw 39", "ass": "assessor pw 39", "org": "organiser pw 39"}
ROLES = {"eng": "engineer", "rev": "reviewer", "ass": "assessor", "org": "organiser"}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    from railval.app.services.diagnosis import diagnose
    from railval.app.services.synth import DEMO_HIDDEN, synth
    from railval.db import users
    from railval.db.engine import connect

    os.environ["RAILVAL_COOKIE_SECRET"] = "v" * 48
    db = connect(f"sqlite:///{tmp_path_factory.mktemp('browser-39') / 'app.db'}")
    db.init()
    synth(db, name="ins", hidden=DEMO_HIDDEN, seed=2026, n_sections=12)
    diagnose(db, "ins", "baseline", effects=[EFFECT], values_per_parameter=2, workers=1)
    with db.session(write=True) as s:
        for name, role in ROLES.items():
            users.create_user(s, name, display_name=f"{role.title()} Thirty-Nine", password=PW[name],
                              roles=[role])
    with served_app(db) as url:
        yield {"db": db, "base": url.rsplit("/app", 1)[0]}
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def sign_in(page, base: str, username: str, password: str) -> None:
    """Sign in on the app's sign-in page (fonts blocked, 1280 × 1100) and wait for the app."""
    block_fonts(page)
    page.set_viewport_size({"width": 1280, "height": 1100})
    page.goto(f"{base}/login")
    page.fill("#username", username)
    page.fill("#password", password)
    page.click("#signin")
    page.locator(".rv-nav, .rv-areas").first.wait_for(timeout=TIMEOUT_MS)


def _open(page, app, user: str, title: str):
    sign_in(page, app["base"], user, PW[user])
    nav(page, title)
    page.locator(".rv-main h2", has_text=title).wait_for(timeout=TIMEOUT_MS)
    return page.locator(".rv-main")


_SIGNATURE_JS = """(svg) => {
  const box = (t) => { const r = t.getBoundingClientRect();
                       return {x0: r.left, x1: r.right, y0: r.top, y1: r.bottom}; };
  const labels = Array.from(svg.querySelectorAll('text.label'));
  return {height: svg.getBoundingClientRect().height, width: svg.getBoundingClientRect().width,
          labels: labels.map(t => ({text: t.textContent, font: parseFloat(getComputedStyle(t).fontSize),
                                    ...box(t)})),
          bars: Array.from(svg.querySelectorAll('rect > title')).map(t => t.textContent),
          axis: (svg.querySelector('text.axis-label') || {}).textContent || ''};
}"""


def _text(locator) -> str:
    """The text of a pane, its shadow root included (Panel renders panes in shadow roots)."""
    return locator.evaluate("el => (el.shadowRoot ? el.shadowRoot.textContent : '') + el.textContent")


def _overlap(a: dict, b: dict) -> bool:
    return a["x0"] < b["x1"] and b["x0"] < a["x1"] and a["y0"] < b["y1"] and b["y0"] < a["y1"]


def _check_signature(main, width: int) -> dict:
    chart = main.locator(".rv-signature svg")  # Playwright's locators pierce the panes' shadow roots
    chart.wait_for(timeout=TIMEOUT_MS)
    info = chart.evaluate(_SIGNATURE_JS)
    labels = info["labels"]
    assert len(labels) >= 12 and len(info["bars"]) == 2 * len(labels), info["bars"]
    # one before/after pair per quantity
    for lab in labels:
        assert sum(t.startswith(f"{lab['text']} before:") for t in info["bars"]) == 1, lab
        assert sum(t.startswith(f"{lab['text']} after (fitted):") for t in info["bars"]) == 1, lab
    assert all(lab["font"] >= 11 for lab in labels)  # legible
    assert not any(_overlap(a, b) for i, a in enumerate(labels) for b in labels[i + 1:]), f"labels overlap at {width}"
    assert "dimensionless" in info["axis"] and "std limit" in info["axis"]
    assert info["height"] >= 30 * len(labels)  # never a thin line
    element_screenshot(chart, f"issue39-signature-{width}")
    return info


def test_diagnosis_fitted_values_give_an_in_sample_verdict_and_a_readable_signature(page, app):
    main = _open(page, app, "eng", "Diagnose & model workshop")
    main.locator(".rv-candidates .tabulator-row").first.wait_for(timeout=TIMEOUT_MS)
    assert main.locator(".rv-effect select").evaluate("s => s.options[s.selectedIndex].text") == EFFECT
    # the signature chart at two window widths: same height, labels apart
    wide = _check_signature(main, 1280)
    page.set_viewport_size({"width": 1000, "height": 1100})
    narrow = _check_signature(main, 1000)
    assert abs(wide["height"] - narrow["height"]) < 1
    page.set_viewport_size({"width": 1280, "height": 1100})
    main.get_by_role("button", name="Add with these parameters & re-simulate").click()
    page.locator(".rv-status", has_text="re-simulation: done").wait_for(timeout=JOB_MS)
    child = f"baseline+{EFFECT}"
    main.get_by_text(f"Parent baseline beside {child}").wait_for(timeout=TIMEOUT_MS)
    box = main.locator(".rv-verdict", has_text=f"{child}:").first
    text = _text(box)
    assert f"(in-sample: {child}'s parameters were fitted by a diagnosis on 12 of these sections)" in text, text
    assert "No held-out check is possible for this configuration" in text and "--split" in text
    # the job's summary line says it too
    main.get_by_text(re.compile(r"Its verdict is in-sample: .* no held-out check is possible")).first.wait_for(
        timeout=TIMEOUT_MS)
    box.scroll_into_view_if_needed()
    screenshot(page, "issue39-diagnose-in-sample")
    nav(page, "Validation dashboard")
    page.locator(".rv-main h2", has_text="Validation dashboard").wait_for(timeout=TIMEOUT_MS)
    verdict = main.locator(".rv-verdict").first
    verdict.wait_for(timeout=TIMEOUT_MS)
    assert "in-sample" in _text(verdict) and "No held-out check" in _text(verdict)
    element_screenshot(verdict, "issue39-dashboard-in-sample")


def test_signoff_form_has_no_default_decision_and_refuses_in_the_page_words(page, app, browser):
    from railval.db.models import Signoff

    db = app["db"]
    main = _open(page, app, "rev", "Sign-off")
    summary = main.locator(".rv-summary")
    summary.wait_for(timeout=TIMEOUT_MS)
    assert "Objective verdict (DynoTRAIN, EN 14363): NOT VALIDATED" in summary.inner_text()
    decision = main.locator(".rv-decision select")
    assert decision.evaluate("s => s.options[s.selectedIndex].text") == "— choose a decision —"
    # submitting without a decision is refused next to the form
    main.locator(".rv-sign-password input").fill(PW["rev"])
    main.locator(".rv-sign button").click()
    refusal = main.locator(".rv-signoff-refusal")
    refusal.get_by_text("Choose a decision").wait_for(timeout=TIMEOUT_MS)
    form_y = main.locator(".rv-sign").bounding_box()["y"]
    assert 0 < refusal.bounding_box()["y"] - form_y < 200  # next to the Sign button
    # "validated" on a NOT VALIDATED configuration without a justification: refused, in words
    decision.select_option(label="validated")
    main.locator(".rv-contrary-warning").wait_for(timeout=TIMEOUT_MS)
    main.locator(".rv-sign-password input").fill(PW["rev"])
    main.locator(".rv-sign button").click()
    refusal.get_by_text("A decision contrary to the objective verdict needs a justification").wait_for(
        timeout=TIMEOUT_MS)
    assert "--" not in refusal.inner_text()
    element_screenshot(main.locator(".rv-signoff-refusal"), "issue39-signoff-refusal")
    screenshot(page, "issue39-signoff-form")
    with db.session() as s:
        assert s.scalar(select(func.count()).select_from(Signoff)) == 0
    main.locator(".rv-justification textarea").fill("guiding forces judged against a second campaign (report 7)")
    main.locator(".rv-sign-password input").fill(PW["rev"])
    main.locator(".rv-sign button").click()
    card = main.locator(".rv-signoff").first
    card.wait_for(timeout=TIMEOUT_MS)
    status = card.locator(".rv-signoff-status").inner_text().strip()
    assert status == "SIGNATURE VALID", status  # not a bare "VALID" beside "CONTRARY …"
    assert "CONTRARY TO THE OBJECTIVE VERDICT" in card.inner_text()
    assert refusal.inner_text().strip() == ""
    # the next sign-off starts without a decision too
    assert decision.evaluate("s => s.options[s.selectedIndex].text") == "— choose a decision —"
    card.scroll_into_view_if_needed()
    element_screenshot(card, "issue39-signoff-card")
    # the audit trail's row of the sign-off carries the contrary mark
    other = browser.new_page()
    try:
        main2 = _open(other, app, "ass", "Audit trail")
        row = main2.locator("table.rv-audit-table tr", has_text="signoff.create").first
        row.wait_for(timeout=TIMEOUT_MS)
        assert "CONTRARY TO THE OBJECTIVE VERDICT" in row.inner_text()
        element_screenshot(row, "issue39-audit-row")
    finally:
        other.close()


_ROWS_JS = """(holder) => {
  const hb = holder.getBoundingClientRect();
  const rows = Array.from(holder.querySelectorAll('.tabulator-row'));
  return {scroll: holder.scrollHeight, client: holder.clientHeight,
          rows: rows.map(r => { const b = r.getBoundingClientRect();
                                return {top: b.top, bottom: b.bottom}; }),
          top: hb.top, bottom: hb.bottom};
}"""


def test_dashboard_shows_all_12_rows_with_readable_numbers_and_workshop_form_explains(page, app):
    main = _open(page, app, "eng", "Validation dashboard")
    table = main.locator(".rv-summary")
    table.locator(".tabulator-row").first.wait_for(timeout=TIMEOUT_MS)
    info = table.locator(".tabulator-tableholder").evaluate(_ROWS_JS)
    assert len(info["rows"]) == 12
    assert info["scroll"] <= info["client"] + 1, info  # nothing hidden inside the table
    assert all(r["bottom"] <= info["bottom"] + 1 for r in info["rows"]), info
    assert table.locator(".tabulator-cell[tabulator-field='quantity']", has_text="az_max").is_visible()
    for field in ("mean D_v", "std D_v (n−1)", "mean limit", "std limit", "mean / limit", "std / limit"):
        cells = table.locator(f".tabulator-cell[tabulator-field='{field}']").all_inner_texts()
        assert len(cells) == 12
        for c in cells:
            assert re.fullmatch(r"-?\d+(\.\d{1,4})?", c.strip()), (field, c)
    element_screenshot(table, "issue39-dashboard-table")
    # the workshop form explains its two shares
    page.goto(f"{app['base']}/workshops/new")
    page.context.clear_cookies()
    sign_in(page, app["base"], "org", PW["org"])
    page.goto(f"{app['base']}/workshops/new")
    rep = page.locator("#repeats-help")
    rep.wait_for(timeout=TIMEOUT_MS)
    assert "shown a second time" in rep.inner_text() and "same answer twice" in rep.inner_text()
    auto = page.locator("#auto-help")
    assert "own y range" in auto.inner_text() and "0 = every plot" in auto.inner_text()
    assert page.locator("input[name='repeats']").get_attribute("aria-describedby") == "repeats-help"
    assert page.locator("input[name='auto_share']").get_attribute("aria-describedby") == "auto-help"
    screenshot(page, "issue39-workshop-form")
