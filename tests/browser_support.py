"""Helpers of the browser tests and the app benchmark: serve the app in a thread on a free
loopback port, drive Debian's Chromium with Playwright.

Browser tests skip with a visible reason when ``/usr/bin/chromium`` is missing, unless
``RAILVAL_REQUIRE_BROWSER=1`` (CI), which turns the skip into a failure.
"""

from __future__ import annotations

import os
from pathlib import Path

from railval.app import report as _report

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = list(_report.CHROMIUM_ARGS)
ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"
VIEWPORT = {"width": 1280, "height": 1200}


def browser_missing_reason() -> str | None:
    """``None`` when Chromium and Playwright are usable, else why not."""
    if not os.path.exists(CHROMIUM):
        return f"no Chromium at {CHROMIUM} (apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError as exc:
        return f"playwright not installed: {exc}"
    return None


def require_browser() -> None:
    """Skip (or fail under ``RAILVAL_REQUIRE_BROWSER=1``) when no browser is usable."""
    import pytest

    reason = browser_missing_reason()
    if reason is None:
        return
    if os.environ.get("RAILVAL_REQUIRE_BROWSER") == "1":
        pytest.fail(f"RAILVAL_REQUIRE_BROWSER=1 but {reason}")
    pytest.skip(reason)


def served_app(database):
    """Serve the railval app on ``database`` in a thread; yields its URL (app.main.served)."""
    from railval.app.main import served

    return served(database)


def block_fonts(page) -> None:
    """FastListTemplate asks Google Fonts for a font: answer nothing, at once."""
    page.route("**/fonts.googleapis.com/**", lambda route: route.abort())
    page.route("**/fonts.gstatic.com/**", lambda route: route.abort())


def open_app(page, url: str, timeout_ms: float = 60_000) -> None:
    page.set_viewport_size(VIEWPORT)
    block_fonts(page)
    page.goto(url)
    # the first chart: a canvas, or the overview's zone chart (static SVG)
    page.locator("canvas, .rv-zone-chart").first.wait_for(state="attached", timeout=timeout_ms)


def nav(page, title: str) -> None:
    """Click a page in the sidebar navigation."""
    page.locator(".rv-nav").get_by_role("button", name=title, exact=True).click()


def screenshot(page, name: str) -> Path:
    """The page (the template's main area scrolls: what the viewport shows) as an artifact."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


def element_screenshot(locator, name: str) -> Path:
    """One element, scrolled into view, as an artifact (for content below the fold)."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    locator.screenshot(path=str(path))
    return path


def demo_database(folder: Path, name: str = "demo", n_configs: int = 2):
    """A fresh SQLite database in ``folder`` holding the ``tests/factories`` demo campaign
    (12 sections in 4 zones, ``n_configs`` configurations)."""
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(folder / name, n_sections=12, n_configs=n_configs, name=name)
    db = connect(f"sqlite:///{folder / 'app.db'}")
    db.init()
    import_campaign(db, manifest.parent)
    return db


_SOURCES_JS = """() => {
  const doc = Bokeh.documents[0];
  const models = doc.all_models ? Array.from(doc.all_models) : Array.from(doc._all_models.values());
  return models.filter(m => m.data && m.data.x && m.data.y && m.data.x.length > 0)
    .map(m => { const x = Array.from(m.data.x);
                return {id: m.id, n: x.length, x0: Math.min(...x), x1: Math.max(...x)}; });
}"""


def bokeh_sources(page) -> dict[str, dict]:
    """The non-empty x/y data sources the browser holds: id → {n, x0, x1}."""
    return {d["id"]: d for d in page.evaluate(_SOURCES_JS)}


def box_zoom(page, canvas, fx: tuple[float, float], fy: tuple[float, float] = (0.3, 0.7)) -> None:
    """Drag a box over ``canvas`` between fractions ``fx`` of its width and ``fy`` of its height
    (the Compare figures' active drag tool is box zoom)."""
    box = canvas.bounding_box()
    x0, x1 = (box["x"] + f * box["width"] for f in fx)
    y0, y1 = (box["y"] + f * box["height"] for f in fy)
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, (y0 + y1) / 2, steps=5)
    page.mouse.move(x1, y1, steps=5)
    page.mouse.up()


_FRAME_JS = """(title) => {
  const out = [], seen = new Set();
  const visit = (v) => {
    if (!v || seen.has(v)) return;
    seen.add(v);
    if (v.frame && v.model && v.model.title && v.model.title.text === title) {
      const r = v.canvas_view.el.getBoundingClientRect(), b = v.frame.bbox;
      out.push({left: r.left + b.x0, right: r.left + b.x1, top: r.top + b.y0, bottom: r.top + b.y1,
                factors: Array.from(v.model.x_range.factors || [])});
    }
    const kids = v.child_views || [];
    for (const c of (kids.values ? Array.from(kids.values()) : kids)) visit(c);
  };
  const roots = Bokeh.index instanceof Map ? Array.from(Bokeh.index.values()) : Object.values(Bokeh.index);
  for (const r of roots) visit(r);
  return out;
}"""


def plot_frame(page, title: str) -> dict:
    """Page coordinates of the data frame of the Bokeh plot titled ``title`` (from BokehJS's
    views: left, right, top, bottom) and its categorical x factors."""
    frames = page.evaluate(_FRAME_JS, title)
    assert len(frames) == 1, f"{len(frames)} plots titled {title!r}"
    return frames[0]


def click_bar(page, title: str, factor: str, above_base_px: float = 4.0) -> None:
    """Click the bar of ``factor`` in the bar chart ``title``, just above its base (the bars
    of a chart whose y axis starts at 0)."""
    fr = plot_frame(page, title)
    i = fr["factors"].index(factor)
    x = fr["left"] + (i + 0.5) / len(fr["factors"]) * (fr["right"] - fr["left"])
    page.mouse.click(x, fr["bottom"] - above_base_px)


def sign_in(page, base: str, username: str, password: str, *, timeout_ms: int = 120_000) -> None:
    """Sign in on the app's own sign-in page (fonts blocked, a 1280 × 1100 viewport) and wait
    for the page navigation of the signed-in app."""
    block_fonts(page)
    page.set_viewport_size({"width": 1280, "height": 1100})
    page.goto(f"{base}/app")
    page.fill("#username", username)
    page.fill("#password", password)
    page.click("#signin")
    page.locator(".rv-nav").wait_for(timeout=timeout_ms)
