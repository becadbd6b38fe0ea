"""The flags railval's browsers start with (``railval.app.pdf.CHROMIUM_ARGS``: the PDF printer,
the benchmarks and these tests), read off the running browser:

* Chromium reads only the last ``--disable-features`` switch and Playwright puts its own list
  before the caller's: railval's switch must repeat every feature Playwright turns off, or a
  Playwright upgrade's new entry would silently come back on in the tests and benchmarks;
* the omnibox popup's WebUI (two hidden ``chrome://omnibox-popup.top-chrome`` pages per new
  window, 1.0–1.8 s of a renderer's tasks each time, docs/app.md "The browser's own address bar") is not built; a
  browser started with Playwright's flags alone builds it.
"""

from __future__ import annotations

import pytest

from railval.app import pdf
from tests.browser_support import CHROMIUM

pytestmark = pytest.mark.browser


def _switches(browser) -> list[str]:
    """The browser's command line as ``chrome://version`` shows it."""
    page = browser.new_page()
    try:
        page.goto("chrome://version")
        return page.locator("#command_line").inner_text().split()
    finally:
        page.close()


def _disabled(switches: list[str]) -> list[set[str]]:
    """Each ``--disable-features`` switch's features, in command-line order."""
    return [set(s.split("=", 1)[1].split(",")) for s in switches if s.startswith("--disable-features=")]


def _browser_ui_targets(browser) -> list[str]:
    """The browser's own WebUI pages (``browser_ui`` targets) after one page is opened in a new
    context, as the benchmarks and tests open every session."""
    context = browser.new_context()
    try:
        context.new_page().goto("about:blank")
        infos = browser.new_browser_cdp_session().send("Target.getTargets")["targetInfos"]
        return [t["url"] for t in infos if t["type"] == "browser_ui"]
    finally:
        context.close()


def test_railvals_switch_is_the_last_and_keeps_every_feature_playwright_turns_off(browser):
    lists = _disabled(_switches(browser))
    assert len(lists) >= 2, f"expected Playwright's switch and railval's, got {lists}"
    playwright_off, effective = lists[0], lists[-1]
    assert playwright_off <= effective, (
        f"Playwright turns off {sorted(playwright_off - effective)} too: add them to "
        "railval.app.pdf.PLAYWRIGHT_OFF_FEATURES (Chromium reads only the last switch)")
    assert set(pdf.OMNIBOX_WEBUI_FEATURES) <= effective


def test_no_omnibox_webui_is_built_for_a_new_context(browser, playwright):
    assert _browser_ui_targets(browser) == []
    plain = playwright.chromium.launch(executable_path=CHROMIUM)  # Playwright's flags alone
    try:
        built = _browser_ui_targets(plain)
    finally:
        plain.close()
    assert any(url.startswith("chrome://omnibox-popup") for url in built), (
        f"with Playwright's flags alone this Chromium builds {built}, no omnibox WebUI: "
        "railval.app.pdf.OMNIBOX_WEBUI_FEATURES may be dropped")
