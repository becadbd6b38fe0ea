"""Curve metrics (Sprague–Geers, Russell, KS, area metric, Anderson–Darling, ISO/TS 18571),
raw and synchronised, as sortable tables (docs/design.md §4). Computed per section in a background
job: the page never freezes."""

from __future__ import annotations

import html

import pandas as pd
import panel as pn

from railval.app.pages._common import PageBase, make_dispatch, message, table, toggle_group
from railval.app.state import AppState, MetricsState, unit_label
from railval.core.metrics.registry import METRICS

NOTE = ("Signals low-pass 20 Hz and resampled to a common axis (the service says where it "
        "resampled). *Synchronised*: the lag estimated by cross-correlation within a bounded "
        "window is removed first (*lag (s)*); *lag reliable* is NO when the lag lies at or within "
        "5 % of the window's bound (the true lag may lie outside; the synchronised values are "
        "doubtful). Click a column header to sort; type in a header field to filter.")


#: measured on the demo campaign (12 channels, 6983 samples at 200 Hz per section, one core,
#: CPU time; docs/metrics.md): the page states these until its own runs are stored
DEMO_COST = "measured 0.4 s CPU per section of 12 channels on the demo"
DEMO_COST_WITH_ISO = ("measured 1.5–1.7 s CPU per section of 12 channels on the demo, "
                      "73–88 % of it ISO/TS 18571")


class MetricsPage(PageBase):
    name_ = "metrics"
    watch_app = ("campaign", "configuration", "revision", "section")

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = MetricsState(app)
        self.state.param.watch(lambda *e: self._on_app_change(), ["view", "frame"])
        self.view = toggle_group(self.state.param.view, "Signals", width=380, sizing_mode="fixed")
        self.scope = toggle_group(self.state.param.scope, "Scope", width=250, sizing_mode="fixed")
        self.iso = pn.widgets.Checkbox.from_param(self.state.param.include_iso,
                                                  name="include ISO/TS 18571 rating (slow)", width=260,
                                                  margin=(8, 10))
        self.state.param.watch(lambda *e: self._on_app_change(), ["include_iso"])
        self.section = pn.widgets.Select.from_param(app.param.section, name="Section", width=160)
        self.compute_btn = pn.widgets.Button(label="Compute metrics", color="primary", width=180)
        self.compute_btn.on_click(lambda e: self.state.compute(dispatch=make_dispatch()))
        self.compute_btn.disabled = app.busy  # the page may be opened while another job runs
        app.param.watch(lambda e: setattr(self.compute_btn, "disabled", bool(e.new)), ["busy"])

    def refresh(self) -> None:
        controls = pn.FlexBox(self.section, self.scope, self.view,
                              pn.Column(pn.Spacer(height=22), self.iso),
                              pn.Column(pn.Spacer(height=30), self.compute_btn))
        df = self.state.table()
        if (df is None or self.state.computed_for != self.state.key()) and self.state.load_stored():
            return  # the stored run is shown (setting the frame redrew the page)
        if df is None or self.state.computed_for != self.state.key():
            hint = f"Press **Compute metrics** ({self._cost()}; *all sections* runs in the background " \
                   "with a progress bar)."
            shown = [message(f"Showing {self.state.computed_for}", "info")] if df is not None else []
            self.body.objects = [controls, pn.pane.Markdown(hint), *shown,
                                 *( [self._table(df)] if df is not None else [])]
            return
        self.body.objects = [controls, pn.pane.Markdown(NOTE, styles={"color": "#555"}), self._table(df),
                             *self._runs()]

    def _cost(self) -> str:
        """The cost of one section as measured: this installation's stored runs with these
        settings, else the figures measured on the demo campaign (docs/metrics.md)."""
        measured = self.state.measured_cost()
        if measured is not None:
            sec, n = measured
            return f"{sec:.1f} s per section here (median of {n} stored run{'s' if n != 1 else ''})"
        return DEMO_COST_WITH_ISO if self.state.include_iso else DEMO_COST

    def _runs(self) -> list:
        """Stored metrics runs of the configuration (newest first, at most 20)."""
        rows = self.state.runs
        if not rows:
            return []
        df = pd.DataFrame([{
            "time (UTC)": r["created_at"].replace("T", " "),
            "sections": ", ".join(r["settings"].get("sections") or ["all"]),
            "channels": len(r["settings"]["channels"]) if r["settings"].get("channels") else "all",
            "rows": r["rows"], "seconds": round(r["seconds"], 1),
            "data current": "yes" if r.get("current") else "no (signals changed)"} for r in rows[:20]])
        return [pn.pane.Markdown(f"#### Stored metrics runs of this configuration ({len(rows)})"),
                table(df, height=40 + 32 * min(len(df), 8), css_classes=["rv-metrics-runs"])]

    def _table(self, df):
        df = df.copy()
        if "unit" in df.columns:
            df["unit"] = df["unit"].map(unit_label)
        num = df.select_dtypes("number").columns
        df[num] = df[num].round(4)
        if "lag_reliable" in df.columns:
            df["lag_reliable"] = df["lag_reliable"].map({True: "yes", False: "NO (at the bound)"})
        df = df.rename(columns=metric_headers(df.columns))
        text_cols = [c for c in ("section", "channel", "unit") if c in df.columns]
        tab = table(df, height=min(560, 110 + 30 * len(df)), pagination="local", page_size=50,
                    frozen_columns=text_cols[:2],
                    layout="fit_data_fill", css_classes=["rv-metrics"],
                    header_filters={c: {"type": "input", "func": "like", "placeholder": "filter"}
                                    for c in text_cols})
        if LAG_HEADER in df.columns:
            tab.style.map(lambda v: "color: #b71c1c; font-weight: bold" if str(v).startswith("NO") else "",
                          subset=[LAG_HEADER])
        return pn.Column(tab, metric_legend([c for c in self.state.frame.columns if c in METRICS]),
                         sizing_mode="stretch_width")


LAG_HEADER = "lag reliable"
#: headers of the non-metric columns of the metrics table
OTHER_HEADERS = {"lag_s": "lag (s)", "lag_reliable": LAG_HEADER}


def metric_headers(columns) -> dict[str, str]:
    """Column → header: the metric registry's label (``railval.core.metrics.registry``),
    "(sync)" for the synchronised value shown beside the raw one, the unit where it has one
    ("signal": the unit column of the row)."""
    out = {}
    for c in columns:
        base = c.removesuffix("_sync")
        if base in METRICS:
            m = METRICS[base]
            unit = {"-": "", "signal": " [signal unit]"}.get(m.unit, f" [{m.unit}]")
            out[c] = f"{m.label}{unit}{' (sync)' if c.endswith('_sync') else ''}"
        elif c in OTHER_HEADERS:
            out[c] = OTHER_HEADERS[c]
    return out


def metric_legend(names) -> pn.pane.HTML:
    """One line per shown metric from the registry: label, what it measures, range, best value,
    source."""
    items = "".join(
        f"<li><b>{html.escape(METRICS[n].label)}</b>: {html.escape(METRICS[n].description)}; "
        f"range {html.escape(METRICS[n].range)}, best {html.escape(str(METRICS[n].best))} "
        f"({html.escape(METRICS[n].better)}) — {html.escape(METRICS[n].source)}</li>"
        for n in names)
    return pn.pane.HTML(f"<details open class='rv-metric-legend'><summary><b>What the columns mean</b>"
                        f"</summary><ul style='font-size: 13px; margin: 4px 0'>{items}</ul></details>",
                        sizing_mode="stretch_width")
