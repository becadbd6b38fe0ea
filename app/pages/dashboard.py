"""Validation dashboard: normalised mean/std bars (Polach & Böttcher 2014 Fig. 12/13), verdict, coverage,
drill-down of the pairs contributing most; a drill-down row opens Compare."""

from __future__ import annotations

import html
from typing import Any

import holoviews as hv
import pandas as pd
import panel as pn
from bokeh.models.widgets.tables import NumberFormatter

from railval.app import plots
from railval.app.pages._common import PageBase, message, table, where_map
from railval.app.pages.signoff import signoff_banner
from railval.app.security import plain_message
from railval.app.state import AppState, DashboardState, unit_label
from railval.app.views import ValidationView
from railval.core.quantities import QUANTITIES

SUMMARY_COLUMNS = ["quantity", "name", "unit", "n", "mean", "std", "mean_limit", "std_limit", "mean_norm",
                   "std_norm", "pass"]


def in_sample_note(view: ValidationView) -> str:
    """" (in-sample: … was calibrated on n of these sections)" when the verdict includes
    sections a fit of the lineage used (a calibration, or a diagnosis whose fitted parameters
    the configuration took), else ""."""
    ins = view.in_sample
    return "" if ins is None else f" (in-sample: {html.escape(ins.note())})"


def held_out_line(view: ValidationView) -> str:
    """For an in-sample verdict, a second line of the verdict box: the held-out check, or why
    none is possible and how to get one (``calibration_provenance``'s ``held_out_check``)."""
    ins = view.in_sample
    if ins is None or not ins.held_out_check:
        return ""
    text = ins.held_out_check[:1].upper() + ins.held_out_check[1:]
    return f"<br><span class='rv-held-out-check'>{html.escape(text)}.</span>"


def verdict_panel(view: ValidationView, config: str) -> pn.pane.Alert:
    """The verdict with the failing quantities, the coverage shortfalls, which quantities
    are definition-sensitive and, when in-sample, the held-out check."""
    sensitive = view.sensitive_quantities
    note = ("" if not sensitive else " — definition-sensitive: " + ", ".join(html.escape(q) for q in sensitive)
            + (" (another reading gives the opposite verdict)" if view.verdict_sensitive else ""))
    if view.validated:
        return pn.pane.Alert(f"<b>{html.escape(config)}: VALIDATED</b>{in_sample_note(view)} — every quantity "
                             "within its limits and coverage holds." + note + held_out_line(view),
                             alert_type="warning" if view.in_sample is not None else "success",
                             sizing_mode="stretch_width", css_classes=["rv-verdict"])
    parts = []
    failing = view.failing
    if failing:
        parts.append(f"{len(failing)} of {len(view.quantities)} quantities exceed their limits: "
                     + ", ".join(html.escape(q) for q in failing))
    if not view.coverage.ok:
        parts.append("coverage: " + "; ".join(html.escape(x) for x in view.coverage.shortfalls))
    return pn.pane.Alert(f"<b>{html.escape(config)}: NOT VALIDATED</b>{in_sample_note(view)} — "
                         + " — ".join(parts or ["see table"]) + note + held_out_line(view),
                         alert_type="danger", sizing_mode="stretch_width", css_classes=["rv-verdict"])


#: the summary table's headers as a reader sees them (field → header)
SUMMARY_HEADERS = {"quantity": "quantity", "name": "what it is", "unit": "unit", "n": "pairs",
                   "mean": "mean D_v", "std": "std D_v (n−1)", "mean_limit": "mean limit",
                   "std_limit": "std limit", "mean_norm": "mean / limit", "std_norm": "std / limit",
                   "pass": "verdict"}


def summary_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The quantity table with human headers: the quantity's name and unit from the quantity
    registry (``railval.core.quantities.QUANTITIES``), D_v statistics and limits in that unit,
    normalised values dimensionless, verdict ``pass``/``FAIL``."""
    df = pd.DataFrame(rows)
    if "quantity" in df:
        df["name"] = [QUANTITIES[q].name if q in QUANTITIES else "" for q in df["quantity"]]
        df["unit"] = [unit_label(QUANTITIES[q].unit).replace("-", "–") if q in QUANTITIES else ""
                      for q in df["quantity"]]
    cols = [c for c in SUMMARY_COLUMNS if c in df.columns]
    df = df[cols].copy()
    for c in ("mean", "std", "mean_limit", "std_limit", "mean_norm", "std_norm"):
        if c in df:
            df[c] = df[c].astype(float).round(4)
    if "pass" in df:
        df["pass"] = df["pass"].map({True: "pass", False: "FAIL"})
    return df.rename(columns=SUMMARY_HEADERS)


WRAP_HEADERS_CSS = ".tabulator-col-title { white-space: normal !important; }"


def verdict_style(value: Any) -> str:
    """Cell style of a verdict: FAIL red and bold, pass green."""
    if value == "FAIL":
        return "color: #b71c1c; background-color: #fdecea; font-weight: bold"
    if value == "pass":
        return "color: #1b5e20"
    return ""


#: numbers for people: at most four decimals, trailing zeros dropped (0.1025, not
#: 0.10250000000000001), right-aligned
NUMBER_FORMAT = "0.[0000]"


def summary_table(rows: list[dict[str, Any]]) -> pn.widgets.Tabulator:
    """The quantity table: human headers, FAIL coloured, columns fitted to their content,
    every row shown (no height: the table grows with its rows, no scrolling inside it),
    numbers formatted for people (:data:`NUMBER_FORMAT`)."""
    df = summary_frame(rows)
    # every column inside the page width: headers wrap, the name column takes the rest
    widths = {c: 72 for c in df.columns}  # 892 px in all: fits the main area at 1280 px
    widths.update({"quantity": 90, "what it is": 154, "unit": 60, "pairs": 80, "verdict": 80})
    numeric = [c for c in df.columns if c not in ("quantity", "what it is", "unit", "verdict", "pairs")]
    formatters: dict[str, Any] = {c: NumberFormatter(format=NUMBER_FORMAT, text_align="right") for c in numeric}
    formatters["what it is"] = {"type": "textarea"}  # long names wrap, never cut
    tab = table(df, layout="fit_columns", widths=widths, css_classes=["rv-summary"], formatters=formatters,
                stylesheets=[":host {font-size: 13px;}", WRAP_HEADERS_CSS])
    if "verdict" in df:
        tab.style.map(verdict_style, subset=["verdict"])
    return tab


def _range(r: Any) -> str:
    return "" if not r else f"{r[0]:+.3f} … {r[1]:+.3f}"


def definition_block(view: ValidationView) -> pn.Column:
    """Which verdicts rest on an open choice of the definitions (docs/validation.md)."""
    rows = view.definition_rows()
    sensitive = [r["quantity"] for r in rows if r["definition_sensitive"]]
    if not view.definitions_available:
        head = pn.pane.Markdown("#### Definition sensitivity\nNot available for this result.")
        return pn.Column(head, css_classes=["rv-definitions"], sizing_mode="stretch_width")
    if sensitive:
        alert = pn.pane.Alert(
            "<b>definition-sensitive</b>: " + ", ".join(html.escape(q) for q in sensitive)
            + " — pass/fail changes under another reading of the percentile or sliding-mean "
            "definition" + ("; so does the verdict" if view.verdict_sensitive else ""),
            alert_type="warning", sizing_mode="stretch_width")
    else:
        alert = pn.pane.Alert("No verdict changes under the alternative readings of the percentile "
                              "and sliding-mean definitions.", alert_type="light",
                              sizing_mode="stretch_width")
    df = pd.DataFrame([{
        "quantity": r["quantity"], "verdict": r["verdict"],
        "definition-sensitive": "yes" if r["definition_sensitive"] else "no",
        "flipped by": r["flipped by"],
        "mean/limit": None if r["mean/limit"] is None else round(r["mean/limit"], 4),
        "mean/limit other readings": _range(r["mean/limit other readings"]),
        "std/limit other readings": _range(r["std/limit other readings"]),
        "readings": r["readings"]} for r in rows])
    return pn.Column(
        pn.pane.Markdown(
            "#### Definition sensitivity\nChosen reading: percentiles by the inverted CDF, sliding-mean "
            "grid from the evaluated range's start, distance-weighted 2 m mean. The alternatives "
            "(linear percentiles; grid from the first evaluated sample; sample means over closed or "
            "half-open windows) are evaluated on the same filtered signals (docs/validation.md).",
            sizing_mode="stretch_width"),
        alert, table(df, height=40 + 32 * max(1, len(df))) if len(df) else pn.Spacer(height=0),
        css_classes=["rv-definitions"], sizing_mode="stretch_width")


def supplementary_block(view: ValidationView) -> pn.Column:
    """Bogie-frame and PSD-band quantities next to the verdict (they do not change it)."""
    rows = view.supplementary_rows()
    head = pn.pane.Markdown(
        "#### Supplementary results (do not change the verdict)\nBogie-frame accelerations "
        "(band-pass 0.4–10 Hz, rms and max of the 0.15 %/99.85 % values, EN 14363) and band rms "
        "of the Welch PSD of car body and bogie-frame accelerations in 0.4–1, 1–2, 2–5, 5–10 Hz; "
        "D_v statistics as for the verdict, rel = value / mean |M_v|, log2 S/M = mean log₂ ratio "
        "(Polach & Böttcher 2014 §3.1 compared such quantities; no limits exist for them).",
        sizing_mode="stretch_width")
    if not rows:
        return pn.Column(head, pn.pane.Markdown("No supplementary channels in this campaign."),
                         css_classes=["rv-supplementary"], sizing_mode="stretch_width")
    df = pd.DataFrame([{
        "quantity": r["quantity"], "group": r["group"], "unit": r["unit"], "n": r["n"],
        "mean D_v": r["mean"], "std D_v": r["std"], "mean rel": r["mean_rel"],
        "std rel": r["std_rel"], "log2 S/M": r["log2_ratio_mean"]} for r in rows])
    for c in ("mean D_v", "std D_v", "mean rel", "std rel", "log2 S/M"):
        df[c] = df[c].astype(float).round(4)
    return pn.Column(head, table(df, height=min(560, 40 + 32 * len(df))),
                     css_classes=["rv-supplementary"], sizing_mode="stretch_width")


def validation_view(state: DashboardState, config: str, height: int = 320, compact: bool = False):
    """Verdict + the two bar charts of one configuration (side by side, or stacked when
    ``compact``); returns (column, view model, bar elements)."""
    summary = state.summary(config)
    mean_ov, mean_bars, std_ov, std_bars = plots.validation_bars(summary.quantities, height=height)
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
        qs = [r["quantity"] for r in summary.quantities]
        for el in bars:
            stream = hv.streams.Selection1D(source=el)
            stream.add_subscriber(lambda index, _qs=qs: self._bar_clicked(index, _qs))
        if self.state.quantity not in qs:
            worst = max(summary.quantities,
                        key=lambda r: max(abs(r["mean_norm"]), abs(r["std_norm"])), default=None)
            self.state.quantity = worst["quantity"] if worst else None
        self.body.objects = [
            signoff_banner(self.app, config),
            col,
            pn.pane.Markdown("Bars: signed mean and std of D_v = (S_v − M_v)·sign(M_v) over all (section, "
                             "position) pairs, divided by the EN 14363 limits (dashed line 1.0). "
                             "std is the sample standard deviation (n − 1). Click a bar for its "
                             "drill-down.", styles={"color": "#555"}),
            summary_table(summary.quantities),
            definition_block(summary),
            self._where(config),
            supplementary_block(summary),
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
            self.drill_box.objects = [message(f"drill-down of {self.state.quantity} not available: "
                                         f"{plain_message(exc, 'drill-down')}",
                                              "danger")]
            return
        df = pd.DataFrame(self._rows)
        show = [c for c in ("section", "zone", "position", "channel", "M_v", "S_v", "D_v", "norm")
                if c in df.columns and not df[c].isna().all()]
        df = df[show].round(4) if len(df) else df
        self.drill_table = table(df, height=min(420, 40 + 32 * max(1, len(df))), layout="fit_data_fill",
                                 selectable=False, css_classes=["rv-drilldown"])
        self.drill_table.on_click(self._row_clicked)
        self.drill_box.objects = [self.drill_table]

    def _row_clicked(self, event) -> None:
        row = event.row
        if row is None or row >= len(self._rows):
            return
        self.state.open_row(self._rows[row])
