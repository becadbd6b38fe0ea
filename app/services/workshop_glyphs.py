"""Glyph bitmaps and text and legend layouts kept across review plots (docs/workshops.md
"Rendering speed").

Matplotlib's Agg renderer rasterises every glyph of every text anew with FreeType
(``RendererAgg._draw_text_glyphs_and_boxes``: set the size, set a transform whose
translation is the glyph's position in 1/64 pixel, render, draw the grey bitmap). Every
review plot draws a title of about a hundred glyphs and the same two legend labels, so most
of its drawing time went into rasterising glyphs already rasterised for the plot before.

FreeType rasterises an outline translated by whole pixels into the same bitmap, moved by
those pixels (the translation is applied to the hinted outline in 26.6 fixed point, a
multiple of 64 moves every coordinate by an integer number of pixels; FreeType API
reference, ``FT_Set_Transform`` and ``FT_Outline_Translate``). A glyph's bitmap therefore
depends on its font, size, glyph index, load flags, render mode and the translation modulo
64 only: :func:`install` makes a renderer keep those bitmaps with their offset from the
whole-pixel position and draw a kept one with the same ``draw_text_image`` call as
matplotlib. Only horizontal text without boxes (not mathtext) takes this path; the rest is
drawn by matplotlib's own method. The pixels are the same as matplotlib's
(tests/test_workshop_jobs.py compares whole plots with a figure drawn by matplotlib alone).

The same renderer keeps each line of text's layout (FreeType's glyphs and their places,
:func:`_draw_text`): the legend's labels are the same on every plot and a title's lines repeat
across sections and configurations. The review figure's legend keeps its boxes' layout
(:func:`keep_layout`). Measured on the 120 demo plots (load 7–9): 36–38 → 28–30 ms CPU a plot
together with the PNG rows of :func:`railval.app.services.workshop_render.encode_png`.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from types import MethodType
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import get_hinting_flag
from matplotlib.ft2font import RenderMode
from matplotlib.offsetbox import OffsetBox

#: glyph bitmaps a renderer keeps (oldest dropped first); a review plot's texts use a few
#: hundred (characters × sub-pixel positions)
GLYPHS = 20000


#: text layouts (the glyphs and their positions of one line of text) a renderer keeps; a
#: workshop's titles repeat their lines across sections and configurations, the legend's two
#: labels are the same in every plot
LAYOUTS = 2000


def install(renderer: Any) -> None:
    """Make ``renderer`` (a ``RendererAgg``) keep glyph bitmaps and text layouts across draws."""
    if getattr(renderer, "_railval_glyphs", None) is not None:
        return
    renderer._railval_glyphs = OrderedDict()
    renderer._railval_layouts = OrderedDict()
    renderer._railval_own = renderer._draw_text_glyphs_and_boxes
    renderer._draw_text_glyphs_and_boxes = MethodType(_draw_glyphs, renderer)
    renderer._railval_own_text = renderer.draw_text
    renderer.draw_text = MethodType(_draw_text, renderer)


def _draw_text(self: Any, gc, x, y, s, prop, angle, ismath=False, mtext=None) -> None:
    """``RendererAgg.draw_text`` with the line's layout (FreeType's glyph indices and
    positions, ``FT2Font._layout``) kept by font file, size, dpi, text, hinting, features and
    language — what the layout depends on; the same glyphs are drawn at the same places.
    Mathtext is drawn by the renderer's own method."""
    if ismath:
        return self._railval_own_text(gc, x, y, s, prop, angle, ismath=ismath, mtext=mtext)
    font = self._prepare_font(prop)
    flags = get_hinting_flag()
    features = mtext.get_fontfeatures() if mtext is not None else None
    language = mtext.get_language() if mtext is not None else None
    size = prop.get_size_in_points()
    key = (id(font), font.fname, size, self.dpi, s, str(flags),
           tuple(features) if features is not None else None, language)
    kept: OrderedDict = self._railval_layouts
    got = kept.get(key)
    if got is None:
        items = font._layout(s, flags=flags, features=features, language=language)
        got = kept[key] = (font, tuple((item.ft_object, item.glyph_index, item.x, item.y)
                                       for item in items))  # (the font kept: its id stays its own)
        if len(kept) > LAYOUTS:
            kept.popitem(last=False)
    else:
        kept.move_to_end(key)
    self._draw_text_glyphs_and_boxes(
        gc, x, y, angle,
        ((ft_object, size, glyph_index, 0, 1, gx, gy) for ft_object, glyph_index, gx, gy in got[1]),
        [])


def _draw_glyphs(self: Any, gc, x, y, angle, glyphs, boxes) -> None:
    """``RendererAgg._draw_text_glyphs_and_boxes`` for angle 0 without boxes, with kept
    bitmaps; anything else is drawn by the renderer's own method."""
    if angle or boxes:
        return self._railval_own(gc, x, y, angle, glyphs, boxes)
    kept: OrderedDict = self._railval_glyphs
    flags = get_hinting_flag()
    aa = bool(gc.get_antialiased())
    mode = RenderMode.NORMAL if aa else RenderMode.MONO
    height = self.height
    for font, size, glyph_index, slant, extend, dx, dy in glyphs:  # dy is upwards
        # the translation matplotlib sets, in 1/64 pixel (FreeType's y is upwards)
        tx = round(0x40 * (x + dx))
        ty = round(0x40 * (height - y + dy))
        key = (id(font), font.fname, size, self.dpi, glyph_index, slant, extend, str(flags),
               aa, tx & 63, ty & 63)
        got = kept.get(key)
        if got is None:
            got = _rasterise(self, font, size, glyph_index, slant, extend, flags, mode, aa,
                             tx, ty)
            kept[key] = got
            if len(kept) > GLYPHS:
                kept.popitem(last=False)
        buffer, left, top = got
        # draw_text_image's y is downwards and the bitmap's bottom side
        self._renderer.draw_text_image(buffer, left + (tx >> 6),
                                       int(height) - (top + (ty >> 6)) + buffer.shape[0], 0, gc)


def _rasterise(self, font, size, glyph_index, slant, extend, flags, mode, aa: bool,
               tx: int, ty: int) -> tuple[Any, int, int]:
    """FreeType's bitmap of one glyph at the sub-pixel part of ``(tx, ty)``, with its left
    and top relative to the whole-pixel part (matplotlib's calls, angle 0)."""

    font.set_size(size, self.dpi)
    font._set_transform(
        (0x10000 * np.array([[1.0, 0.0], [0.0, 1.0]])
         @ [[extend, extend * slant], [0, 1]]).round().astype(int),
        [tx, ty])
    bitmap = font._render_glyph(glyph_index, flags, mode)
    buffer = np.array(bitmap.buffer, copy=True)
    if not aa:
        buffer *= 0xff
    return buffer, bitmap.left - (tx >> 6), bitmap.top - (ty >> 6)


def keep_layout(box) -> None:
    """Make ``box`` (the legend's packed boxes) and the boxes in it keep their layout — the
    bounding box and the children's offsets (``OffsetBox.get_bbox`` and
    ``_get_bbox_and_child_offsets``), per renderer size and dpi: the legend's labels, handles
    and place in the axes are the same for every plot of a canvas, and recomputing their
    layout (every label's text extent) took a fifth of a plot's drawing. The legend is drawn
    from the same numbers at the same places: the same pixels (tests/test_workshop_jobs.py,
    tests/test_workshop_render_kept.py)."""
    for name in ("get_bbox", "_get_bbox_and_child_offsets"):
        if name not in box.__dict__:
            setattr(box, name, _kept(getattr(box, name)))
    for child in box.get_children():
        if isinstance(child, OffsetBox):
            keep_layout(child)


def _kept(own: Callable):
    """``own(renderer)``, computed once per renderer size and dpi."""
    memo: dict[tuple, Any] = {}

    def kept(renderer):
        key = (renderer.width, renderer.height, renderer.dpi)
        if key not in memo:
            memo[key] = own(renderer)
        return memo[key]
    return kept
