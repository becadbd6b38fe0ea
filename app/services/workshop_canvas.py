"""The drawing of review plots: matplotlib's Agg backend, one reusable figure per axis type
and thread, and the PNG writer (docs/workshops.md "One fixed scaling", "Rendering speed").

Output is deterministic: fixed size and dpi, DejaVu Sans (shipped with matplotlib), no time
stamp or software version in the PNG metadata, no antialiasing differences between runs (same
library build) — the same inputs give byte-identical files.

Look (the same for every plot of a workshop, :data:`railval.app.services.workshop_render.STYLE`):
measurement drawn first (beneath) in black, simulation on top in Okabe–Ito vermilion (the
app's colours, :mod:`railval.app.scales`: a colour-blind-safe pair; Okabe & Ito 2008, "Color
Universal Design"), legend in the upper right corner, both axes labelled with units, the
kind's fixed axis ranges (:func:`railval.core.workshop.kind_scale`).

Speed: a thread keeps one figure per axis type (linear or logarithmic y) and redraws it with
each plot's data (:class:`_Canvas`); the static part of a plot (background, grid, ticks, tick
and axis labels — the same for every plot of a kind at its fixed scaling) is drawn once per
scale and its pixels restored for each plot, which then draws only its lines, spines, title
and legend, in the order of a full draw: the pixels are those of a figure made for the plot
alone (:func:`render_fresh`; tests/test_workshop_jobs.py compares them with matplotlib's own
rendering). The PNG is written by :func:`encode_png` (RGB, Up filter, zlib level 1).
"""

from __future__ import annotations

import json
import struct
import threading
import zlib
from collections import OrderedDict
from typing import Any

import matplotlib

matplotlib.use("Agg", force=False)

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from railval.app.services.workshop_glyphs import install as install_glyphs
from railval.app.services.workshop_glyphs import keep_layout
from railval.app.services.workshop_render import STYLE
from railval.core.workshop import AxisRange, Scale

_RC = {
    "font.family": "sans-serif",
    "font.sans-serif": [STYLE["font"]],
    "font.size": STYLE["font_size"],
    "axes.titlesize": STYLE["title_size"],
    "svg.hashsalt": "railval",
    "path.simplify": True,
}

#: zlib effort of the stored PNGs (:func:`encode_png`; 1: fastest — the pixels are the same
#: at every level)
PNG_LEVEL = 1
#: static backgrounds (one per scale and labels) a canvas keeps
BACKGROUNDS = 16


class _Canvas:
    """One reusable review figure (one per axis type and thread): two lines, grid and legend
    made once. The static part of a plot — background, grid, ticks, tick labels and axis
    labels, the same for every plot of one kind at its fixed scaling — is drawn once per
    (scale, labels) and kept as pixels (:meth:`_background`); :meth:`draw` restores them and
    draws only what differs — the two lines, the spines between them, the title and the
    legend above them — in the order a full draw uses (z-order), so the pixels are those of
    a figure made for the plot alone (tests/test_workshop_jobs.py)."""

    def __init__(self, log: bool):
        m, s = STYLE["measurement"], STYLE["simulation"]
        with matplotlib.rc_context(_RC):
            fig = Figure(figsize=(STYLE["width_in"], STYLE["height_in"]), dpi=STYLE["dpi"])
            install_glyphs(FigureCanvasAgg(fig).get_renderer())  # kept glyph bitmaps
            ax = fig.add_subplot(1, 1, 1)
            ax.set_axisbelow(True)
            ax.grid(True, color=STYLE["grid_color"], linewidth=0.6)
            (self.meas,) = ax.plot([], [], color=m["color"], linewidth=m["linewidth"],
                                   zorder=m["zorder"], label=m["label"])
            (self.sim,) = ax.plot([], [], color=s["color"], linewidth=s["linewidth"],
                                  zorder=s["zorder"], label=s["label"])
            if log:
                ax.set_yscale("log")
            self.legend = ax.legend(loc=STYLE["legend"], frameon=True, framealpha=0.9)
            keep_layout(self.legend._legend_box)  # the same for every plot
            fig.subplots_adjust(**STYLE["margins"])
        self.fig, self.ax = fig, ax
        self.title = ax._left_title  # what set_title(..., loc="left") sets
        self._backgrounds: OrderedDict[tuple, Any] = OrderedDict()
        self._axes_key: tuple | None = None  # the scale and labels the axes are set to

    def _dynamic(self) -> list:
        """The artists drawn per plot, in the z-order of a full draw (measurement 2, spines
        2.5, simulation 3, title 3, legend 5)."""
        return [self.meas, *self.ax.spines.values(), self.sim, self.title, self.legend]

    def _background(self, scale: Scale, x_label: str, y_label: str):
        key = (json.dumps(scale.to_dict(), sort_keys=True), x_label, y_label)
        ax = self.ax
        ax.set_xlim(scale.x.lo, scale.x.hi)  # the lines' data coordinates
        ax.set_ylim(scale.y.lo, scale.y.hi)
        if key != self._axes_key:  # the axes' ticks and labels of this scale (the title's
            self._axes_key = key   # place may depend on them: the y offset text)
            if not scale.y.log:
                ax.set_yticks(_ticks(scale.y.lo, scale.y.hi, scale.y.step))
            ax.set_xticks(_ticks(scale.x.lo, scale.x.hi, scale.x.step))
            ax.set_xlim(scale.x.lo, scale.x.hi)
            ax.set_ylim(scale.y.lo, scale.y.hi)
            ax.set_xlabel(x_label)
            ax.set_ylabel(y_label)
        got = self._backgrounds.get(key)
        if got is not None:
            self._backgrounds.move_to_end(key)
            return got
        self.title.set_text("")  # (an empty title is not placed by the full draw)
        for a in self._dynamic():
            a.set_visible(False)
        self.fig.canvas.draw()
        for a in self._dynamic():
            a.set_visible(True)
        # whether the y axis shows an offset text at this scale (the title keeps clear of it)
        off = ax.yaxis.offsetText
        got = self._backgrounds[key] = (self.fig.canvas.copy_from_bbox(self.fig.bbox),
                                        bool(off.get_visible() and off.get_text()))
        while len(self._backgrounds) > BACKGROUNDS:
            self._backgrounds.popitem(last=False)
        return got

    def draw(self, x_meas, y_meas, x_sim, y_sim, scale: Scale, *, title: str, x_label: str,
             y_label: str) -> bytes:
        canvas = self.fig.canvas
        with matplotlib.rc_context(_RC):
            bg, y_offset = self._background(scale, x_label, y_label)
            canvas.restore_region(bg)
            self.meas.set_data(x_meas, y_meas)
            self.sim.set_data(x_sim, y_sim)
            self.title.set_text(title)
            renderer = canvas.get_renderer()
            self._place_title(renderer, y_offset)
            for a in self._dynamic():
                a.draw(renderer)
            return encode_png(np.asarray(canvas.buffer_rgba()))


    def _place_title(self, renderer, y_offset: bool) -> None:
        """Place the title where a full draw puts it: matplotlib's
        ``Axes._update_title_position``, twice (where the title goes, then what a full draw
        does before drawing). That method lays out the y axis's ticks again
        (``yaxis.get_tightbbox``) only to bring the axis's offset text up to date and keep
        the title clear of it; without an offset text at this scale (seen when its
        background was drawn, and none shown now) the title's place does not depend on it,
        and the relayout — a third of a plot's drawing time — is skipped: the same place,
        the same pixels (tests/test_workshop_jobs.py compares with matplotlib's own draw)."""
        ax = self.ax
        off = ax.yaxis.offsetText
        if y_offset or (off.get_visible() and off.get_text()):
            ax._update_title_position(renderer)
            ax._update_title_position(renderer)
            return
        ax.yaxis.get_tightbbox = _no_tightbbox  # (its result is not used there)
        try:
            ax._update_title_position(renderer)
            ax._update_title_position(renderer)
        finally:
            del ax.yaxis.get_tightbbox


def _no_tightbbox(renderer=None, *, for_layout_only=False) -> None:
    return None


def encode_png(rgba: np.ndarray) -> bytes:
    """PNG bytes of a figure's pixels (PNG specification, W3C Recommendation 2003 / ISO/IEC
    15948: signature, IHDR, pHYs, one IDAT, IEND; each chunk's CRC-32 over type and data):
    8-bit RGB (the figure is opaque: alpha 255 everywhere, checked), every row but the first
    with filter type 2 (Up: the byte minus the one above it, modulo 256; the first row with
    type 0), zlib level :data:`PNG_LEVEL`, the figure's dpi as pixels per metre, no other
    metadata — same pixels, same bytes. Measured on four plots of the demo workshop (load
    2.8–3.8): 15 ms and 80 kB a plot against 38 ms and 71 kB at level 6 (docs/workshops.md
    "Rendering speed")."""
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"review plot pixels have shape {rgba.shape}, expected (h, w, 4)")
    px = np.ascontiguousarray(rgba, np.uint8)
    if not (px.view("<u4") >= 0xFF000000).all():  # alpha: the high byte of each RGBA word
        raise ValueError("review plot has transparent pixels; RGB would change them")
    h, w = px.shape[:2]
    # Up filter on all four channels (contiguous: fast; each byte minus the one above, the
    # channels independent), then alpha dropped by Pillow's raw packer, which writes the RGBA
    # image's R, G, B as they are ("RGB" raw mode of an "RGBA" image) — the same bytes as
    # filtering the RGB pixels; packing straight from RGBA, without first converting the image
    # to RGB, takes 8.0 instead of 10.2 ms of the whole encoding (demo plot, 200 alternating runs)
    up = np.empty_like(px)
    up[0] = px[0]
    np.subtract(px[1:], px[:-1], out=up[1:])  # uint8 arithmetic wraps: modulo 256
    rgb = Image.frombuffer("RGBA", (w, h), up, "raw", "RGBA", 0, 1).tobytes("raw", "RGB")
    rows = np.empty((h, 1 + 3 * w), np.uint8)
    rows[0, 0], rows[1:, 0] = 0, 2  # filter types: none, then Up
    rows[:, 1:] = np.frombuffer(rgb, np.uint8).reshape(h, 3 * w)
    ppm = round(STYLE["dpi"] / 0.0254)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    return b"".join((b"\x89PNG\r\n\x1a\n",
                     chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)),
                     chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1)),
                     chunk(b"IDAT", zlib.compress(rows.tobytes(), PNG_LEVEL)),
                     chunk(b"IEND", b"")))


_LOCAL = threading.local()


def render_png(x_meas: np.ndarray, y_meas: np.ndarray, x_sim: np.ndarray, y_sim: np.ndarray,
               scale: Scale, *, title: str, x_label: str, y_label: str) -> bytes:
    """One review plot as PNG bytes (see the module docstring for the look), drawn on this
    thread's reusable figure of the plot's axis type."""
    canvases = getattr(_LOCAL, "canvases", None)
    if canvases is None:
        canvases = _LOCAL.canvases = {}
    log = bool(scale.y.log)
    if log not in canvases:
        canvases[log] = _Canvas(log)
    return canvases[log].draw(x_meas, y_meas, x_sim, y_sim, scale, title=title,
                              x_label=x_label, y_label=y_label)


def render_fresh(x_meas: np.ndarray, y_meas: np.ndarray, x_sim: np.ndarray, y_sim: np.ndarray,
                 scale: Scale, *, title: str, x_label: str, y_label: str) -> bytes:
    """The same plot on a figure made for it alone (what :func:`render_png` is checked
    against)."""
    return _Canvas(bool(scale.y.log)).draw(x_meas, y_meas, x_sim, y_sim, scale, title=title,
                                           x_label=x_label, y_label=y_label)


#: the title of :func:`warm`'s plots: the characters of review plot titles
_WARM_TITLE = ("Guiding force Y, wheelset 1 left wheel — section S01\n"
               "Vehicle (bogie), configuration baseline 0123456789 …")


def warm() -> None:
    """Make this thread's linear and logarithmic figures and keep the glyph bitmaps of a
    typical title, the legend and the tick labels (a worker forked afterwards starts with
    them). Nothing is kept but figures and glyphs: a plot's pixels do not depend on what was
    drawn before (tests/test_workshop_jobs.py). Nothing to do once this thread has drawn on
    both figures."""
    if len(getattr(_LOCAL, "canvases", {})) == 2:
        return
    x = np.array([0.0, 1.0])
    for log in (False, True):
        y = AxisRange(1e-3, 1.0, 10.0, log=True) if log else AxisRange(-1.0, 1.0, 0.5)
        render_png(x, x / 2 + 0.1, x, x / 3 + 0.1, Scale(AxisRange(0.0, 1.0, 0.25), y),
                   title=_WARM_TITLE, x_label="distance in m", y_label="force in kN")


def _ticks(lo: float, hi: float, step: float) -> np.ndarray:
    n = round((hi - lo) / step)
    return np.round(lo + step * np.arange(n + 1), 12)


__all__ = ["encode_png", "render_fresh", "render_png", "warm"]
