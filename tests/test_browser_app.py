"""The web app in a real browser (Playwright driving Debian's Chromium).

The app is served with ``pn.serve(..., threaded=True)`` on a free loopback port over the
``tests/factories`` demo campaign. Screenshots go to ``test-artifacts/``. Skipped with the
reason when ``/usr/bin/chromium`` is missing, unless ``RAILVAL_REQUIRE_BROWSER=1``.
"""

from __future__ import annotations

import re

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from tests.browser_support import (
    bokeh_sources,
    box_zoom,
    click_bar,
    element_screenshot,
    nav,
    open_app,
    require_browser,
    screenshot,
    served_app,
)

# Bokeh warns (benignly) when a button-click event refers to a model the server knows;
# pytest turns warnings into errors process-wide, which would break the server thread
pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
PAGE_TIMEOUT_MS = 120_000


@pytest.fixture(scope="module")
def app_url(tmp_path_factory):
    require_browser()
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("browser"))
    from railval.app.services import workshops as ws

    # a small review workshop: its plot cards can be chosen into the report
    ws.create(db, "RW", "demo", configurations=["baseline"], sections=["S01"], kinds=["Y_time"],
              repeats=0.0)
    with served_app(db) as url:
        yield url
    db.dispose()


def _wait_page(page, title: str) -> None:
    page.locator(".rv-main h2", has_text=title).wait_for(timeout=PAGE_TIMEOUT_MS)


def test_overview_and_compare_pages(page, app_url):
    open_app(page, app_url)
    _wait_page(page, "Campaign overview")
    main = page.locator(".rv-main")
    assert main.get_by_text("Coverage holds").is_visible()
    sections = main.locator("table.rv-sections tbody tr")
    assert sections.count() == 12
    assert sections.first.locator("td").first.inner_text() == "S01"  # zone 1 first
    assert main.locator("table.rv-channels tbody tr").count() >= 8
    assert main.get_by_text("baseline", exact=True).first.is_visible()  # lineage tree
    screenshot(page, "overview")

    nav(page, "Compare signals")
    _wait_page(page, "Compare signals")
    main.get_by_text("Measurement in black beneath").wait_for(timeout=PAGE_TIMEOUT_MS)
    # two series (EN-filtered, raw) and the PSD: three Bokeh canvases in the page
    main.locator("canvas").nth(2).wait_for(state="attached", timeout=PAGE_TIMEOUT_MS)
    screenshot(page, "compare")

    # zoom: the visible window is re-sampled on the server from the full 200 Hz arrays
    before = bokeh_sources(page)
    series = {k: v for k, v in before.items() if v["n"] == 2000}  # 2 traces × 2 series figures
    assert len(series) == 4, before
    full = max(v["x1"] - v["x0"] for v in series.values())
    assert all(v["n"] / (v["x1"] - v["x0"]) < 100 for v in series.values())  # thinned: < 100 points/s
    box_zoom(page, main.locator("canvas").first, (0.45, 0.55))

    def refined() -> dict:
        now = bokeh_sources(page)
        return {k: now[k] for k in series if now[k]["x1"] - now[k]["x0"] < 0.3 * full}

    for _ in range(100):
        if len(refined()) == 4:  # both figures follow (linked x range)
            break
        page.wait_for_timeout(100)
    zoomed = refined()
    assert len(zoomed) == 4, bokeh_sources(page)
    for v in zoomed.values():  # every sample of the window: the recording's 200 Hz
        assert v["n"] / (v["x1"] - v["x0"]) == pytest.approx(200, rel=0.02)
    screenshot(page, "compare-zoomed")


def test_dashboard_drilldown_row_opens_compare(page, app_url):
    open_app(page, app_url)
    nav(page, "Validation dashboard")
    _wait_page(page, "Validation dashboard")
    main = page.locator(".rv-main")
    main.get_by_text(re.compile(r"baseline: (NOT )?VALIDATED")).wait_for(timeout=PAGE_TIMEOUT_MS)
    assert main.get_by_text("std is the sample standard deviation (n − 1)", exact=False).is_visible()
    rows = main.locator(".rv-drilldown .tabulator-row")
    rows.first.wait_for(timeout=PAGE_TIMEOUT_MS)
    section = rows.first.locator(".tabulator-cell[tabulator-field='section']").inner_text().strip()
    screenshot(page, "dashboard")
    where = main.locator(".rv-where")
    where.locator("canvas").first.wait_for(state="attached", timeout=PAGE_TIMEOUT_MS)
    element_screenshot(main.locator(".rv-where-box"), "dashboard-where")
    # the row's click opens Compare; on a loaded machine a click that lands before the
    # table's handlers are bound is lost (seen once in CI), so it is given again while the
    # dashboard is still there — what is asserted stays the same: Compare opens on that row
    cell = rows.first.locator(".tabulator-cell[tabulator-field='position']")
    compare = page.locator(".rv-main h2", has_text="Compare signals")
    for _attempt in range(3):
        cell.click()
        try:
            compare.wait_for(timeout=20_000)
            break
        except PlaywrightTimeout:
            if not cell.is_visible():
                break
    _wait_page(page, "Compare signals")
    shown = main.locator("select").first.evaluate("s => s.options[s.selectedIndex].text")
    assert shown == section
    main.locator("canvas").nth(2).wait_for(state="attached", timeout=PAGE_TIMEOUT_MS)
    screenshot(page, "drilldown-compare")

    # back on the dashboard, a click on a bar of the std chart drills to that quantity
    nav(page, "Validation dashboard")
    _wait_page(page, "Validation dashboard")
    drill_select = main.locator("select").first
    shown_q = drill_select.evaluate("s => s.value")
    other = "az_max" if shown_q != "az_max" else "ay_max"
    click_bar(page, "Normalised std (std / limit, n − 1)", other)
    page.wait_for_function("([el, q]) => el.value === q", arg=[drill_select.element_handle(), other],
                           timeout=PAGE_TIMEOUT_MS)


def test_metrics_report_and_workshop_pages(page, app_url):
    open_app(page, app_url)
    nav(page, "Curve metrics")
    _wait_page(page, "Curve metrics")
    main = page.locator(".rv-main")
    main.get_by_role("button", name="Compute metrics").click()
    main.locator(".tabulator-col-title", has_text="Sprague–Geers M").first.wait_for(timeout=PAGE_TIMEOUT_MS)
    assert main.locator(".tabulator-row").count() >= 12  # one section × its channels
    screenshot(page, "metrics")

    nav(page, "Report")
    _wait_page(page, "Report")
    frame = page.frame_locator("iframe[title='report preview']")
    frame.locator("h1", has_text="Validation report: baseline").wait_for(timeout=PAGE_TIMEOUT_MS)
    assert main.get_by_role("button", name="Download PDF").is_visible()
    screenshot(page, "report")
    # a workshop plot card chosen into the report
    main.locator(".choices").first.click()
    page.locator(".choices__item--choice", has_text="RW · plot").first.click()
    frame.locator("h2", has_text="Expert review: plot cards").wait_for(timeout=PAGE_TIMEOUT_MS)
    assert frame.locator(".card").count() == 1
    frame.locator(".card").scroll_into_view_if_needed()
    screenshot(page, "report-with-card")

    nav(page, "Diagnose & model workshop")
    _wait_page(page, "Diagnose & model workshop")
    assert main.get_by_role("button", name="Run diagnosis").is_visible()
    main.get_by_text("Add an effect").wait_for(timeout=PAGE_TIMEOUT_MS)
    main.locator("canvas").first.wait_for(state="attached", timeout=PAGE_TIMEOUT_MS)  # lineage chart
    # the settings cards open and announce the cost in campaign simulations
    main.get_by_text("Diagnosis settings").click()
    main.get_by_text(re.compile(r"Run diagnosis simulates the campaign \d+ times")).wait_for(
        timeout=PAGE_TIMEOUT_MS)
    main.get_by_text("Calibration settings").click()
    cost = main.get_by_text(re.compile(r"Calibrate simulates the campaign at most \d+ times"))
    cost.wait_for(timeout=PAGE_TIMEOUT_MS)
    before = int(re.search(r"at most (\d+)", cost.inner_text()).group(1))
    # the page calibrates with the local fit: its estimate (the CLI's), 1–3 parameters
    from railval.app.services.calibration_plan import calibration_simulations

    assert before in {calibration_simulations(n) for n in (1, 2, 3)}, before
    # population, generations, polish and seed belong to the global search: not editable
    # with the local fit, editable once "Global search" is ticked, and then they set the cost
    generations = main.locator(".rv-cal-settings .bk-input:not([type=checkbox])").nth(2)
    assert generations.is_disabled()
    main.locator(".rv-cal-settings input[type=checkbox]").first.check()
    page.wait_for_function("el => !el.disabled", arg=generations.element_handle(),
                           timeout=PAGE_TIMEOUT_MS)
    generations.fill("10")
    generations.press("Enter")
    main.get_by_text(re.compile(r"population × generations of differential evolution")).wait_for(
        timeout=PAGE_TIMEOUT_MS)
    page.wait_for_timeout(1500)
    assert int(re.search(r"at most (\d+)", cost.inner_text()).group(1)) > before
    screenshot(page, "workshop")
