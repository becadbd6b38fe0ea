"""Glyph bitmaps kept across review plots (docs/workshops.md "Rendering speed").

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
"""

from __future__ import annotations

from collections import OrderedDict
from types import MethodType
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import get_hinting_flag
from matplotlib.ft2font import RenderMode

#: glyph bitmaps a renderer keeps (oldest dropped first); a review plot's texts use a few
#: hundred (characters × sub-pixel positions)
GLYPHS = 20000


def install(renderer: Any) -> None:
    """Make ``renderer`` (a ``RendererAgg``) keep glyph bitmaps across draws."""
    if getattr(renderer, "_railval_glyphs", None) is not None:
        return
    renderer._railval_glyphs = OrderedDict()
    renderer._railval_own = renderer._draw_text_glyphs_and_boxes
    renderer._draw_text_glyphs_and_boxes = MethodType(_draw_glyphs, renderer)


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
