"""Campaign overview: vehicle, sections by zone with coverage, channels, configuration tree."""

from __future__ import annotations

import html
import math

import pandas as pd
import panel as pn

from railval.app import plots
from railval.app.pages._common import PageBase, html_table, message, table_markup
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
        cov = (message("Coverage shortfalls: " + "; ".join(short), "danger") if short
               else message(f"Coverage holds: {len(ov.sections)} sections, every zone ≥ "
                            f"{MIN_SECTIONS_PER_ZONE} sections, ≥ {MIN_POSITIONS} signals per channel "
                            "kind.", "success"))
        sections_html, channels_html, n_channels = overview_tables(ov)
        zone_plot = pn.pane.Bokeh(plots.zone_coverage(ov.zone_counts(), need=MIN_SECTIONS_PER_ZONE), sizing_mode="stretch_width")
        tree = pn.pane.HTML(lineage_tree_html(ov, self.app.configuration), sizing_mode="stretch_width",
                            stylesheets=[TREE_CSS])
        desc = pn.pane.Markdown(f"### {html.escape(ov.name)}\n{no_external_images(html.escape(ov.description))}\n\n{vehicle_md}",
                                sizing_mode="stretch_width")
        self.body.objects = [
            desc, cov,
            pn.Row(pn.Column(zone_plot, sizing_mode="stretch_width"),
                   pn.Column(pn.pane.Markdown("#### Configurations and lineage"), tree,
                             sizing_mode="stretch_width"), sizing_mode="stretch_width"),
            pn.pane.Markdown("#### Sections (by zone)"), html_table(sections_html, max_height=520),
            # every channel shown (no inner scroll hiding half of them), the count in the heading
            pn.pane.Markdown(f"#### Channels ({n_channels})"), html_table(channels_html),
        ]


TREE_CSS = """
ul.rv-tree, ul.rv-tree ul { list-style: none; padding-left: 1.2em; font-size: 14px; }
ul.rv-tree li { margin: 4px 0; border-left: 2px solid #c5cbd3; padding-left: 8px; }
.rv-effects { color: #555; font-size: 13px; }
.rv-selected { background: #e3f0ff; padding: 0 4px; border-radius: 3px; }
"""
