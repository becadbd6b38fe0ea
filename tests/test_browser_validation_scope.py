"""The dashboard in a real browser shows definition-sensitive verdicts and the supplementary
block (Playwright driving Debian's Chromium; screenshots in ``test-artifacts/``)."""

from __future__ import annotations

import re

import pytest

from tests.browser_support import element_screenshot, nav, open_app, require_browser, served_app
from tests.test_definitions import store_definition_sensitive_configuration

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
PAGE_TIMEOUT_MS = 120_000


@pytest.fixture(scope="module")
def app_url(tmp_path_factory):
    require_browser()
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("browser-scope"), n_configs=1)
    store_definition_sensitive_configuration(db)
    with served_app(db) as url:
        yield url
    db.dispose()


def test_dashboard_shows_definition_sensitivity_and_supplementary_results(page, app_url):
    open_app(page, app_url)
    config = page.locator("select", has=page.locator("option", has_text="scaled")).first
    config.select_option("scaled")
    nav(page, "Validation dashboard")
    main = page.locator(".rv-main")
    main.get_by_text(re.compile(r"scaled: (NOT )?VALIDATED")).wait_for(timeout=PAGE_TIMEOUT_MS)
    # the verdict names the definition-sensitive quantity
    assert main.get_by_text(re.compile(r"definition-sensitive: .*SumY_max")).first.is_visible()
    defs = main.locator(".rv-definitions")
    defs.wait_for(timeout=PAGE_TIMEOUT_MS)
    row = defs.locator(".tabulator-row", has_text="SumY_max")
    row.wait_for(timeout=PAGE_TIMEOUT_MS)
    cell = row.locator(".tabulator-cell[tabulator-field='definition-sensitive']")
    assert cell.inner_text().strip() == "yes"
    assert "with" in row.locator(".tabulator-cell[tabulator-field='flipped by']").inner_text()
    # rms quantities depend on no open choice: not listed
    assert defs.locator(".tabulator-row", has_text="ay_rms").count() == 0
    element_screenshot(defs, "dashboard-definition-sensitivity")

    supp = main.locator(".rv-supplementary")
    supp.scroll_into_view_if_needed()
    assert supp.get_by_text("do not change the verdict", exact=False).first.is_visible()
    supp.locator(".tabulator-row", has_text="psd_ay_cb_0.4-1Hz").wait_for(timeout=PAGE_TIMEOUT_MS)
    assert supp.locator(".tabulator-row").count() >= 8  # car body PSD bands at b1/b2
    element_screenshot(supp, "dashboard-supplementary")
