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
