"""The Import page shows its outcome in one place, under the upload box: a refused zip (the
precise message naming file and field, and that nothing was stored) exactly where a
successful import is reported. Real served app, real Chromium, SQLite.

Screenshots: ``test-artifacts/import-refused.png``, ``test-artifacts/import-ok.png``.
"""

from __future__ import annotations

import io
import json
import zipfile

import pytest

from railval.db import repo, users
from tests.browser_support import (
    block_fonts,
    element_screenshot,
    require_browser,
    screenshot,
    served_app,
    sign_in,
)
from tests.factories import write_demo_campaign

pytestmark = [pytest.mark.browser,
              pytest.mark.filterwarnings("ignore:reference already known:UserWarning")]
TIMEOUT_MS = 120_000


def _zip(folder) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                zf.write(p, f"{folder.name}/{p.relative_to(folder).as_posix()}")
    return buf.getvalue()


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    require_browser()
    import os

    from railval.db.engine import connect

    root = tmp_path_factory.mktemp("browser-import")
    good = root / "track-2026"
    write_demo_campaign(good, n_sections=1, fs=50.0, name="track-2026")
    bad = root / "digits"
    write_demo_campaign(bad, n_sections=1, fs=50.0, name="digits")
    manifest = json.loads((bad / "campaign.json").read_text())
    manifest["name"] = "1"
    (bad / "campaign.json").write_text(json.dumps(manifest))
    (root / "digits.zip").write_bytes(_zip(bad))
    (root / "track-2026.zip").write_bytes(_zip(good))
    os.environ["RAILVAL_COOKIE_SECRET"] = "i" * 48
    db = connect(f"sqlite:///{root / 'app.db'}")
    db.init()
    with db.session(write=True) as s:
        users.create_user(s, "eng", display_name="Erik Engineer", password="engineer password",
                          roles=["engineer"])
    with served_app(db) as url:
        yield db, url.rsplit("/app", 1)[0], root
    db.dispose()
    os.environ.pop("RAILVAL_COOKIE_SECRET", None)


def _upload(page, path) -> None:
    page.locator(".rv-import-file input[type=file]").set_input_files(str(path))
    page.wait_for_timeout(500)  # the file reaches the server over the websocket
    page.locator(".rv-import-go button").click()


def test_refusal_and_success_appear_under_the_upload_box(page, app):
    db, base, root = app
    block_fonts(page)
    sign_in(page, base, "eng", "engineer password")
    page.locator(".rv-nav").get_by_role("button", name="Import", exact=True).click()
    page.get_by_text("Largest upload: 100 MB").wait_for(timeout=TIMEOUT_MS)

    _upload(page, root / "digits.zip")
    error = page.locator(".rv-import-result .rv-import-error")
    error.wait_for(timeout=TIMEOUT_MS)
    text = error.inner_text()
    assert "Not imported: file campaign.json, field name: campaign name '1' is digits only" in text
    assert "Nothing of digits.zip was stored." in text
    box = page.locator(".rv-import-file").bounding_box()
    shown = error.bounding_box()
    assert 0 <= shown["y"] - (box["y"] + box["height"]) < 80, (box, shown)  # right under it
    assert abs(shown["x"] - box["x"]) < 40
    screenshot(page, "import-refused")
    element_screenshot(page.locator(".rv-import-result"), "import-refused-message")
    with db.session() as s:
        assert repo.list_campaigns(s) == []

    _upload(page, root / "track-2026.zip")
    ok = page.locator(".rv-import-result .rv-import-ok")
    ok.wait_for(timeout=TIMEOUT_MS)
    assert ok.inner_text().strip() == "Imported campaign track-2026 from track-2026.zip."
    assert page.locator(".rv-import-result .rv-import-error").count() == 0
    shown_ok = ok.bounding_box()
    assert abs(shown_ok["y"] - shown["y"]) < 2 and abs(shown_ok["x"] - shown["x"]) < 2
    screenshot(page, "import-ok")
    with db.session() as s:
        assert [c.name for c in repo.list_campaigns(s)] == ["track-2026"]
