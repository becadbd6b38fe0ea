"""The render pool's start (docs/workshops.md "Rendering speed"): workers forked from a warmed
process and workers started by the forkserver give exactly the bytes of rendering in one
process, and a forked worker starts with the parent's figures and glyph bitmaps."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from railval.app.services import workshop_canvas as wc
from railval.app.services import workshop_render as wr
from railval.core.workshop import AxisRange, Scale
from tests.test_workshop_jobs import _ref, _same_pixels, _specs


def _probe(_: int) -> dict:
    """In a worker, before it renders anything: what it started with."""
    canvases = getattr(wc._LOCAL, "canvases", {})
    return {"canvases": sorted(canvases),
            "glyphs": [len(c.fig.canvas.get_renderer()._railval_glyphs) for c in canvases.values()]}


@pytest.mark.parametrize("method", ["fork", "forkserver"])
def test_pool_bytes_equal_the_serial_render(monkeypatch, method):
    monkeypatch.setattr(wr, "POOL_MIN_PLOTS", 4)
    monkeypatch.setattr(wr, "start_context", lambda: multiprocessing.get_context(method))
    specs = _specs(12)
    doubled = specs + specs[:4]
    wr.clear_cache()
    serial = wr.render_many(doubled, workers=1)
    wr.clear_cache()
    used = []
    real = wr.pool_context
    monkeypatch.setattr(wr, "pool_context", lambda: used.append(real()) or used[-1])
    pooled = wr.render_many(doubled, workers=2)
    assert [c.get_start_method() for c in used] == [method]  # the pool did run
    assert pooled == serial
    assert _same_pixels(pooled[:3], [_ref(s) for s in specs[:3]])  # matplotlib's own pixels


def test_a_forked_worker_starts_with_the_warm_figures(monkeypatch):
    monkeypatch.setattr(wr, "start_context", lambda: multiprocessing.get_context("fork"))
    monkeypatch.setattr(wc._LOCAL, "canvases", {}, raising=False)  # nothing rendered before
    ctx = wr.pool_context()
    with ProcessPoolExecutor(1, mp_context=ctx) as pool:
        got = pool.submit(_probe, 0).result()
    assert got["canvases"] == [False, True]  # linear and logarithmic figures made
    assert all(n > 50 for n in got["glyphs"])  # the title's, legend's and ticks' glyphs kept


def test_a_y_offset_text_moves_the_title_as_in_matplotlibs_own_draw():
    """A scale whose y tick labels need an offset text ("+1e3" above the axis, where the
    left-aligned title is): the title is placed clear of it as a full draw places it, on a
    figure that drew plots without offset text before (and back)."""
    x = np.linspace(0.0, 500.0, 400)
    y = 1000.25 + 0.2 * np.sin(x / 40)
    offset = Scale(AxisRange(0.0, 500.0, 100.0), AxisRange(1000.0, 1000.5, 0.1))
    title = "Wheel load Q, wheelset 1 left wheel — section S01\nVehicle, configuration c1"
    plain = _specs(2)
    specs = [plain[0], wr.PlotSpec(x, y, x, y + 0.05, offset, title, "distance in m", "Q in kN"),
             plain[1], wr.PlotSpec(x, y - 0.1, x, y, offset, "short", "distance in m", "Q in kN")]
    canvas = wc._Canvas(False)
    _, shown = canvas._background(offset, "distance in m", "Q in kN")
    assert shown  # the offset text is there at this scale
    got = [wr.render_png(s.x_meas, s.y_meas, s.x_sim, s.y_sim, s.scale, title=s.title,
                         x_label=s.x_label, y_label=s.y_label) for s in specs]
    assert _same_pixels(got, [_ref(s) for s in specs])
