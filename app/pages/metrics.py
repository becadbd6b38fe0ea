"""Curve metrics (Sprague–Geers, Russell, KS, area metric, ISO/TS 18571), raw and
synchronised, as sortable tables (DESIGN §4)."""

from __future__ import annotations

import panel as pn

from app.pages._common import PageBase, table
from app.state import AppState, MetricsState


class MetricsPage(PageBase):
    name_ = "metrics"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = MetricsState(app)
        self.state.param.watch(lambda *e: self._on_app_change(), ["synchronised"])
        self.sync = pn.widgets.RadioButtonGroup.from_param(self.state.param.synchronised, name="Signals")

    def refresh(self) -> None:
        df = self.state.table()
        num = df.select_dtypes("number").columns
        df[num] = df[num].round(4)
        tab = table(df, height=560, pagination="local", page_size=50,
                    header_filters={c: {"type": "input", "func": "like", "placeholder": "filter"}
                                    for c in df.columns if df[c].dtype == object})
        self.body.objects = [
            pn.Row(self.sync, pn.pane.Markdown(
                "Signals resampled to a common axis; *synchronised*: the lag estimated by "
                "cross-correlation within a bounded window is removed first. Click a header to "
                "sort.", styles={"color": "#555"})),
            tab,
        ]
