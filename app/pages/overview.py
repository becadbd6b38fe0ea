"""Campaign overview: vehicle, sections by zone with coverage, channels, configuration tree."""

from __future__ import annotations

import html
import math

import pandas as pd
import panel as pn

from railval.app.pages._common import HTML_TABLE_CSS, PageBase, message, table_markup
from railval.app.scales import FAIL_COLOR, LIMIT_COLOR, PASS_COLOR
from railval.app.security import no_external_images
from railval.app.state import CampaignOverview, unit_label
from railval.core.coverage import MIN_POSITIONS, MIN_SECTIONS_PER_ZONE


def lineage_tree_html(ov: CampaignOverview, selected: str | None = None) -> str:
    """Nested list of configurations under their parents (names escaped)."""
    tree = ov.children()
    effects = {c.name: c.effects for c in ov.configurations}

    def node(name: str) -> str:
        eff = effects.get(name) or {}
        eff_txt = (" <span class='rv-effects'>+ " + ", ".join(html.escape(e) for e in eff) + "</span>"
                   if eff else " <span class='rv-effects'>(no effects)</span>")
        cls = " class='rv-selected'" if name == selected else ""
        kids = "".join(node(k) for k in tree.get(name, []))
        return f"<li><b{cls}>{html.escape(name)}</b>{eff_txt}" + (f"<ul>{kids}</ul>" if kids else "") + "</li>"

    roots = tree.get(None, [])
    if not roots:
        return "<p>No configurations yet.</p>"
    return ("<ul class='rv-tree'>" + "".join(node(r) for r in roots) + "</ul>")


def overview_tables(ov: CampaignOverview) -> tuple[str, str, int]:
    """The markup of the sections table (sorted by zone) and of the channels table, and the
    channel count — made once per overview and kept on it: the overview is shared read-only
    by the sessions of a process (docs/app.md, "Cheap sessions"), so is its markup."""
    cached = getattr(ov, "_tables_markup", None)
    if cached is not None:
        return cached
    sec_df = pd.DataFrame([{
        "section": s.id, "country": s.country,
        "radius (m)": "straight" if (not s.radius_m or math.isinf(s.radius_m)) else round(s.radius_m),
        "cant (mm)": s.cant_mm, "speed (km/h)": s.speed_kmh, "zone": s.zone,
        "evaluated from (m)": round(s.eval_start_m, 1), "to (m)": round(s.eval_end_m, 1),
        "evaluated length (m)": round(s.eval_end_m - s.eval_start_m, 1),
    } for s in ov.sections]).sort_values(["zone", "section"]) if ov.sections else pd.DataFrame()
    ch_df = pd.DataFrame([{"channel": c["name"], "kind": c["kind"], "position": c["position"],
                           "unit": unit_label(c["unit"])} for c in ov.channels])
    cached = (table_markup(sec_df, "rv-sections"), table_markup(ch_df, "rv-channels"), len(ch_df))
    ov._tables_markup = cached
    return cached


def zone_chart_svg(counts: dict[int, int], need: int = MIN_SECTIONS_PER_ZONE) -> str:
    """Sections per EN 14363 test zone as a static SVG bar chart (the content of the Bokeh
    figure it replaces, ``railval.app.plots.zone_coverage``): zones below ``need`` red, the
    need dashed, integer ticks (sections are counted), each bar's count as its tooltip. Plain
    markup: made once per shared overview and sent as text, no Bokeh models per session."""
    zones = sorted(counts)
    vals = [int(counts[z]) for z in zones]
    top = max(vals + [need]) + 1
    step = 1 if top <= 12 else max(1, top // 8)
    w, h, left, right, up, down = 560, 260, 56, 12, 34, 46
    pw, ph = w - left - right, h - up - down
    y = lambda v: up + ph * (1 - v / top)
    out = [(f"<svg class='rv-zone-chart' role='img' viewBox='0 0 {w} {h}' width='100%' "
           f"style='max-width:{w}px;font-family:sans-serif' xmlns='http://www.w3.org/2000/svg'>"),
           f"<title>Sections per zone (need ≥ {need})</title>",
           (f"<text x='{left}' y='20' font-size='15' font-weight='bold'>Sections per zone "
           f"(need ≥ {need})</text>")]
    for t in range(0, top + 1, step):
        out.append(f"<line x1='{left}' x2='{w - right}' y1='{y(t):.1f}' y2='{y(t):.1f}' stroke='#e5e5e5'/>"
                   f"<text x='{left - 6}' y='{y(t) + 4:.1f}' font-size='12' text-anchor='end'>{t}</text>")
    slot = pw / max(1, len(zones))
    for i, (z, v) in enumerate(zip(zones, vals, strict=True)):
        x0, colour = left + slot * (i + 0.1), PASS_COLOR if v >= need else FAIL_COLOR
        state = "ok" if v >= need else "short"
        out.append(f"<rect class='rv-zone-bar rv-{state}' x='{x0:.1f}' y='{y(v):.1f}' width='{slot * 0.8:.1f}' "
                   f"height='{y(0) - y(v):.1f}' fill='{colour}'><title>zone {z}: {v} sections "
                   f"({state})</title></rect>"
                   f"<text x='{left + slot * (i + 0.5):.1f}' y='{y(0) + 17:.1f}' font-size='12' "
                   f"text-anchor='middle'>zone {z}</text>")
    out.append(f"<line x1='{left}' x2='{w - right}' y1='{y(need):.1f}' y2='{y(need):.1f}' "
               f"stroke='{LIMIT_COLOR}' stroke-width='1.5' stroke-dasharray='6 4'/>"
               f"<line x1='{left}' x2='{left}' y1='{up}' y2='{y(0):.1f}' stroke='#444'/>"
               f"<line x1='{left}' x2='{w - right}' y1='{y(0):.1f}' y2='{y(0):.1f}' stroke='#444'/>"
               f"<text x='{left + pw / 2:.1f}' y='{h - 6}' font-size='13' text-anchor='middle'>"
               "EN 14363 test zone</text>"
               f"<text transform='translate(16 {up + ph / 2:.1f}) rotate(-90)' font-size='13' "
               "text-anchor='middle'>sections (count)</text></svg>")
    return "".join(out)


def zone_chart(ov: CampaignOverview) -> str:
    """:func:`zone_chart_svg` of ``ov``, made once and kept on the shared overview."""
    cached = getattr(ov, "_zone_chart_svg", None)
    if cached is None:
        cached = ov._zone_chart_svg = zone_chart_svg(ov.zone_counts())
    return cached


class OverviewPage(PageBase):
    name_ = "overview"

    def refresh(self) -> None:
        ov = self.app.overview
        if ov is None:
            self.body.objects = [message("campaign not loaded", "warning")]
            return
        v = ov.vehicle
        vehicle_md = (
            f"**Vehicle** {html.escape(str(v.get('name', '')))} — {html.escape(str(v.get('kind', '')))}, "
            f"secondary suspension: {'yes' if v.get('secondary_suspension') else 'no'}, "
            f"Q0 = {float(v.get('Q0_kN', float('nan'))):.1f} kN, template "
            f"`{html.escape(str(v.get('template', '')))}`"
        )
        short = ov.coverage_shortfalls()
        cov = (("danger", "Coverage shortfalls: " + "; ".join(short)) if short
               else ("success", (f"Coverage holds: {len(ov.sections)} sections, every zone ≥ "
                     f"{MIN_SECTIONS_PER_ZONE} sections, ≥ {MIN_POSITIONS} signals per channel kind.")))
        # no linkify: it took escaped characters into the links it made of bare addresses
        # (``<img src='http://…'>`` showed as a link ending in ``&#x27;&gt;``); the text now
        # shows as typed, written links ``[text](url)`` still work
        desc = pn.pane.Markdown(f"### {html.escape(ov.name)}\n{no_external_images(html.escape(ov.description))}\n\n{vehicle_md}",
                                sizing_mode="stretch_width", renderer_options={"linkify": False})
        # the rest of the page is one HTML pane (one Bokeh model instead of ten panes and
        # layouts per session); its pieces but the lineage's selection are shared markup
        self.body.objects = [desc, pn.pane.HTML(overview_markup(ov, self.app.configuration, *cov),
                                                sizing_mode="stretch_width",
                                                stylesheets=[HTML_TABLE_CSS, TREE_CSS, OVERVIEW_CSS])]


def overview_markup(ov: CampaignOverview, selected: str | None, level: str, coverage: str) -> str:
    """The overview below the description: the coverage message (``level``: success or
    danger), the zone chart beside the configurations' lineage (``selected`` marked), the
    sections table (by zone, scrolled beyond 520 px) and every channel."""
    sections_html, channels_html, n_channels = overview_tables(ov)
    return (f"<div class='rv-coverage rv-coverage-{level}'>{html.escape(coverage)}</div>"
            f"<div class='rv-overview-row'><div class='rv-overview-cell'>{zone_chart(ov)}</div>"
            "<div class='rv-overview-cell'><h4>Configurations and lineage</h4>"
            f"{lineage_tree_html(ov, selected)}</div></div>"
            f"<h4>Sections (by zone)</h4><div style='overflow-y:auto;max-height:520px'>{sections_html}</div>"
            # every channel shown (no inner scroll hiding half of them), the count in the heading
            f"<h4>Channels ({n_channels})</h4><div>{channels_html}</div>")


OVERVIEW_CSS = """
.rv-coverage { margin: 5px 0; padding: 10px 12px; border-radius: 4px; font-size: 14px; }
.rv-coverage-success { background: #d4edda; color: #155724; border: 1px solid #c3e6cb; }
.rv-coverage-danger { background: #f8d7da; color: #721c24; border: 1px solid #f5c6cb; }
.rv-overview-row { display: flex; flex-wrap: wrap; gap: 16px; }
.rv-overview-cell { flex: 1 1 380px; min-width: 0; }
h4 { margin: 14px 0 6px 0; font-size: 16px; }
"""


TREE_CSS = """
ul.rv-tree, ul.rv-tree ul { list-style: none; padding-left: 1.2em; font-size: 14px; }
ul.rv-tree li { margin: 4px 0; border-left: 2px solid #c5cbd3; padding-left: 8px; }
.rv-effects { color: #555; font-size: 13px; }
.rv-selected { background: #e3f0ff; padding: 0 4px; border-radius: 3px; }
"""
