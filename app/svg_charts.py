"""Charts of the HTML report as inline SVG (no JavaScript, no network), so the report prints
the way it displays: normalised-value bar charts (Polach & Böttcher 2014 Fig. 12/13) and
line charts of the worst cases. Scales and colours from :mod:`railval.app.scales`."""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

from railval.app.scales import nice_limits, nice_ticks, norm_axis_top, norm_ticks, verdict_color


def _esc(x: Any) -> str:
    return html.escape(str(x))


def svg_bars(labels: list[str], values: list[float], *, title: str, ylabel: str,
             limits: tuple[float, ...] = (1.0,), intervals: list | None = None,
             width: int = 560, height: int = 300) -> str:
    """Vertical bar chart as SVG; bars beyond ±1 red, others green; dashed limit lines."""
    ml, mr, mt, mb = 62, 12, 30, 92
    w, h = width - ml - mr, height - mt - mb
    ends = [b for c in (intervals or []) if c for b in c]
    top = norm_axis_top([*values, *ends])  # the dashboard's axis: ±2 unless exceeded
    signed = any(lim < 0 for lim in limits)
    lo = -top if signed else 0.0

    def y(v: float) -> float:
        return mt + h * (top - v) / (top - lo)

    out = [(f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="DejaVu Sans, Arial, sans-serif" font-size="12">'),
           f'<text x="{width / 2}" y="18" text-anchor="middle" font-size="14" font-weight="bold">{_esc(title)}</text>']
    for t in norm_ticks(top, signed):  # nice steps and the limit 1.0
        out.append(f'<line x1="{ml}" x2="{ml + w}" y1="{y(t):.1f}" y2="{y(t):.1f}" stroke="#e0e0e0"/>'
                   f'<text x="{ml - 6}" y="{y(t) + 4:.1f}" text-anchor="end" class="tick">{t:g}</text>')
    n = max(1, len(labels))
    bw = w / n
    for i, (lab, v) in enumerate(zip(labels, values, strict=True)):
        x0 = ml + i * bw
        if v is not None and math.isfinite(v):
            color = verdict_color(v)
            y0, y1 = sorted((y(0.0), y(v)))
            out.append(f'<rect x="{x0 + bw * 0.15:.1f}" y="{y0:.1f}" width="{bw * 0.7:.1f}" '
                       f'height="{max(y1 - y0, 0.5):.1f}" fill="{color}"><title>{_esc(lab)}: {v:.3f}</title></rect>')
            if intervals and intervals[i] and None not in intervals[i]:
                a, b = intervals[i]
                xc = x0 + bw / 2
                out.append(f'<line x1="{xc:.1f}" x2="{xc:.1f}" y1="{y(a):.1f}" y2="{y(b):.1f}" stroke="#000" '
                           f'stroke-width="1.3"/>')
        out.append(f'<text transform="translate({x0 + bw / 2:.1f},{mt + h + 8}) rotate(45)" '
                   f'font-size="11">{_esc(lab)}</text>')
    for lim in limits:
        out.append(f'<line x1="{ml}" x2="{ml + w}" y1="{y(lim):.1f}" y2="{y(lim):.1f}" stroke="#000" '
                   f'stroke-dasharray="6,4" stroke-width="1.4"/>')
    out.append(f'<line x1="{ml}" x2="{ml}" y1="{mt}" y2="{mt + h}" stroke="#000"/>'
               f'<line x1="{ml}" x2="{ml + w}" y1="{y(max(lo, 0.0)):.1f}" y2="{y(max(lo, 0.0)):.1f}" stroke="#000"/>')
    out.append(f'<text transform="translate(16,{mt + h / 2}) rotate(-90)" text-anchor="middle">{_esc(ylabel)}</text>')
    out.append("</svg>")
    return "".join(out)


def svg_lines(traces: list[tuple[str, np.ndarray, np.ndarray, str]], *, title: str, xlabel: str,
              ylabel: str, shade: tuple[float, float] | None = None, width: int = 760,
              height: int = 280, marks: list[tuple[str, float, str]] | None = None) -> str:
    """Line chart as SVG: ``traces`` = [(label, x, y, colour)], first drawn first (beneath);
    ``marks`` = [(label, y, colour)]: dashed horizontal lines across ``shade`` (the evaluated
    range) or the whole width, e.g. the evaluated statistic of each side."""
    marks = [m for m in (marks or []) if math.isfinite(m[1])]
    # with marks the legend goes below the plot (two columns), clear of the traces
    legend_rows = math.ceil((len(traces) + len(marks)) / 2) if marks else 0
    height += 18 * legend_rows + 12 if legend_rows else 0
    ml, mr, mt, mb = 70, 14, 30, 46 + (18 * legend_rows + 12 if legend_rows else 0)
    w, h = width - ml - mr, height - mt - mb
    xs = np.concatenate([t[1] for t in traces]) if traces else np.array([0.0, 1.0])
    ys = np.concatenate([t[2] for t in traces] + [np.array([m[1] for m in marks])]) if traces \
        else np.array([0.0, 1.0])
    x0, x1 = nice_limits(float(np.min(xs)), float(np.max(xs)))
    y0, y1 = nice_limits(float(np.min(ys)), float(np.max(ys)))

    def px(v):
        return ml + w * (np.asarray(v) - x0) / (x1 - x0)

    def py(v):
        return mt + h * (y1 - np.asarray(v)) / (y1 - y0)

    out = [(f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="DejaVu Sans, Arial, sans-serif" font-size="12">'),
           f'<text x="{width / 2}" y="18" text-anchor="middle" font-size="13" font-weight="bold">{_esc(title)}</text>']
    if shade is not None:
        a, b = max(shade[0], x0), min(shade[1], x1)
        out.append(f'<rect x="{px(a):.1f}" y="{mt}" width="{max(px(b) - px(a), 0):.1f}" height="{h}" '
                   f'fill="#f2c14e" fill-opacity="0.2"/>')
    for t in nice_ticks(y0, y1):
        out.append(f'<line x1="{ml}" x2="{ml + w}" y1="{py(t):.1f}" y2="{py(t):.1f}" stroke="#e6e6e6"/>'
                   f'<text x="{ml - 6}" y="{py(t) + 4:.1f}" text-anchor="end">{t:.4g}</text>')
    for t in nice_ticks(x0, x1):
        out.append(f'<text x="{px(t):.1f}" y="{mt + h + 16}" text-anchor="middle">{t:.4g}</text>')
    for i, (label, x, y, color) in enumerate(traces):
        pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px(x), py(y), strict=True))
        out.append(f'<polyline fill="none" stroke="{color}" stroke-width="{1.4 if i == 0 else 1.1}" '
                   f'points="{pts}"/>')
        if marks:
            lx, ly = ml + (i % 2) * w / 2, mt + h + 52 + 18 * (i // 2)
            out.append(f'<rect x="{lx:.1f}" y="{ly - 5}" width="14" height="3" fill="{color}"/>'
                       f'<text x="{lx + 20:.1f}" y="{ly}">{_esc(label)}</text>')
        else:
            out.append(f'<rect x="{ml + w - 200}" y="{mt + 6 + 16 * i}" width="14" height="3" fill="{color}"/>'
                       f'<text x="{ml + w - 180}" y="{mt + 11 + 16 * i}">{_esc(label)}</text>')
    for j, (label, yv, color) in enumerate(marks):
        a, b = (max(shade[0], x0), min(shade[1], x1)) if shade is not None else (x0, x1)
        out.append(f'<line class="mark" x1="{px(a):.1f}" x2="{px(b):.1f}" y1="{py(yv):.1f}" y2="{py(yv):.1f}" '
                   f'stroke="{color}" stroke-width="1.6" stroke-dasharray="7,3"><title>{_esc(label)}</title></line>')
        k = len(traces) + j
        lx, ly = ml + (k % 2) * w / 2, mt + h + 52 + 18 * (k // 2)
        out.append(f'<line x1="{lx:.1f}" x2="{lx + 14:.1f}" y1="{ly - 4}" y2="{ly - 4}" '
                   f'stroke="{color}" stroke-width="1.6" stroke-dasharray="4,2"/>'
                   f'<text x="{lx + 20:.1f}" y="{ly}">{_esc(label)}</text>')
    out.append(f'<rect x="{ml}" y="{mt}" width="{w}" height="{h}" fill="none" stroke="#000"/>')
    out.append(f'<text x="{ml + w / 2}" y="{mt + h + 32}" text-anchor="middle">{_esc(xlabel)}</text>')
    out.append(f'<text transform="translate(16,{mt + h / 2}) rotate(-90)" text-anchor="middle">{_esc(ylabel)}</text>')
    out.append("</svg>")
    return "".join(out)




def svg_paired_hbars(labels: list[str], before: list[float], after: list[float], *, title: str,
                     xlabel: str, names: tuple[str, str] = ("before", "after"),
                     colors: tuple[str, str] = ("#c0392b", "#2e7d32"), width: int = 640,
                     row: int = 30) -> str:
    """Grouped horizontal bar chart as SVG: one pair of bars (``names``: before / after) per
    label, the labels left of the bars in reading direction (never rotated, never
    overlapping: one row of ``row`` px each), the value axis below with ``xlabel`` and a
    legend above. Height = ``row`` × labels + margins, fixed for a given number of labels,
    whatever the window width. Non-finite values draw no bar (the value reads "n/a")."""
    n = len(labels)
    longest = max((len(str(lab)) for lab in labels), default=4)
    ml, mr, mt, mb = 16 + 7 * min(longest, 24), 56, 52, 48
    height = mt + mb + row * max(n, 1)
    w = width - ml - mr
    vals = [v for v in (*before, *after) if v is not None and math.isfinite(v)]
    _, hi = nice_limits(0.0, max(vals) if vals else 1.0)

    def px(v: float) -> float:
        return ml + w * max(v, 0.0) / hi

    out = [(f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
            f'font-family="DejaVu Sans, Arial, sans-serif" font-size="12">'),
           f'<title>{_esc(title)}</title>',
           f'<text x="{width / 2}" y="18" text-anchor="middle" font-size="14" font-weight="bold">{_esc(title)}</text>']
    for k, (name, color) in enumerate(zip(names, colors, strict=True)):  # the legend, above the bars
        lx = ml + k * 170
        out.append(f'<rect x="{lx}" y="30" width="14" height="10" fill="{color}"/>'
                   f'<text x="{lx + 20}" y="39" class="legend">{_esc(name)}</text>')
    for t in nice_ticks(0.0, hi):
        out.append(f'<line x1="{px(t):.1f}" x2="{px(t):.1f}" y1="{mt}" y2="{mt + row * n}" stroke="#e3e3e3"/>'
                   f'<text x="{px(t):.1f}" y="{mt + row * n + 16}" text-anchor="middle" class="tick">{t:.4g}</text>')
    bar = (row - 8) / 2
    for i, lab in enumerate(labels):
        y0 = mt + i * row
        out.append(f'<text x="{ml - 8}" y="{y0 + row / 2 + 4:.1f}" text-anchor="end" class="label">{_esc(lab)}</text>')
        for k, (vals_k, name, color) in enumerate(zip((before, after), names, colors, strict=True)):
            v = vals_k[i]
            yb = y0 + 4 + k * bar
            if v is None or not math.isfinite(v):
                out.append(f'<text x="{ml + 4}" y="{yb + bar - 2:.1f}" font-size="11">n/a</text>')
                continue
            out.append(f'<rect x="{ml}" y="{yb:.1f}" width="{max(px(v) - ml, 0.5):.1f}" height="{bar:.1f}" '
                       f'fill="{color}"><title>{_esc(lab)} {_esc(name)}: {v:.3g}</title></rect>'
                       f'<text x="{px(v) + 4:.1f}" y="{yb + bar - 2:.1f}" font-size="11" class="value">{v:.2f}</text>')
    out.append(f'<line x1="{ml}" x2="{ml}" y1="{mt}" y2="{mt + row * n}" stroke="#000"/>'
               f'<line x1="{ml}" x2="{ml + w}" y1="{mt + row * n}" y2="{mt + row * n}" stroke="#000"/>')
    out.append(f'<text x="{ml + w / 2}" y="{mt + row * n + 36}" text-anchor="middle" class="axis-label">'
               f'{_esc(xlabel)}</text>')
    out.append("</svg>")
    return "".join(out)
