"""HoloViews/Bokeh plot builders of the web app (docs/design.md §3–§5).

House rules, applied by every builder here:

* axes labelled with their quantity **and unit**; fonts readable at 1280 px width;
* measurement drawn first (beneath, black), simulations on top in a fixed colour order;
* fixed y scaling per plot from all traces (nice round limits) — switching a configuration
  on or off never rescales the other traces silently (``framewise=False``);
* the evaluated (constant-curvature) range shaded;
* long signals downsampled on the server so a 20 000-sample trace sends ~2 000 points and
  re-samples on zoom.

The Compare page uses :class:`CompareFigure`: plain Bokeh figures built once per session whose
``ColumnDataSource`` data are replaced on a switch (min-max-LTTB with tsdownsample directly),
because building and rendering HoloViews overlays with a ``downsample1d`` stream cost ~0.3 s
per plot. :func:`compare_plot` (HoloViews) remains for static use.
"""

from __future__ import annotations

import math
from typing import Any

import holoviews as hv
import numpy as np
from bokeh.events import RangesUpdate
from bokeh.models import (
    BoxAnnotation,
    ColumnDataSource,
    HoverTool,
    Legend,
    LegendItem,
    Range1d,
    Span,
)
from bokeh.plotting import figure
from holoviews.operation.downsample import downsample1d

from railval.app.scales import (
    FAIL_COLOR,
    LIMIT_COLOR,
    MEASURED_COLOR,
    PASS_COLOR,
    SIM_COLORS,
    downsample_xy,
    nice_limits,
    norm_axis_top,
    norm_ticks,
    passes,
    unit_label,
)
from railval.app.state.compare import CompareData

hv.extension("bokeh", logo=False)

FONTS = {"title": "13pt", "labels": "12pt", "xticks": "11pt", "yticks": "11pt", "legend": "11pt"}
#: signals longer than this are downsampled on the server
DOWNSAMPLE_ABOVE = 2000
DOWNSAMPLE_WIDTH = 1000
#: points per trace sent by :class:`CompareFigure` (per visible window, refined on zoom)
FIGURE_POINTS = 2000
#: traces a :class:`CompareFigure` can show: the measurement + 4 configurations
MAX_TRACES = 5
EVAL_FILL = "#f2c14e"


def _curve(x: np.ndarray, y: np.ndarray, label: str, xdim: hv.Dimension, ydim: hv.Dimension,
           color: str, width: float) -> hv.Curve:
    return hv.Curve((x, y), xdim, ydim, label=label).opts(color=color, line_width=width)


def compare_plot(data: CompareData, height: int = 330, downsample: bool = True,
                 ylim: tuple[float, float] | None = None) -> hv.Overlay | hv.DynamicMap:
    """Measured vs simulated series (or PSD) of one channel, with the evaluated range shaded."""
    # dimension names decide which axes Panel links across panes: series of one page share
    # "time"/"distance" and "signal"; a PSD has its own "frequency"/"psd"
    xdim = hv.Dimension(data.x_label.split(" (")[0], label=data.x_label)
    ydim = hv.Dimension("psd" if data.log_axes else "signal", label=data.y_label)
    ordered = sorted(data.traces, key=lambda t: not t.measured)  # measurement beneath
    finite = [t.y[np.isfinite(t.y)] for t in ordered if t.y.size]
    curves: list[hv.Curve] = []
    sim_i = 0
    for t in ordered:
        if t.measured:
            color, width = MEASURED_COLOR, 1.6
        else:
            color, width = SIM_COLORS[sim_i % len(SIM_COLORS)], 1.3
            sim_i += 1
        curves.append(_curve(t.x, t.y, t.label, xdim, ydim, color, width))
    if not curves:
        curves.append(hv.Curve([], xdim, ydim))
    overlay: Any = hv.Overlay(curves)
    if downsample and not data.log_axes and max(len(c) for c in curves) > DOWNSAMPLE_ABOVE:
        # one dynamic operation for the whole overlay (one RangeXY stream, data sliced once)
        overlay = downsample1d(overlay, algorithm="minmax-lttb", width=DOWNSAMPLE_WIDTH)
    if data.eval_range is not None:
        a, b = data.eval_range
        overlay = overlay * hv.VSpan(a, b).opts(color="#f2c14e", alpha=0.18, line_alpha=0)
    opts: dict[str, Any] = {
        "title": data.title, "xlabel": data.x_label, "ylabel": data.y_label, "responsive": True, "height": height, "fontsize": FONTS,
        "show_grid": True, "legend_position": "right", "framewise": False,
        "tools": ["hover"], "active_tools": ["box_zoom"],
    }
    if data.log_axes:
        opts.update(logx=True, logy=True)
        if finite:
            lo = min(float(np.min(f[f > 0])) for f in finite if np.any(f > 0))
            hi = max(float(np.max(f)) for f in finite)
            # six decades below the peak: the filter roll-off would otherwise dominate the axis
            lo = max(lo, hi * 1e-6)
            opts["ylim"] = (10 ** math.floor(math.log10(lo)), 10 ** math.ceil(math.log10(hi)))
    else:
        if ylim is None and finite:
            ylim = nice_limits(min(float(f.min()) for f in finite if f.size),
                               max(float(f.max()) for f in finite if f.size))
        if ylim is not None:
            opts["ylim"] = ylim
    return overlay.opts(hv.opts.Overlay(**opts))


class CompareFigure:
    """One plain Bokeh figure of the Compare page, built once and updated in place.

    Up to :data:`MAX_TRACES` line renderers (the first reserved for the measurement, black,
    drawn beneath; then :data:`SIM_COLORS`), the evaluated range as a ``BoxAnnotation``, the
    legend outside right, fixed y range. :meth:`update` replaces the sources' data (downsampled
    to :data:`FIGURE_POINTS`) and labels; with ``x_range`` shared between figures, zooming one
    zooms the others, and the visible window is re-sampled from the full arrays on the server
    (``RangesUpdate``). ``log_axes`` gives a log–log figure (PSD, never downsampled).
    """

    def __init__(self, height: int = 330, log_axes: bool = False, x_range: Range1d | None = None,
                 x_name: str = "x", y_name: str = "y"):
        self.log_axes = log_axes
        self.x_range = x_range if x_range is not None else Range1d(0.0, 1.0)
        kw: dict[str, Any] = {"x_axis_type": "log", "y_axis_type": "log"} if log_axes else {}
        self.fig = figure(height=height, sizing_mode="stretch_width", x_range=self.x_range,
                          y_range=Range1d(0.0, 1.0), tools="pan,box_zoom,wheel_zoom,reset,save",
                          active_drag="box_zoom", toolbar_location="right", **kw)
        _fonts(self.fig)
        self.shade = BoxAnnotation(left=0.0, right=0.0, fill_color=EVAL_FILL, fill_alpha=0.18,
                                   line_alpha=0, visible=False, level="underlay")
        self.fig.add_layout(self.shade)
        self.sources: list[ColumnDataSource] = []
        self.renderers = []
        for i in range(MAX_TRACES):
            color, width = (MEASURED_COLOR, 1.6) if i == 0 else (SIM_COLORS[(i - 1) % len(SIM_COLORS)], 1.3)
            src = ColumnDataSource({"x": np.zeros(0), "y": np.zeros(0)})
            self.sources.append(src)
            self.renderers.append(self.fig.line("x", "y", source=src, line_color=color,
                                                line_width=width, visible=False))
        self.legend = Legend(items=[], location="top_left", label_text_font_size=FONTS["legend"],
                             click_policy="hide")
        self.fig.add_layout(self.legend, "right")
        self.hover = HoverTool(tooltips=[("", "$name"), (x_name, "$x"), (y_name, "$y")],
                               renderers=self.renderers, mode="mouse")
        self.fig.add_tools(self.hover)
        self._full: list[tuple[np.ndarray, np.ndarray] | None] = [None] * MAX_TRACES
        if not log_axes:
            self.fig.on_event(RangesUpdate, self._on_ranges)

    def update(self, data: CompareData, ylim: tuple[float, float] | None = None) -> None:
        """Show ``data``: measurement beneath, simulations on top, evaluated range shaded,
        x range reset to the data, y range ``ylim`` (or nice limits / six decades for log)."""
        ordered = sorted(data.traces, key=lambda t: not t.measured)
        self.fig.title.text = data.title
        self.fig.xaxis[0].axis_label = data.x_label
        self.fig.yaxis[0].axis_label = data.y_label
        slots: list[int] = []
        sim_i = 1
        for t in ordered:
            if t.measured and 0 not in slots:
                slots.append(0)
            elif sim_i < MAX_TRACES:
                slots.append(sim_i)
                sim_i += 1
            else:
                slots.append(-1)  # more configurations than renderers: not shown
        items = []
        used = set()
        for t, slot in zip(ordered, slots, strict=True):
            if slot < 0:
                continue
            used.add(slot)
            x, y = np.asarray(t.x, dtype=float), np.asarray(t.y, dtype=float)
            self._full[slot] = (x, y)
            if self.log_axes:
                keep = (x > 0) & (y > 0)
                sx, sy = x[keep], y[keep]
            else:
                sx, sy = downsample_xy(x, y)
            self.sources[slot].data = {"x": sx, "y": sy}
            self.renderers[slot].name = t.label
            self.renderers[slot].visible = True
            items.append(LegendItem(label=t.label, renderers=[self.renderers[slot]]))
        for slot in range(MAX_TRACES):
            if slot not in used:
                self._full[slot] = None
                self.renderers[slot].visible = False
                self.sources[slot].data = {"x": np.zeros(0), "y": np.zeros(0)}
        self.legend.items = items
        if data.eval_range is not None:
            self.shade.update(left=float(data.eval_range[0]), right=float(data.eval_range[1]), visible=True)
        else:
            self.shade.visible = False
        xs = [f[0][np.isfinite(f[0])] for f in self._full if f is not None]
        xs = [v[v > 0] if self.log_axes else v for v in xs]
        xs = [v for v in xs if v.size]
        if xs:
            self.x_range.update(start=min(float(v.min()) for v in xs), end=max(float(v.max()) for v in xs))
        finite = [t.y[np.isfinite(t.y)] for t in ordered if t.y.size]
        finite = [f for f in finite if f.size]
        if self.log_axes:
            pos = [f[f > 0] for f in finite if np.any(f > 0)]
            if pos:
                hi = max(float(np.max(f)) for f in pos)
                lo = max(min(float(np.min(f)) for f in pos), hi * 1e-6)  # six decades below the peak
                ylim = (10 ** math.floor(math.log10(lo)), 10 ** math.ceil(math.log10(hi)))
        elif ylim is None and finite:
            ylim = nice_limits(min(float(f.min()) for f in finite), max(float(f.max()) for f in finite))
        if ylim is not None:
            self.fig.y_range.update(start=float(ylim[0]), end=float(ylim[1]))

    def refine(self, x0: float, x1: float) -> None:
        """Re-sample the window ``[x0, x1]`` from the full arrays (zoom)."""
        for slot, full in enumerate(self._full):
            if full is not None:
                sx, sy = downsample_xy(full[0], full[1], x_range=(x0, x1))
                self.sources[slot].data = {"x": sx, "y": sy}

    def _on_ranges(self, event: RangesUpdate) -> None:
        if event.x0 is not None and event.x1 is not None:
            self.refine(float(event.x0), float(event.x1))


def _bars(rows: list[dict[str, Any]], key: str, ci_key: str | None, title: str,
          ylabel: str, signed: bool, height: int) -> tuple[hv.Overlay, hv.Bars]:
    quantities = [r["quantity"] for r in rows]
    values = [float("nan") if r.get(key) is None else float(r[key]) for r in rows]
    status = ["pass" if passes(v) else "fail" for v in values]
    bars = hv.Bars(
        {"quantity": quantities, "value": values, "verdict": status},
        kdims=[hv.Dimension("quantity", label="EN 14363 quantity")],
        vdims=[hv.Dimension("value", label=ylabel), "verdict"],
    ).opts(color=hv.dim("verdict").categorize({"pass": PASS_COLOR, "fail": FAIL_COLOR}),
           tools=["tap", "hover"], nonselection_alpha=0.45, line_color=None)
    layers: list[Any] = [bars]
    cis = [r.get(ci_key) for r in rows] if ci_key else []
    if cis and all(isinstance(c, (list, tuple)) and len(c) == 2 and None not in c for c in cis):
        lo = [v - float(c[0]) for v, c in zip(values, cis, strict=True)]
        hi = [float(c[1]) - v for v, c in zip(values, cis, strict=True)]
        layers.append(hv.ErrorBars((quantities, values, lo, hi), kdims=["quantity"],
                                   vdims=["value", "neg", "pos"]).opts(line_width=1.5))
    layers.append(hv.HLine(1.0).opts(color=LIMIT_COLOR, line_dash="dashed", line_width=1.5))
    if signed:
        layers.append(hv.HLine(-1.0).opts(color=LIMIT_COLOR, line_dash="dashed", line_width=1.5))
        layers.append(hv.HLine(0.0).opts(color="#888888", line_width=0.8))
    extent = [abs(v) for v in values if math.isfinite(v)]
    extent += [abs(float(b)) for c in cis if isinstance(c, (list, tuple)) for b in c
               if b is not None and math.isfinite(float(b))]
    # one axis for every configuration (±2 like the heat map), wider only when a bar or its
    # interval exceeds it; bars and intervals stay inside
    top = norm_axis_top(extent)
    ylim = (-top, top) if signed else (0.0, top)
    overlay = hv.Overlay(layers).opts(
        title=title, responsive=True, height=height, fontsize=FONTS, ylim=ylim,
        yticks=norm_ticks(top, signed),
        xrotation=45, show_grid=True, show_legend=False,
    )
    return overlay, bars


def validation_bars(rows: list[dict[str, Any]], height: int = 340):
    """The seed's Fig. 12/13: normalised mean (signed, limits ±1) and normalised std
    (limit 1) per quantity; bars red where the limit is exceeded.

    Returns ``(mean_overlay, mean_bars, std_overlay, std_bars)`` — attach a
    ``hv.streams.Selection1D`` to a ``*_bars`` element to react to clicks.
    """
    mean_ov, mean_bars = _bars(rows, "mean_norm", "mean_norm_ci", "Normalised mean (mean / limit)",
                               "mean / limit (–)", True, height)
    std_ov, std_bars = _bars(rows, "std_norm", "std_norm_ci",
                             "Normalised std (std / limit, n − 1)",
                             "std / limit (–)", False, height)
    return mean_ov, mean_bars, std_ov, std_bars


def zone_coverage(counts: dict[int, int], need: int = 3, height: int = 260):
    """Sections per EN 14363 test zone as a plain Bokeh figure (first page: no HoloViews
    render on the way to the first paint): zones below ``need`` red, the need dashed,
    integer ticks (sections are counted)."""
    zones = [f"zone {z}" for z in sorted(counts)]
    vals = [int(counts[z]) for z in sorted(counts)]
    ok = ["ok" if v >= need else "short" for v in vals]
    top = max(vals + [need]) + 1
    fig = figure(x_range=zones, y_range=Range1d(0, top), height=height, sizing_mode="stretch_width",
                 title=f"Sections per zone (need ≥ {need})", tools="save", toolbar_location="right")
    src = ColumnDataSource({"zone": zones, "sections": vals, "ok": ok,
                            "color": [PASS_COLOR if o == "ok" else FAIL_COLOR for o in ok]})
    fig.vbar(x="zone", top="sections", width=0.8, source=src, fill_color="color", line_color=None)
    fig.add_layout(Span(location=need, dimension="width", line_color=LIMIT_COLOR,
                        line_dash="dashed", line_width=1.5))
    fig.add_tools(HoverTool(tooltips=[("zone", "@zone"), ("sections", "@sections")]))
    fig.xaxis.axis_label = "EN 14363 test zone"
    fig.yaxis.axis_label = "sections (count)"
    fig.yaxis.ticker = list(range(0, top + 1, 1 if top <= 12 else max(1, top // 8)))
    fig.xgrid.grid_line_color = None
    _fonts(fig)
    return fig


def _fonts(fig) -> None:
    """House fonts (:data:`FONTS`) on a plain Bokeh figure."""
    fig.title.text_font_size = FONTS["title"]
    for ax in (*fig.xaxis, *fig.yaxis):
        ax.axis_label_text_font_size = FONTS["labels"]
        ax.major_label_text_font_size = FONTS["xticks"]


#: Colour limits of the "where it fails" heat maps, the same on every page and configuration
#: so colours compare: mean D_v / std limit (beyond ±2 saturated; the cell text is exact) and
#: log2 PSD ratio (±1 = a factor 2 in power).
WHERE_LIMIT = 2.0
PSD_RATIO_LIMIT = 1.0


def pattern_heatmap(grid, title: str, limit: float, value_label: str, x_label: str,
                    y_label: str = "EN 14363 quantity", height: int = 330) -> hv.Overlay:
    """Heat map of a :class:`railval.app.state.PatternGrid` with the value in each cell; diverging
    colours fixed at ±``limit`` (pass the same limit to plots that are compared: red =
    simulation above measurement, blue = below)."""
    cells = [(c, r, float(grid.values[i, j])) for i, r in enumerate(grid.rows)
             for j, c in enumerate(grid.cols) if math.isfinite(grid.values[i, j])]
    xdim = hv.Dimension("col", label=x_label)
    ydim = hv.Dimension("row", label=y_label)
    vdim = hv.Dimension("value", label=value_label)
    heat = hv.HeatMap(cells, [xdim, ydim], vdim).redim.values(col=grid.cols, row=grid.rows[::-1]).opts(
        cmap="RdBu_r", clim=(-limit, limit), colorbar=True, tools=["hover"], line_color="white")
    overlay = heat
    for dark, color in ((False, "#222222"), (True, "#ffffff")):  # light text on the deep colours
        part = [(c, r, f"{v:+.2f}") for c, r, v in cells if (abs(v) > 0.55 * limit) == dark]
        if part:
            overlay = overlay * hv.Labels(part, [xdim, ydim], "text").opts(text_font_size="9pt",
                                                                          text_color=color)
    return overlay.opts(title=title, responsive=True, height=height, fontsize=FONTS,
                        xrotation=0, toolbar="right")


def lineage_chart(rows: list[dict[str, Any]], height: int = 300) -> hv.Overlay:
    """Largest normalised error along a configuration lineage, limit 1.0 dashed."""
    names = [r["configuration"] for r in rows]
    vals = [float(r["max_norm"]) for r in rows]
    xdim = hv.Dimension("configuration", label="configuration (root → newest)")
    ydim = hv.Dimension("max_norm", label="largest normalised error (–)")
    curve = hv.Curve((names, vals), xdim, ydim).opts(color="#1f77b4", line_width=2)
    pts = hv.Scatter({"configuration": names, "max_norm": vals,
                      "verdict": ["validated" if r["validated"] else "not validated" for r in rows]},
                     xdim, [ydim, "verdict"]).opts(
        size=11, color=hv.dim("verdict").categorize({"validated": PASS_COLOR, "not validated": FAIL_COLOR}),
        tools=["hover"])
    line = hv.HLine(1.0).opts(color=LIMIT_COLOR, line_dash="dashed", line_width=1.5)
    top = max([1.2] + [v * 1.1 for v in vals if math.isfinite(v)])
    return (curve * pts * line).opts(title="Error along the lineage", responsive=True, height=height,
                                     fontsize=FONTS, ylim=(0, top), show_grid=True)


__all__ = [
    "CompareFigure",
    "compare_plot",
    "downsample_xy",
    "lineage_chart",
    "nice_limits",
    "pattern_heatmap",
    "unit_label",
    "validation_bars",
    "zone_coverage",
]
