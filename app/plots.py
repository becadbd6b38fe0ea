"""HoloViews/Bokeh plot builders of the web app (DESIGN §3–§5).

House rules, applied by every builder here:

* axes labelled with their quantity **and unit**; fonts readable at 1280 px width;
* measurement drawn first (beneath, dark grey), simulations on top in a fixed colour order;
* fixed y scaling per plot from all traces (nice round limits) — switching a configuration
  on or off never rescales the other traces silently (``framewise=False``);
* the evaluated (constant-curvature) range shaded;
* long signals downsampled on the server with HoloViews ``downsample1d``
  (``minmax-lttb`` via tsdownsample) so a 20 000-sample trace sends ~1 000 points and
  re-samples on zoom.
"""

from __future__ import annotations

import math
from typing import Any

import holoviews as hv
import numpy as np
from holoviews.operation.downsample import downsample1d

from app.state import CompareData, nice_limits, unit_label

hv.extension("bokeh", logo=False)

MEASURED_COLOR = "#444444"
SIM_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")
PASS_COLOR = "#2e7d32"
FAIL_COLOR = "#c62828"
LIMIT_COLOR = "#000000"
FONTS = {"title": "13pt", "labels": "12pt", "xticks": "11pt", "yticks": "11pt", "legend": "11pt"}
#: signals longer than this are downsampled on the server
DOWNSAMPLE_ABOVE = 2000
DOWNSAMPLE_WIDTH = 1000


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


def _bars(rows: list[dict[str, Any]], key: str, ci_key: str | None, title: str,
          ylabel: str, signed: bool, height: int) -> tuple[hv.Overlay, hv.Bars]:
    quantities = [r["quantity"] for r in rows]
    values = [float("nan") if r.get(key) is None else float(r[key]) for r in rows]
    passed = [math.isfinite(v) and abs(v) <= 1.0 for v in values]
    status = ["pass" if p else "fail" for p in passed]
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
    top = max([1.2] + [e * 1.1 for e in extent])  # bars and their intervals stay inside
    ylim = (-top, top) if signed else (0.0, top)
    overlay = hv.Overlay(layers).opts(
        title=title, responsive=True, height=height, fontsize=FONTS, ylim=ylim,
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


def zone_coverage(counts: dict[int, int], need: int = 3, height: int = 260) -> hv.Overlay:
    """Sections per EN 14363 test zone; zones below ``need`` in red, the need as a line."""
    zones = [f"zone {z}" for z in sorted(counts)]
    vals = [counts[z] for z in sorted(counts)]
    ok = ["ok" if v >= need else "short" for v in vals]
    bars = hv.Bars({"zone": zones, "sections": vals, "ok": ok},
                   kdims=[hv.Dimension("zone", label="EN 14363 test zone")],
                   vdims=[hv.Dimension("sections", label="sections (count)"), "ok"]).opts(
        color=hv.dim("ok").categorize({"ok": PASS_COLOR, "short": FAIL_COLOR}), line_color=None)
    line = hv.HLine(need).opts(color=LIMIT_COLOR, line_dash="dashed", line_width=1.5)
    return (bars * line).opts(title=f"Sections per zone (need ≥ {need})", responsive=True,
                              height=height, fontsize=FONTS, ylim=(0, max(vals + [need]) + 1),
                              show_grid=True)


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
    "compare_plot",
    "lineage_chart",
    "nice_limits",
    "unit_label",
    "validation_bars",
    "zone_coverage",
]
