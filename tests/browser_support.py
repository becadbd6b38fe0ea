"""Helpers of the browser tests and the app benchmark: serve the app in a thread on a free
loopback port, drive Debian's Chromium with Playwright (NOTES-stack.md).

Browser tests skip with a visible reason when ``/usr/bin/chromium`` is missing, unless
``RAILVAL_REQUIRE_BROWSER=1`` (CI), which turns the skip into a failure.
"""

from __future__ import annotations

import os
import socket
import time
import urllib.request
from contextlib import contextmanager
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def served_app(database, timeout_s: float = 30.0):
    """Serve the railval app on ``database`` in a background thread; yields the base URL
    of the app (``http://127.0.0.1:PORT/app``)."""
    from app.main import serve

    port = free_port()
    server = serve(database, port=port, address="127.0.0.1", threaded=True)
    url = f"http://127.0.0.1:{port}/app"
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(url, timeout=5) as resp:
                if resp.status == 200:
                    break
        except OSError:
            if time.monotonic() > deadline:
                server.stop()
                raise
            time.sleep(0.1)
    try:
        yield url
    finally:
        server.stop()
        server.join(10)


def block_fonts(page) -> None:
    """FastListTemplate asks Google Fonts for a font: answer nothing, at once."""
    page.route("**/fonts.googleapis.com/**", lambda route: route.abort())
    page.route("**/fonts.gstatic.com/**", lambda route: route.abort())


def open_app(page, url: str, timeout_ms: float = 60_000) -> None:
    page.set_viewport_size(VIEWPORT)
    block_fonts(page)
    page.goto(url)
    page.locator("canvas").first.wait_for(state="attached", timeout=timeout_ms)


def nav(page, title: str) -> None:
    """Click a page in the sidebar navigation."""
    page.locator(".rv-nav").get_by_role("button", name=title, exact=True).click()


def screenshot(page, name: str) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


def demo_database(folder: Path, name: str = "demo", n_configs: int = 2):
    """A fresh SQLite database in ``folder`` holding the ``tests/factories`` demo campaign
    (12 sections in 4 zones, ``n_configs`` configurations)."""
    from db.engine import connect
    from db.importer import import_campaign
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(folder / name, n_sections=12, n_configs=n_configs, name=name)
    db = connect(f"sqlite:///{folder / 'app.db'}")
    db.init()
    import_campaign(db, manifest.parent)
    return db
