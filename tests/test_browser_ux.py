"""What a new user meets in the browser: results that outlive the session, tables with human
headers and a coloured verdict, toggle groups with a visible selected state, the overview's
whole channel list and bounded inputs. Playwright driving Debian's Chromium; screenshots go
to ``test-artifacts/``."""

from __future__ import annotations

import re

import pytest

from tests.browser_support import element_screenshot, nav, open_app, require_browser, screenshot, served_app

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000


@pytest.fixture(scope="module")
def app_url(tmp_path_factory):
    require_browser()
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("browser-ux"))
    with served_app(db) as url:
        yield url
    db.dispose()


def _wait_page(page, title: str) -> None:
    page.locator(".rv-main h2", has_text=title).wait_for(timeout=TIMEOUT_MS)


def _rgb(locator) -> tuple[int, ...]:
    text = locator.evaluate("el => getComputedStyle(el).backgroundColor")
    return tuple(int(x) for x in re.findall(r"\d+", text)[:3])


def test_metrics_persist_across_sessions_with_human_headers(page, app_url, context):
    open_app(page, app_url)
    nav(page, "Curve metrics")
    _wait_page(page, "Curve metrics")
    main = page.locator(".rv-main")
    # the selected toggle button is filled: its background differs clearly from the others
    active = _rgb(main.get_by_role("button", name="raw", exact=True))
    other = _rgb(main.get_by_role("button", name="synchronised", exact=True))
    assert sum(abs(a - b) for a, b in zip(active, other, strict=True)) > 200, (active, other)
    main.get_by_role("button", name="Compute metrics").click()
    main.locator(".tabulator-col-title", has_text="Sprague–Geers M").first.wait_for(timeout=TIMEOUT_MS)
    titles = main.locator(".rv-metrics .tabulator-col-title").all_inner_texts()
    assert "sg_M" not in titles and "ks_p_eff" not in titles
    assert "KS p-value (n_eff)" in titles and "area validation metric [signal unit]" in titles
    legend = main.locator(".rv-metric-legend")
    assert "phase error factor" in legend.inner_text()  # Sprague–Geers P's description
    screenshot(page, "ux-metrics-computed")

    # a second tab (a new session): the stored run is shown without computing again
    other_tab = context.new_page()
    open_app(other_tab, app_url)
    nav(other_tab, "Curve metrics")
    _wait_page(other_tab, "Curve metrics")
    main2 = other_tab.locator(".rv-main")
    main2.locator(".tabulator-col-title", has_text="Sprague–Geers M").first.wait_for(timeout=TIMEOUT_MS)
    assert main2.locator(".rv-metrics .tabulator-row").count() >= 12
    main2.get_by_text("Stored metrics runs of this configuration (1)").wait_for(timeout=TIMEOUT_MS)
    screenshot(other_tab, "ux-metrics-second-tab")
    other_tab.close()


def test_dashboard_table_headers_units_and_red_fail(page, app_url):
    open_app(page, app_url)
    nav(page, "Validation dashboard")
    _wait_page(page, "Validation dashboard")
    main = page.locator(".rv-main")
    table = main.locator(".rv-summary")
    table.locator(".tabulator-row").first.wait_for(timeout=TIMEOUT_MS)
    titles = table.locator(".tabulator-col-title").all_inner_texts()
    for header in ("what it is", "unit", "mean D_v", "std D_v (n−1)", "mean limit", "mean / limit", "verdict"):
        assert header in titles, titles
    assert not {"mean_norm", "std_norm", "pass"} & set(titles)
    table.get_by_text("quasi-static guiding force").first.wait_for(timeout=TIMEOUT_MS)
    fails = table.locator(".tabulator-cell[tabulator-field='verdict']", has_text="FAIL")
    passes = table.locator(".tabulator-cell[tabulator-field='verdict']", has_text="pass")
    assert fails.count() + passes.count() > 0
    cell = fails.first if fails.count() else None
    if cell is not None:
        colour = cell.evaluate("el => getComputedStyle(el).color")
        r, g, b = (int(x) for x in re.findall(r"\d+", colour)[:3])
        assert r > 150 and g < 80 and b < 80, colour  # red text
    # every column fits: no header is cut ("…") and the table is not wider than the page
    box = table.bounding_box()
    assert box is not None and box["width"] <= page.viewport_size["width"]
    last = table.locator(".tabulator-cell[tabulator-field='verdict']").first.bounding_box()
    assert last["x"] + last["width"] <= box["x"] + box["width"] + 1  # the verdict is in view, not scrolled off
    element_screenshot(table, "ux-dashboard-summary")
    screenshot(page, "ux-dashboard")


def test_overview_lists_every_channel_and_inputs_are_bounded(page, app_url):
    open_app(page, app_url)
    main = page.locator(".rv-main")
    heading = main.get_by_text(re.compile(r"^Channels \(\d+\)$"))
    heading.wait_for(timeout=TIMEOUT_MS)
    n = int(re.search(r"\d+", heading.inner_text()).group(0))
    rows = main.locator("table.rv-channels tbody tr")
    assert n >= 12 and rows.count() == n  # the demo campaign has 12 channels
    # nothing hidden behind an inner scroll bar: the last channel is as visible as the first
    hidden = main.locator("table.rv-channels").evaluate(
        "t => { const p = t.parentElement; return p.scrollHeight - p.clientHeight; }")
    assert hidden <= 1
    element_screenshot(main.locator("table.rv-channels"), "ux-overview-channels")

    nav(page, "Compare signals")
    _wait_page(page, "Compare signals")
    field = main.locator(".rv-psd-segment input")
    field.fill("500")
    field.press("Enter")
    page.get_by_text("PSD segment (s): 500 is outside the allowed range 1 … 60; kept 10").wait_for(
        timeout=TIMEOUT_MS)
    assert field.input_value() in ("10", "10.0")
    screenshot(page, "ux-compare-bounded-input")
