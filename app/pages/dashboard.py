"""Validation dashboard: normalised mean/std bars (Polach & Böttcher 2014 Fig. 12/13), verdict, coverage,
drill-down of the pairs contributing most; a drill-down row opens Compare."""

from __future__ import annotations

import html
from typing import Any

import holoviews as hv
import pandas as pd
import panel as pn

from railval.app import plots
from railval.app.pages._common import PageBase, message, table, where_map
from railval.app.state import AppState, DashboardState

SUMMARY_COLUMNS = ["quantity", "n", "mean", "std", "mean_limit", "std_limit", "mean_norm", "std_norm", "pass"]


def coverage_lines(coverage: Any) -> tuple[bool, list[str]]:
    """(coverage holds, shortfall messages) from the validation result's ``coverage``."""
    if isinstance(coverage, dict):
        ok = bool(coverage.get("ok", coverage.get("holds", coverage.get("satisfied", not coverage.get("shortfalls")))))
        lines = [str(x) for x in coverage.get("shortfalls", coverage.get("messages", []))]
        return ok and not lines, lines
    if isinstance(coverage, (list, tuple)):
        return not coverage, [str(x) for x in coverage]
    return bool(coverage), []


def in_sample_note(summary: dict[str, Any]) -> str:
    """" (in-sample: … was calibrated on n of these sections)" when the verdict includes
    sections a calibration of the lineage was fitted to, else ""."""
    info = summary.get("info") or (summary.get("raw") or {}).get("info") or {}
    if not info.get("in_sample"):
        return ""
    return (f" (in-sample: {html.escape(', '.join(info.get('calibrated_in') or []))} was calibrated on "
            f"{len(info.get('fit_sections') or [])} of these sections)")


def verdict_panel(summary: dict[str, Any], config: str) -> pn.pane.Alert:
    ok_cov, lines = coverage_lines(summary["coverage"])
    failing = [r["quantity"] for r in summary["quantities"] if not r.get("pass", False)]
    if summary["validated"]:
        return pn.pane.Alert(f"<b>{html.escape(config)}: VALIDATED</b>{in_sample_note(summary)} — every quantity "
                             "within its limits and coverage holds.", alert_type="success", sizing_mode="stretch_width")
    parts = []
    if failing:
        parts.append(f"{len(failing)} of {len(summary['quantities'])} quantities exceed their limits: "
                     + ", ".join(html.escape(q) for q in failing))
    if not ok_cov:
        parts.append("coverage: " + "; ".join(html.escape(x) for x in lines))
    return pn.pane.Alert(f"<b>{html.escape(config)}: NOT VALIDATED</b>{in_sample_note(summary)} — "
                         + " — ".join(parts or ["see table"]),
                         alert_type="danger", sizing_mode="stretch_width")


def summary_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    cols = [c for c in SUMMARY_COLUMNS if c in df.columns]
    df = df[cols].copy()
    for c in ("mean", "std", "mean_limit", "std_limit", "mean_norm", "std_norm"):
        if c in df:
            df[c] = df[c].astype(float).round(4)
    if "pass" in df:
        df["pass"] = df["pass"].map({True: "pass", False: "FAIL"})
    return df


def validation_view(state: DashboardState, config: str, height: int = 320, compact: bool = False):
    """Verdict + the two bar charts of one configuration (side by side, or stacked when
    ``compact``); returns (column, summary, bar elements)."""
    summary = state.summary(config)
    mean_ov, mean_bars, std_ov, std_bars = plots.validation_bars(summary["quantities"], height=height)
    box = pn.Column if compact else pn.Row
    col = pn.Column(
        verdict_panel(summary, config),
        box(pn.pane.HoloViews(mean_ov, sizing_mode="stretch_width"),
            pn.pane.HoloViews(std_ov, sizing_mode="stretch_width"), sizing_mode="stretch_width"),
        sizing_mode="stretch_width")
    return col, summary, (mean_bars, std_bars)


class DashboardPage(PageBase):
    name_ = "dashboard"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = DashboardState(app)
        self.quantity_select = pn.widgets.Select.from_param(self.state.param.quantity, name="Drill-down quantity",
                                                            width=220)
        self.state.param.watch(lambda e: self._show_drilldown(), ["quantity"])
        self.drill_table: pn.widgets.Tabulator | None = None
        self.drill_box = pn.Column(sizing_mode="stretch_width")
        self._rows: list[dict[str, Any]] = []

    def refresh(self) -> None:
        config = self.app.configuration
        col, summary, bars = validation_view(self.state, config)
        qs = [r["quantity"] for r in summary["quantities"]]
        for el in bars:
            stream = hv.streams.Selection1D(source=el)
            stream.add_subscriber(lambda index, _qs=qs: self._bar_clicked(index, _qs))
        if self.state.quantity not in qs:
            worst = max(summary["quantities"],
                        key=lambda r: max(abs(r["mean_norm"]), abs(r["std_norm"])), default=None)
            self.state.quantity = worst["quantity"] if worst else None
        self.body.objects = [
            col,
            pn.pane.Markdown("Bars: signed mean and std of D_v = (S_v − M_v)·sign(M_v) over all (section, "
                             "position) pairs, divided by the EN 14363 limits (dashed line 1.0). "
                             "std is the sample standard deviation (n − 1). Click a bar for its "
                             "drill-down.", styles={"color": "#555"}),
            table(summary_frame(summary["quantities"]), height=40 + 32 * len(qs)),
            self._where(config),
            pn.Row(self.quantity_select, pn.pane.Markdown(
                "Pairs contributing most (largest |D_v|). **Click a row** to compare that section "
                "and channel.", margin=(28, 10, 0, 10))),
            self.drill_box,
        ]
        self._show_drilldown()

    def _where(self, config: str) -> pn.viewable.Viewable:
        """Heat map of the mean normalised D_v per quantity × EN zone: where it fails."""
        grid = self.state.where(config)
        return pn.Column(
            pn.pane.Markdown("#### Where it fails: quantity × test zone\nMean of D_v / std limit over the "
                             "sections and positions of each zone; red = simulation above the measurement, "
                             "blue = below; colour scale fixed at ±2 for every configuration.",
                             sizing_mode="stretch_width"),
            pn.Row(where_map(grid, f"{config}: mean D_v / std limit", height=380), sizing_mode="stretch_width",
                   css_classes=["rv-where"]),
            sizing_mode="stretch_width", css_classes=["rv-where-box"])

    def _bar_clicked(self, index: list[int], quantities: list[str]) -> None:
        if index:
            self.state.quantity = quantities[index[0]]

    def _show_drilldown(self) -> None:
        if self.state.quantity is None:
            self.drill_box.objects = []
            return
        try:
            self._rows = self.state.drilldown()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.drill_box.objects = [message(f"drill-down of {self.state.quantity} not available: {exc}",
                                              "danger")]
            return
        df = pd.DataFrame(self._rows)
        show = [c for c in ("section", "zone", "position", "channel", "M_v", "S_v", "D_v", "norm")
                if c in df.columns and not df[c].isna().all()]
        df = df[show].round(4) if len(df) else df
        self.drill_table = table(df, height=min(420, 40 + 32 * max(1, len(df))),
                                 selectable=False, css_classes=["rv-drilldown"])
        self.drill_table.on_click(self._row_clicked)
        self.drill_box.objects = [self.drill_table]

    def _row_clicked(self, event) -> None:
        row = event.row
        if row is None or row >= len(self._rows):
            return
        self.state.open_row(self._rows[row])
