"""Cheap Panel sessions (issue 41, docs/app.md "Cheap sessions"): campaign lists and overviews
shared by the sessions of a process while the database's catalogue stamp is unchanged, static
files gzipped once per process, and no process-wide busy spinner."""

from __future__ import annotations

import gzip
import urllib.request
from pathlib import Path

import pytest

from railval.app.services import overview as overview_service
from tests.browser_support import demo_database


def test_overview_is_shared_until_the_catalogue_changes(tmp_path):
    from railval.app.state import AppState, Backend
    from railval.db import repo

    db = demo_database(tmp_path)
    a, b = AppState(Backend(db)), AppState(Backend(db))
    assert a.overview is b.overview  # one object for both sessions
    assert a.param.configuration.objects == b.param.configuration.objects == ["baseline", "variant1"]
    fresh = overview_service.overview(db, "demo")  # computed without the cache: equal
    assert [c.name for c in fresh.configurations] == [c.name for c in a.overview.configurations]
    assert [s.id for s in fresh.sections] == [s.id for s in a.overview.sections]
    with db.session(write=True) as s:
        repo.delete_configuration(s, "demo", "variant1", reason="test")
    c = AppState(Backend(db))  # a new session sees the change at once (stamp changed)
    assert c.overview is not a.overview
    assert c.param.configuration.objects == ["baseline"]
    db.dispose()


def test_stamp_changes_with_rows_added_deleted_and_replaced(tmp_path):
    from railval.db import repo

    db = demo_database(tmp_path)
    with db.session() as s:
        first = repo.catalogue_stamp(s)
        sets = repo.load_signalsets(s, "demo", "variant1")
    with db.session() as s:
        assert repo.catalogue_stamp(s) == first  # reading changes nothing
    with db.session(write=True) as s:
        # replaced in place: same configuration id, new recordings and an audit row
        repo.store_configuration(s, "demo", "variant1", parent="baseline", effects={"x": {}}, parameters={},
                                 description="", signalsets=sets, replace=True)
    with db.session() as s:
        second = repo.catalogue_stamp(s)
    assert second != first and second[8:10] == first[8:10]  # configuration count and max id kept
    db.dispose()


def test_signing_in_keeps_the_shared_overview(tmp_path):
    """A sign-in writes audit rows (``user.add``, ``login.ok``) but changes no campaign: the
    next session still shares the overview (before, the stamp took the largest audit id of any
    row, so every sign-in made the next session read and decode the campaign again)."""
    from railval.app.services import sessions
    from railval.app.state import AppState, Backend
    from railval.db import repo, users

    db = demo_database(tmp_path)
    a = AppState(Backend(db))
    with db.session() as s:
        before = repo.catalogue_stamp(s)
    with db.session(write=True) as s:
        users.create_user(s, "eng", password="engineer password", roles=["engineer"])
    signed = sessions.sign_in(db, "eng", "engineer password", max_age_s=600)
    assert signed.ok and signed.session_id
    sessions.sign_out(db, signed.session_id, "eng")
    with db.session() as s:
        assert repo.catalogue_stamp(s) == before
    assert AppState(Backend(db)).overview is a.overview
    with db.session(write=True) as s:  # a change of the catalogue still counts
        repo.delete_configuration(s, "demo", "variant1", reason="test")
    with db.session() as s:
        assert repo.catalogue_stamp(s) != before
    db.dispose()


def test_campaign_manifest_is_read_only_when_asked(tmp_path):
    """The campaign's stored manifest (large JSON) is not loaded by a lookup of the campaign
    (every session's overview and every page action look campaigns up), only when read."""
    from sqlalchemy import inspect

    from railval.db import repo

    db = demo_database(tmp_path)
    with db.session() as s:
        camp = repo.get_campaign(s, "demo")
        assert "manifest" in inspect(camp).unloaded
        assert camp.manifest["name"] == "demo"  # loaded on demand inside the unit of work
        assert [c.name for c in repo.list_campaigns(s)] == ["demo"]
    db.dispose()


def test_static_files_are_compressed_once(tmp_path):
    import bokeh

    from railval.app import static_cache
    from railval.app.main import served

    db = demo_database(tmp_path)
    static_cache.clear()
    js = Path(bokeh.__file__).parent / "server" / "static" / "js" / "bokeh.min.js"
    with served(db) as url:
        base = url.rsplit("/app", 1)[0]
        bodies = []
        for k in range(2):
            req = urllib.request.Request(f"{base}/static/js/bokeh.min.js", headers={"Accept-Encoding": "gzip"})
            with urllib.request.urlopen(req, timeout=60) as r:
                assert r.headers["Content-Encoding"] == "gzip"
                body = r.read()
                if k == 1:  # the kept bytes go out whole, with their length (the first: chunked)
                    assert int(r.headers["Content-Length"]) == len(body)
                assert r.headers["Content-Security-Policy"]  # the later transforms still apply
            bodies.append(body)
            if not static_cache.cached_size():
                pytest.fail("the first static response was not kept")
        assert bodies[0] == bodies[1]  # the second is the kept bytes
        assert gzip.decompress(bodies[1]) == js.read_bytes()
        size = static_cache.cached_size()
        # plain pages are compressed as before and not kept
        with urllib.request.urlopen(urllib.request.Request(f"{base}/health",
                                                           headers={"Accept-Encoding": "gzip"}), timeout=60) as r:
            r.read()
        assert static_cache.cached_size() == size
        # a client without gzip gets the file itself
        with urllib.request.urlopen(f"{base}/static/js/bokeh.min.js", timeout=60) as r:
            assert "Content-Encoding" not in r.headers and r.read() == js.read_bytes()
    db.dispose()


def test_template_has_no_busy_spinner_and_one_sidebar_root(tmp_path):
    from railval.app.main import build_app

    db = demo_database(tmp_path)
    t = build_app(db)
    assert t.busy_indicator is None
    assert len(t.sidebar) == 1
    db.dispose()


def test_overview_tables_are_made_once_per_shared_overview(tmp_path):
    from railval.app.main import build_app
    from railval.app.pages.overview import overview_tables

    db = demo_database(tmp_path)
    a, b = build_app(db), build_app(db)
    ov = a.railval_state.overview
    assert b.railval_state.overview is ov
    first = overview_tables(ov)
    assert overview_tables(ov) is first  # kept on the shared overview
    sections, channels, n = first
    assert n == len(ov.channels) and channels.count("<tr>") == n + 1  # header + one row per channel
    assert sections.count("<tr>") == len(ov.sections) + 1
    # rows sorted by zone, as the page always showed them
    order = [s.id for s in sorted(ov.sections, key=lambda s: (s.zone, s.id))]
    assert [sections.index(f"<td>{sid}</td>") for sid in order] == sorted(
        sections.index(f"<td>{sid}</td>") for sid in order)
    db.dispose()


def test_zone_chart_is_static_markup_made_once_per_overview(tmp_path):
    """The overview's zone chart is SVG text kept on the shared overview: the bars of the
    zones below the need red, the need dashed at its height, integer ticks, and no Bokeh
    figure in the session's page."""
    import re

    from railval.app.pages.overview import OverviewPage, zone_chart, zone_chart_svg
    from railval.app.scales import FAIL_COLOR, PASS_COLOR
    from railval.app.state import AppState, Backend

    svg = zone_chart_svg({1: 3, 2: 4, 3: 2, 4: 3}, need=3)
    fills = re.findall(r"<rect class='rv-zone-bar rv-(\w+)'[^>]* fill='([^']+)'", svg)
    assert fills == [("ok", PASS_COLOR), ("ok", PASS_COLOR), ("short", FAIL_COLOR), ("ok", PASS_COLOR)]
    heights = [float(h) for h in re.findall(r"rv-zone-bar[^>]* height='([0-9.]+)'", svg)]
    assert heights[1] / heights[2] == pytest.approx(4 / 2)  # bars in proportion to the counts
    # the dashed need line at the height of a bar of 3 sections
    need_y = float(re.search(r"y1='([0-9.]+)'[^>]*stroke-dasharray", svg).group(1))
    bar_tops = [float(y) for y in re.findall(r"rv-zone-bar[^>]* y='([0-9.]+)'", svg)]
    assert need_y == pytest.approx(bar_tops[0])
    ticks = re.findall(r"text-anchor='end'>(\d+)</text>", svg)
    assert ticks == [str(t) for t in range(6)]  # counts: integer ticks 0..max+1

    db = demo_database(tmp_path)
    a, b = AppState(Backend(db)), AppState(Backend(db))
    assert zone_chart(a.overview) is zone_chart(b.overview)  # one string for both sessions
    page = OverviewPage(a)
    page.show()
    kinds = {type(o).__name__ for o in page.body.select()}
    assert "Bokeh" not in kinds and "HTML" in kinds
    # the description, then one pane: coverage, zone chart, lineage (selection marked), tables
    _desc, rest = page.body.objects
    for part in ("Coverage holds", "rv-zone-chart", "<b class='rv-selected'>baseline</b>",
                 "table class='rv-table rv-sections'", "Channels ("):
        assert part in rest.object
    db.dispose()


def test_status_area_is_one_pane_until_a_job_runs(tmp_path):
    """The status message is escaped markup coloured by its level; the progress bar and the
    cancel button are made when the session's first job starts, then follow ``busy``."""
    import panel as pn

    from railval.app.main import STATUS_COLOURS, status_area
    from railval.app.state import AppState, Backend

    db = demo_database(tmp_path)
    app = AppState(Backend(db))
    area = status_area(app)
    assert len(area.objects) == 1 and "Ready." in area.objects[0].object
    app.set_status("cannot open <b>x</b>", "error")
    text = area.objects[0].object
    assert "cannot open &lt;b&gt;x&lt;/b&gt;" in text and STATUS_COLOURS["error"][0] in text
    app.busy, app.progress = True, 0.42
    bar, cancel = area.objects[1:]
    assert isinstance(bar, pn.indicators.Progress) and bar.visible and bar.value == 42
    assert cancel.visible
    app.busy = False
    assert not bar.visible and not cancel.visible and len(area.objects) == 3
    db.dispose()
