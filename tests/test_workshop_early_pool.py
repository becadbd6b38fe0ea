"""Render workers started before the signals are read (workshop_render.early_pool): they are
warm before any plot reaches them, they draw the bytes the serial renderer draws, and the
creating process of ``railval workshop create`` never loads the plotting backend nor
scipy.signal (docs/workshops.md "Workers started before the signals are read")."""

from __future__ import annotations

import json
import multiprocessing
import subprocess
import sys

import pytest

from railval.app.services import workshop_canvas as wc
from railval.app.services import workshop_render as wr
from railval.app.services import workshops as ws
from railval.db import workshops as wsdb
from tests.test_workshop_jobs import _specs
from tests.test_workshop_pool import _probe


@pytest.mark.parametrize("method", ["fork", "forkserver"])
def test_early_workers_are_warm_and_draw_the_serial_bytes(monkeypatch, method):
    monkeypatch.setattr(wr, "start_context", lambda: multiprocessing.get_context(method))
    specs = _specs(12)
    wr.clear_cache()
    serial = wr.render_many(specs, workers=1)
    wr.clear_cache()
    monkeypatch.setattr(wc._LOCAL, "canvases", {}, raising=False)  # nothing drawn here before
    with wr.early_pool(40, workers=2) as pool:
        assert pool is not None
        probes = [pool.submit(_probe, i).result() for i in range(2)]
        pooled = wr.render_many(specs, pool=pool)
    # before any plot: the linear and logarithmic figures made, the glyphs kept
    assert all(p["canvases"] == [False, True] and min(p["glyphs"]) > 50 for p in probes), probes
    assert pooled == serial


def test_no_early_pool_where_the_plots_are_rendered_here(monkeypatch):
    with wr.early_pool(wr.POOL_MIN_PLOTS - 1, workers=2) as pool:
        assert pool is None
    with wr.early_pool(200, workers=1) as pool:
        assert pool is None
    with wr.serial_renderer(lambda *a, **k: b""), wr.early_pool(200, workers=2) as pool:
        assert pool is None


def test_an_early_pool_is_shut_down_when_reading_fails(monkeypatch):
    monkeypatch.setattr(wr, "start_context", lambda: multiprocessing.get_context("fork"))
    with pytest.raises(RuntimeError, match="reading failed"), wr.early_pool(64, workers=2) as pool:
        procs = list(pool._processes.values())
        raise RuntimeError("reading failed")
    for p in procs:
        p.join(timeout=30)
    assert procs and not any(p.is_alive() for p in procs)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from tests.browser_support import demo_database

    folder = tmp_path_factory.mktemp("early")
    db = demo_database(folder)
    yield db, folder
    db.dispose()


_CREATE = """
import json, sys
from railval.app.cli import main
code = main(sys.argv[1:])
sys.stdout.flush()
print(json.dumps({"code": code, "loaded": sorted(m for m in ("scipy.signal", "scipy.stats",
      "matplotlib.figure", "matplotlib.backends.backend_agg") if m in sys.modules)}))
"""

CHOICE = ["--campaign", "demo", "--sections", "S01", "S02", "--kinds", "Y_time", "Q_time",
          "az_cb_psd", "--repeats", "0"]


def test_cli_creation_draws_on_early_workers_the_same_plots(demo):
    """``railval workshop create`` (fork: a quiet main thread) stores the PNG bytes a creation
    without the early workers stores, and its own process imported neither the backend nor
    scipy.signal (the second run: the first fills the design store)."""
    db, _ = demo
    url = db.engine.url.render_as_string(hide_password=False)
    reports = []
    for name in ("E1", "E2"):
        proc = subprocess.run([sys.executable, "-c", _CREATE, "--db", url, "workshop", "create",
                               name, *CHOICE], capture_output=True, text=True, timeout=600,
                              check=False)
        assert proc.returncode == 0, proc.stderr
        reports.append(json.loads(proc.stdout.splitlines()[-1]))
    assert reports[1] == {"code": 0, "loaded": []}, reports
    wr.clear_cache()
    out = ws.create(db, "E0", "demo", sections=["S01", "S02"], kinds=["Y_time", "Q_time", "az_cb_psd"],
                    repeats=0.0)  # no planned count: the pool starts when the plots are known
    assert out["plots"] >= wr.POOL_MIN_PLOTS
    with db.session() as s:
        stored = {n: [(p.kind, p.section, p.channel, p.image_sha256)
                      for p in wsdb.plots(s, wsdb.get_workshop(s, n))] for n in ("E0", "E1", "E2")}
    assert stored["E1"] == stored["E0"] and stored["E2"] == stored["E0"]


def test_tasks_keep_the_plots_of_one_background_together():
    """Each task holds plots of one background (scale and labels), a group longer than the
    fair share is cut, every plot is in exactly one task, the largest tasks go first."""
    specs = _specs(30) + [s for s in _specs(30)[:6]]  # (repeated specs share a key)
    todo = {wr.content_key(s): s for s in specs}
    for workers in (1, 2, 3):
        chunks = wr._chunks_by_background(todo, workers)
        flat = [k for c in chunks for k in c]
        assert sorted(flat) == sorted(todo) and len(flat) == len(set(flat))
        fair = max(wr.CHUNK, -(-len(todo) // (2 * workers)))
        assert all(len({wr.background_key(todo[k]) for k in c}) == 1 and len(c) <= fair for c in chunks)
        assert [len(c) for c in chunks] == sorted((len(c) for c in chunks), reverse=True)
        groups = {wr.background_key(s) for s in todo.values()}
        assert len(chunks) <= sum(-(-sum(1 for s in todo.values() if wr.background_key(s) == g) // fair)
                                  for g in groups)


def test_a_server_job_thread_creates_on_early_forkserver_workers(demo, monkeypatch):
    """As the organiser's page does: ``create`` with the planned count, called from a
    thread that is not the main thread (the workers then start from the forkserver); the
    stored PNGs are those of a creation without early workers."""
    import threading

    db, _ = demo
    kinds = ["Y_time", "az_cb_psd"]
    used = []
    real = wr.start_context

    def spy():
        used.append(real())
        return used[-1]
    wr.clear_cache()
    got: dict = {}
    monkeypatch.setattr(wr, "start_context", spy)
    t = threading.Thread(target=lambda: got.update(ws.create(
        db, "F1", "demo", sections=["S03", "S04"], kinds=kinds, repeats=0.0, planned_plots=20)))
    t.start()
    t.join(600)
    monkeypatch.undo()
    assert got.get("plots", 0) >= wr.POOL_MIN_PLOTS and [c.get_start_method() for c in used] == ["forkserver"]
    wr.clear_cache()
    ws.create(db, "F0", "demo", sections=["S03", "S04"], kinds=kinds, repeats=0.0)
    with db.session() as s:
        stored = {n: [(p.kind, p.section, p.channel, p.image_sha256)
                      for p in wsdb.plots(s, wsdb.get_workshop(s, n))] for n in ("F0", "F1")}
    assert stored["F1"] == stored["F0"]
