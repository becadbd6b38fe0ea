"""Compare: measured vs simulated series and PSD for any section × channel × configuration.

The EN-filtered and raw series share their x axis (linked zoom) and one fixed y range; the
evaluated range is shaded; long signals are downsampled on the server (``railval.app.plots``).

The figures are plain Bokeh figures built once per session (:class:`CompareView`); a switch
only replaces their data sources (docs/design.md §9: p95 ≤ 300 ms server-side for 20 000 samples).
"""

from __future__ import annotations

import html

import numpy as np
import panel as pn

from railval.app import plots
from railval.app.pages._common import PageBase, bounded_input, message, toggle_group
from railval.app.state import AppState, CompareState


def _compare_datas(state: CompareState):
    """([series CompareData], PSD CompareData, shared y limits); each source loaded once."""
    sources = state.sources()
    datas = [state.series(p, sources=sources) for p in state.processings()]
    finite = [t.y[np.isfinite(t.y)] for d in datas for t in d.traces if t.y.size]
    finite = [f for f in finite if f.size]
    ylim = plots.nice_limits(min(float(f.min()) for f in finite), max(float(f.max()) for f in finite)) \
        if finite else None
    return datas, state.psd(sources=sources), ylim


def build_compare_objects(state: CompareState):
    """The HoloViews objects of the Compare page: ([series plots], PSD plot) — for static
    use and as the baseline of ``railval bench app``; the page itself uses :class:`CompareView`."""
    datas, psd, ylim = _compare_datas(state)
    return [plots.compare_plot(d, ylim=ylim) for d in datas], plots.compare_plot(psd, height=320)


class CompareView:
    """The Compare page's figures, built once: two series figures sharing their x range
    (linked zoom) and the PSD. :meth:`update` is the switch callback timed by
    ``railval bench app``."""

    def __init__(self):
        first = plots.CompareFigure(height=330)
        self.series = [first, plots.CompareFigure(height=330, x_range=first.x_range)]
        self.psd = plots.CompareFigure(height=320, log_axes=True)

    def update(self, state: CompareState) -> int:
        """Load, filter, downsample and push the data of the current selection; returns the
        number of series figures in use (1 or 2)."""
        datas, psd, ylim = _compare_datas(state)
        for fig, d in zip(self.series, datas, strict=False):
            fig.update(d, ylim=ylim)
        self.psd.update(psd)
        return len(datas)


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
            self._configuration_choice(),
            toggle_group(self.state.param.axis, "Axis", width=180, sizing_mode="fixed",
                         margin=(2, 10, 5, 10)),
            pn.widgets.Select.from_param(self.state.param.processing, name="Processing", width=190),
            bounded_input(self.state.param.psd_segment_s, "PSD segment (s)", app, width=120,
                          css_classes=["rv-psd-segment"]),
        )
        # Bokeh figures built once; the series share one x range (linked zoom)
        self.view = CompareView()
        self.series_panes = [pn.pane.Bokeh(f.fig, sizing_mode="stretch_width") for f in self.view.series]
        self.psd_pane = pn.pane.Bokeh(self.view.psd.fig, sizing_mode="stretch_width")
        self.note = pn.pane.Markdown("", sizing_mode="stretch_width", styles={"color": "#555"})


    def _configuration_choice(self) -> pn.widgets.MultiChoice:
        """The configurations to overlay. Bokeh's MultiChoice (Choices.js) renders option
        labels as HTML, so every label is escaped here: a name is always shown as text."""
        st = self.state
        widget = pn.widgets.MultiChoice(name="Configurations", width=360, max_items=4)

        def options(*_):
            widget.options = {html.escape(n): n for n in st.param.configurations.objects}
            widget.value = [v for v in st.configurations if v in st.param.configurations.objects]

        options()
        st.param.watch(options, ["configurations"], what="objects")
        widget.link(st, value="configurations", bidirectional=True)
        return widget

    def refresh(self) -> None:
        if self.app.section is None or self.app.channel is None:
            self.body.objects = [self.controls, message("choose a section and a channel", "warning")]
            return
        n_series = self.view.update(self.state)
        self.note.object = (
            "Measurement in black beneath, simulations on top in colour-blind-safe colours; shaded: evaluated "
            "(constant-curvature) range. Zoom on one series plot zooms the other. Series are "
            "downsampled on the server (min-max LTTB, 2 000 points) and refined on zoom. PSD: evaluated range, "
            f"EN-filtered, Welch with {self.state.psd_segment_s:g} s Hann segments.")
        self.body.objects = [self.controls, pn.Column(*self.series_panes[:n_series], sizing_mode="stretch_width"),
                             self.psd_pane, self.note]
