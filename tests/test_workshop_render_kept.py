"""What the review-plot renderer keeps between plots (docs/workshops.md "Rendering speed"):
text layouts per font, size, dpi and text (:mod:`railval.app.services.workshop_glyphs`), the
legend's layout per renderer size and dpi, the PNG rows filtered on all four channels — each
giving the same pixels or bytes as without it — and the benchmark's serial renderer
(:func:`railval.app.services.workshop_render.serial_renderer`)."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.offsetbox import OffsetBox

from railval.app.services import workshop_glyphs
from railval.app.services import workshop_canvas as wc
from railval.app.services import workshop_render as wr
from railval.core.workshop import AxisRange, Scale

#: (text, font size): the same text at two sizes and another text at the first size — a
#: layout kept without the size or the text in its key draws the wrong glyphs or places
TEXTS = [("Guiding force Y", 10), ("Guiding force Y", 19), ("Yaw moment Z", 10),
         ("Guiding force Y", 10)]


def _texts_pixels(kept: bool) -> np.ndarray:
    fig = Figure(figsize=(4, 2), dpi=100)
    canvas = FigureCanvasAgg(fig)
    if kept:
        workshop_glyphs.install(canvas.get_renderer())
    for i, (s, size) in enumerate(TEXTS):
        fig.text(0.05, 0.8 - 0.22 * i, s, fontsize=size)
    canvas.draw()
    canvas.draw()  # the second draw reads the kept layouts
    return np.asarray(canvas.buffer_rgba()).copy()


def test_kept_text_layouts_draw_the_pixels_matplotlib_draws():
    assert np.array_equal(_texts_pixels(kept=True), _texts_pixels(kept=False))


def test_the_text_layout_key_holds_size_and_text():
    fig = Figure(figsize=(4, 2), dpi=100)
    canvas = FigureCanvasAgg(fig)
    renderer = canvas.get_renderer()
    workshop_glyphs.install(renderer)
    for i, (s, size) in enumerate(TEXTS):
        fig.text(0.05, 0.8 - 0.22 * i, s, fontsize=size)
    canvas.draw()
    keys = list(renderer._railval_layouts)
    assert len(keys) == 3  # the fourth text is the first one again
    assert {(k[2], k[4]) for k in keys} == {(10.0, "Guiding force Y"), (19.0, "Guiding force Y"),
                                            (10.0, "Yaw moment Z")}


def test_a_kept_legend_layout_is_computed_once_per_renderer_size_and_dpi():
    calls = []

    class Renderer:
        def __init__(self, dpi):
            self.width, self.height, self.dpi = 1000, 560, dpi

    kept = workshop_glyphs._kept(lambda r: calls.append(r.dpi) or len(calls))
    a, b = Renderer(100), Renderer(200)
    assert [kept(a), kept(a), kept(b), kept(Renderer(100))] == [1, 1, 2, 1]
    assert calls == [100, 200]


def test_the_legend_boxes_of_a_canvas_keep_their_layout():
    canvas = wc._Canvas(False)
    boxes, todo = [], [canvas.legend._legend_box]
    while todo:
        box = todo.pop()
        boxes.append(box)
        todo += [c for c in box.get_children() if isinstance(c, OffsetBox)]
    assert len(boxes) >= 5  # the packers, the two handles' areas and the two labels
    assert all("get_bbox" in b.__dict__ for b in boxes)


def _reference_rows(rgba: np.ndarray) -> bytes:
    """The PNG rows of render version 3 as first written: RGB, Up filter after row 0."""
    h, w = rgba.shape[:2]
    rgb = rgba[..., :3].astype(np.int16).reshape(h, 3 * w)
    rows = np.zeros((h, 1 + 3 * w), np.uint8)
    rows[1:, 0] = 2
    rows[0, 1:] = rgb[0]
    rows[1:, 1:] = (rgb[1:] - rgb[:-1]) % 256
    return rows.tobytes()


def test_encode_png_writes_the_rows_of_an_rgb_up_filter():
    rng = np.random.default_rng(11)
    rgba = np.full((9, 6, 4), 255, np.uint8)
    rgba[..., :3] = rng.integers(0, 256, (9, 6, 3), dtype=np.uint8)
    png = wc.encode_png(rgba)
    at = png.index(b"IDAT")
    size = int.from_bytes(png[at - 4:at], "big")
    assert zlib.decompress(png[at + 4:at + 4 + size]) == _reference_rows(rgba)
    # a strided view (not contiguous) gives the same bytes
    wide = np.full((9, 12, 4), 255, np.uint8)
    wide[:, ::2] = rgba
    assert wc.encode_png(wide[:, ::2]) == png


def _spec(i: int) -> wr.PlotSpec:
    x = np.linspace(0.0, 10.0, 50)
    return wr.PlotSpec(x, np.sin(x + i), x, np.cos(x + i),
                       Scale(AxisRange(0.0, 10.0, 2.0), AxisRange(-2.0, 2.0, 1.0)),
                       f"plot {i}", "distance in m", "force in kN")


def test_serial_renderer_renders_every_plot_in_order_without_the_cache_and_ends_with_its_block(
        monkeypatch):
    monkeypatch.setattr(wr, "RENDER_WORKERS", 2)
    monkeypatch.setattr(wr, "POOL_MIN_PLOTS", 1)  # the pool would be used without the block
    wr.clear_cache()
    specs = [_spec(i) for i in range(6)] + [_spec(0)]
    seen, progress = [], []

    def fake(xm, ym, xs, ys, scale, *, title, x_label, y_label):
        seen.append(title)
        return title.encode()

    with wr.serial_renderer(fake):
        out = wr.render_many(specs, lambda d, t: progress.append((d, t)))
    assert out == [s.title.encode() for s in specs]
    assert seen == [s.title for s in specs]  # every plot, duplicates too, in this process
    assert progress[-1] == (7, 7)
    assert wr._cached(wr.content_key(specs[0])) is None  # nothing remembered
    assert wr._SERIAL is None
    with pytest.raises(RuntimeError), wr.serial_renderer(fake):
        raise RuntimeError("a failed creation")
    assert wr._SERIAL is None  # restored after a failure too
