"""Compare: measured vs simulated series and PSD for any section × channel × configuration.

The EN-filtered and raw series share their x axis (linked zoom) and one fixed y range; the
evaluated range is shaded; long signals are downsampled on the server (``app.plots``).
"""

from __future__ import annotations

import numpy as np
import panel as pn

from app import plots
from app.pages._common import PageBase, message
from app.state import AppState, CompareState


def build_compare_objects(state: CompareState):
    """The HoloViews objects of the Compare page: ([series plots], PSD plot).

    Loads each source once and shares it between the views. This is the callback timed by
    ``railval bench app`` (plot switching)."""
    sources = state.sources()
    datas = [state.series(p, sources=sources) for p in state.processings()]
    finite = [t.y[np.isfinite(t.y)] for d in datas for t in d.traces if t.y.size]
    ylim = plots.nice_limits(min(float(f.min()) for f in finite), max(float(f.max()) for f in finite)) \
        if finite else None
    series = [plots.compare_plot(d, ylim=ylim) for d in datas]
    psd = plots.compare_plot(state.psd(sources=sources), height=320)
    return series, psd


class ComparePage(PageBase):
    name_ = "compare"
    watch_app = ("campaign", "configuration", "revision", "section", "channel")

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = CompareState(app)
        self.state.param.watch(lambda *e: self._on_app_change(), ["configurations", "axis", "processing",
                                                                   "psd_segment_s"])
        self.controls = pn.FlexBox(
            pn.widgets.Select.from_param(app.param.section, name="Section", width=160),
            pn.widgets.Select.from_param(app.param.channel, name="Channel", width=160),
            pn.widgets.MultiChoice.from_param(self.state.param.configurations, name="Configurations",
                                              width=360, max_items=4),
            pn.widgets.RadioButtonGroup.from_param(self.state.param.axis, name="Axis", width=180,
                                                   sizing_mode="fixed", margin=(26, 10, 5, 10)),
            pn.widgets.Select.from_param(self.state.param.processing, name="Processing", width=190),
            pn.widgets.FloatInput.from_param(self.state.param.psd_segment_s, name="PSD segment (s)", width=120),
        )
        # one pane per series; Panel links the axes of panes sharing dimension names
        self.series_panes = [pn.pane.HoloViews(sizing_mode="stretch_width", linked_axes=True)
                             for _ in range(2)]
        self.psd_pane = pn.pane.HoloViews(sizing_mode="stretch_width")
        self.note = pn.pane.Markdown("", sizing_mode="stretch_width", styles={"color": "#555"})

    def refresh(self) -> None:
        if self.app.section is None or self.app.channel is None:
            self.body.objects = [self.controls, message("choose a section and a channel", "warning")]
            return
        series, psd = build_compare_objects(self.state)
        for pane, obj in zip(self.series_panes, series, strict=False):
            pane.object = obj
        self.psd_pane.object = psd
        self.note.object = (
            "Measurement in dark grey beneath, simulations on top; shaded: evaluated "
            "(constant-curvature) range. Zoom on one series plot zooms the other. Series are "
            "downsampled on the server (min-max LTTB) and refined on zoom. PSD: evaluated range, "
            f"EN-filtered, Welch with {self.state.psd_segment_s:g} s Hann segments.")
        self.body.objects = [self.controls, pn.Column(*self.series_panes[:len(series)], sizing_mode="stretch_width"),
                             self.psd_pane, self.note]
