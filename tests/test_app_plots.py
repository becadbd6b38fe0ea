"""Plot builders (app/plots.py): units on axes, measurement beneath, fixed scaling,
server-side downsampling, limit lines and pass/fail colours."""

from __future__ import annotations

import holoviews as hv
import numpy as np
import pytest
from bokeh.models import GlyphRenderer, Span

from railval.app import plots
from railval.app.scales import norm_axis_top, norm_ticks
from railval.app.state import CompareData, Trace


@pytest.mark.parametrize(("lo", "hi", "expected"), [
    (0.3, 9.7, (0.0, 10.0)),        # raw step 1.88 → 2
    (-13.2, 41.0, (-20.0, 60.0)),   # raw step 10.84 → 20; 41 rounds up to 60
    (0.101, 0.149, (0.1, 0.15)),    # raw step 0.0096 → 0.01
    (5.0, 5.0, (0.0, 10.0)),        # degenerate: ±|5| → [0, 10], step 2
])
def test_nice_limits_by_hand(lo, hi, expected):
    assert plots.nice_limits(lo, hi) == pytest.approx(expected)


def _data(n=200, log=False):
    x = np.linspace(0, 10, n)
    return CompareData(
        title="Y_w1L", x_label="time (s)", y_label="Y_w1L (kN)",
        traces=[Trace("sim A", x, np.sin(x) + 0.2), Trace("measurement", x, np.sin(x), measured=True)],
        eval_range=(2.0, 8.0), log_axes=log)


def _renderers(fig):
    return [r for r in fig.renderers if isinstance(r, GlyphRenderer)]


def _spans(fig):
    """Locations of the horizontal limit lines (bokeh Span annotations)."""
    return sorted(a.location for a in list(fig.renderers) + list(fig.center) if isinstance(a, Span))


def test_compare_plot_labels_units_measurement_beneath_and_shading():
    fig = hv.render(plots.compare_plot(_data()), backend="bokeh")
    assert fig.xaxis[0].axis_label == "time (s)"
    assert fig.yaxis[0].axis_label == "Y_w1L (kN)"
    lines = [r for r in _renderers(fig) if type(r.glyph).__name__ == "Line"]
    # the measurement is drawn first (beneath) although it came second
    assert lines[0].glyph.line_color == plots.MEASURED_COLOR
    assert lines[1].glyph.line_color == plots.SIM_COLORS[0]
    boxes = [a for a in fig.renderers if type(a).__name__ == "BoxAnnotation"]
    assert [(b.left, b.right) for b in boxes] == [(2.0, 8.0)]  # the evaluated range, shaded
    # fixed y range from all traces, rounded outwards: [-0.9999, 1.2], step 0.5 → [-1, 1.5]
    assert (fig.y_range.start, fig.y_range.end) == pytest.approx((-1.0, 1.5))
    assert fig.title.text_font_size == "13pt"


def test_large_signals_are_downsampled_on_the_server():
    big = _data(n=20_000)
    ov = plots.compare_plot(big)
    fig = hv.render(ov, backend="bokeh")
    lines = [r for r in _renderers(fig) if type(r.glyph).__name__ == "Line"]
    assert lines and all(len(r.data_source.data["time"]) <= 2 * plots.DOWNSAMPLE_WIDTH for r in lines)
    small = hv.render(plots.compare_plot(_data(n=500)), backend="bokeh")
    assert max(len(r.data_source.data["time"]) for r in _renderers(small)
               if type(r.glyph).__name__ == "Line") == 500


def test_downsample_xy_keeps_extremes_ends_and_window():
    x = np.linspace(0.0, 100.0, 20_001)
    y = np.sin(x)
    y[12_345] = 9.0  # a spike min-max LTTB must keep
    sx, sy = plots.downsample_xy(x, y, n_out=2000)
    assert len(sx) == 2000 and np.all(np.diff(sx) > 0)
    assert (sx[0], sx[-1]) == (0.0, 100.0) and sy.max() == 9.0
    wx, _ = plots.downsample_xy(x, y, n_out=2000, x_range=(10.0, 20.0))
    # window [10, 20] holds 2001 samples (+1 neighbour each side) → downsampled to 2000
    assert len(wx) == 2000 and wx[0] == pytest.approx(9.995) and wx[-1] == pytest.approx(20.005)
    short_x, short_y = plots.downsample_xy(x[:10], np.r_[y[:9], np.nan])
    assert len(short_x) == 9 and np.all(np.isfinite(short_y))  # NaN dropped, nothing thinned


def test_compare_figure_updates_in_place():
    fig = plots.CompareFigure()
    other = plots.CompareFigure(x_range=fig.x_range)
    assert other.fig.x_range is fig.fig.x_range  # linked zoom
    fig.update(_data(n=20_000))
    f = fig.fig
    assert f.xaxis[0].axis_label == "time (s)" and f.yaxis[0].axis_label == "Y_w1L (kN)"
    shown = [r for r in fig.renderers if r.visible]
    # measurement beneath (first renderer, black), simulation on top
    assert [r.name for r in shown] == ["measurement", "sim A"]
    assert shown[0].glyph.line_color == plots.MEASURED_COLOR
    assert shown[1].glyph.line_color == plots.SIM_COLORS[0]
    assert all(len(r.data_source.data["x"]) == plots.FIGURE_POINTS for r in shown)
    assert (fig.shade.left, fig.shade.right, fig.shade.visible) == (2.0, 8.0, True)
    assert (f.y_range.start, f.y_range.end) == pytest.approx((-1.0, 1.5))
    assert (fig.x_range.start, fig.x_range.end) == (0.0, 10.0)
    assert [i.label.value for i in fig.legend.items] == ["measurement", "sim A"]
    fig.refine(4.0, 5.0)  # zoom: the window re-sampled from the full arrays
    xs = shown[0].data_source.data["x"]
    assert xs[0] < 4.0 < xs[1] and xs[-2] < 5.0 < xs[-1] and len(xs) == 2000
    models = {id(m) for m in (f, *fig.sources, *fig.renderers)}
    only_meas = _data(n=300)
    only_meas.traces = [only_meas.traces[1]]
    only_meas.eval_range = None
    fig.update(only_meas, ylim=(-2.0, 2.0))
    assert {id(m) for m in (f, *fig.sources, *fig.renderers)} == models  # same Bokeh models
    assert [r.name for r in fig.renderers if r.visible] == ["measurement"]
    assert len(fig.sources[0].data["x"]) == 300 and len(fig.sources[1].data["x"]) == 0
    assert not fig.shade.visible and (f.y_range.start, f.y_range.end) == (-2.0, 2.0)


def test_compare_figure_psd_is_log_log_six_decades():
    fig = plots.CompareFigure(log_axes=True)
    f = np.linspace(0.1, 50.0, 500)
    d = _data(log=True)
    d.traces = [Trace("measurement", f, 3.0 / f ** 4, measured=True)]
    fig.update(d)
    assert type(fig.fig.x_scale).__name__ == "LogScale" and type(fig.fig.y_scale).__name__ == "LogScale"
    # peak 3/0.1^4 = 3e4 → top 1e5; six decades below the peak 3e-2 → bottom 1e-2
    assert (fig.fig.y_range.start, fig.fig.y_range.end) == pytest.approx((1e-2, 1e5))


def test_psd_plot_is_log_log():
    fig = hv.render(plots.compare_plot(_data(log=True)), backend="bokeh")
    assert type(fig.x_scale).__name__ == "LogScale" and type(fig.y_scale).__name__ == "LogScale"


def _rows():
    return [
        {"quantity": "Y_qst", "mean_norm": 0.4, "std_norm": 0.5, "mean_norm_ci": [0.3, 0.5],
         "std_norm_ci": [0.4, 0.6]},
        {"quantity": "ay_rms", "mean_norm": -1.6, "std_norm": 1.3, "mean_norm_ci": [-1.9, -1.3],
         "std_norm_ci": [1.1, 1.5]},
        {"quantity": "Q_max", "mean_norm": None, "std_norm": None},
    ]


def test_validation_bars_colour_by_limit_and_limit_lines():
    mean_ov, mean_bars, std_ov, _std_bars = plots.validation_bars(_rows())
    fig = hv.render(mean_ov, backend="bokeh")
    assert _spans(fig) == [-1.0, 0.0, 1.0]  # ±limit and zero
    # the fixed axis ±2 (the heat map's scale) holds the largest bar or interval end (|−1.9|)
    assert fig.y_range.start == pytest.approx(-2.0) and fig.y_range.end == pytest.approx(2.0)
    verdicts = list(mean_bars.dimension_values("verdict"))
    assert verdicts == ["pass", "fail", "fail"]  # |−1.6| > 1; a missing value is not a pass
    fig_s = hv.render(std_ov, backend="bokeh")
    assert _spans(fig_s) == [1.0]
    assert fig_s.yaxis[0].axis_label == "std / limit (–)"


def test_zone_coverage_marks_short_zones_and_lineage_chart():
    zfig = plots.zone_coverage({1: 3, 2: 4, 3: 2, 4: 3})
    data = zfig.renderers[0].data_source.data
    assert list(data["ok"]) == ["ok", "ok", "short", "ok"]
    assert list(data["color"]) == [plots.PASS_COLOR] * 2 + [plots.FAIL_COLOR, plots.PASS_COLOR]
    assert _spans(zfig) == [3]
    assert zfig.yaxis[0].axis_label == "sections (count)"
    assert zfig.yaxis[0].ticker.ticks == [0, 1, 2, 3, 4, 5]  # counts: integer ticks only
    fig = hv.render(plots.lineage_chart([
        {"configuration": "baseline", "max_norm": 2.4, "validated": False},
        {"configuration": "baseline+fd", "max_norm": 0.7, "validated": True}]), backend="bokeh")
    assert fig.yaxis[0].axis_label == "largest normalised error (–)"
    assert _spans(fig) == [1.0]


def test_signature_chart_of_a_candidate():
    """One before/after bar pair per quantity (EN order), labels horizontal in their own
    rows, the value axis labelled as normalised and dimensionless, fixed height per group."""
    import re

    from railval.app.pages.diagnose import SIGNATURE_AXIS, signature_chart

    quantities = {"az_rms": (1.4, 0.3), "Y_qst": (0.2, 0.25)}
    svg = signature_chart("friction_damping", quantities)
    labels = re.findall(r'class="label">([^<]+)<', svg)
    assert labels == ["Y_qst", "az_rms"]  # EN quantity order
    bars = re.findall(r'<title>(\S+) (before|after \(fitted\)): ([0-9.]+)</title>', svg)
    assert bars == [("Y_qst", "before", "0.2"), ("Y_qst", "after (fitted)", "0.25"),
                    ("az_rms", "before", "1.4"), ("az_rms", "after (fitted)", "0.3")]
    assert f'fill="{plots.FAIL_COLOR}"' in svg and f'fill="{plots.PASS_COLOR}"' in svg
    assert "dimensionless" in SIGNATURE_AXIS and "std limit" in SIGNATURE_AXIS and SIGNATURE_AXIS in svg
    assert "friction_damping" in svg and "rotate(" not in svg
    h2 = int(re.search(r'height="(\d+)"', svg).group(1))
    more = dict(quantities, Q_qst=(0.5, 0.4))
    h3 = int(re.search(r'height="(\d+)"', signature_chart("friction_damping", more)).group(1))
    assert h3 - h2 == 30  # one row per quantity, whatever the window


def test_pattern_grids_average_positions_per_quantity_zone_and_psd_band():
    from railval.core.diagnosis import Component, pattern_grids

    components = [Component.pair("Y_qst", 4, "w1L"), Component.pair("Y_qst", 4, "w2L"),
                  Component.pair("Y_qst", 1, "w1L"), Component.pair("az_rms", 2, "b1"),
                  Component.psd("az_cb_b1", (5, 10)), Component.psd("az_cb_b2", (5, 10)),
                  Component.psd("ay_cb_b1", (0.4, 1))]
    assert [c.label for c in components][-3:] == ["psd az_cb_b1 5-10 Hz", "psd az_cb_b2 5-10 Hz",
                                                  "psd ay_cb_b1 0.4-1 Hz"]
    values = [-1.0, -2.0, 0.5, 0.25, 1.0, 0.0, -0.5]
    q, p = pattern_grids(components, values)
    assert q.rows == ["Y_qst", "az_rms"] and q.cols == ["zone 1", "zone 2", "zone 3", "zone 4"]
    np.testing.assert_array_equal(q.values, [[0.5, np.nan, np.nan, -1.5], [np.nan, 0.25, np.nan, np.nan]])
    assert p.rows == ["ay", "az"] and p.cols == ["0.4-1 Hz", "5-10 Hz"]  # bands by frequency
    np.testing.assert_array_equal(p.values, [[-0.5, np.nan], [np.nan, 0.5]])


def test_pattern_heatmap_fixed_symmetric_scale_and_cell_values():
    from railval.core.diagnosis import PatternGrid

    grid = PatternGrid(["Y_qst", "Q_qst"], ["zone 1", "zone 2"], np.array([[0.2, -1.8], [np.nan, 0.0]]))
    fig = hv.render(plots.pattern_heatmap(grid, "now", 2.0, "D_v / limit (–)", "EN 14363 test zone"),
                    backend="bokeh")
    rect = next(r for r in fig.renderers if type(r.glyph).__name__ == "Rect")
    mapper = rect.glyph.fill_color.transform
    assert (mapper.low, mapper.high) == (-2.0, 2.0)  # the limit given, not the data's range
    z = rect.data_source.data["zvalues"]
    assert np.isnan(z).sum() == 1 and sorted(z[np.isfinite(z)]) == [-1.8, 0.0, 0.2]  # the gap stays empty
    texts = {(str(c), str(r)): (t, g.glyph.text_color) for g in fig.renderers if type(g.glyph).__name__ == "Text"
             for c, r, t in zip(g.data_source.data["col"], g.data_source.data["row"], g.data_source.data["text"],
                                strict=True)}
    assert texts[("zone 2", "Y_qst")] == ("-1.80", "#ffffff")  # deep colour: light text
    assert texts[("zone 1", "Y_qst")] == ("+0.20", "#222222")
    assert fig.xaxis[0].axis_label == "EN 14363 test zone"
    assert list(fig.y_range.factors) == ["Q_qst", "Y_qst"]  # first row on top


def test_measurement_and_simulation_colours_stay_distinct_in_greyscale():
    """Measurement and the first simulation must differ in print (greyscale) too: relative
    luminance (WCAG 2.1 definition) differs by at least 0.15, and every simulation colour is
    one of the Okabe–Ito colour-blind-safe set."""
    from railval.app.scales import MEASURED_COLOR, SIM_COLORS

    def luminance(hex_colour: str) -> float:
        rgb = [int(hex_colour[i:i + 2], 16) / 255 for i in (1, 3, 5)]
        lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
        return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]

    assert abs(luminance(SIM_COLORS[0]) - luminance(MEASURED_COLOR)) >= 0.15
    okabe_ito = {"#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00", "#CC79A7"}
    assert set(SIM_COLORS) <= okabe_ito


def test_mean_chart_axis_is_the_same_for_every_configuration():
    """Configurations compare at a glance: ±2 whatever the values within it (a configuration
    with |mean/limit| ≤ 0.6 and one reaching 1.9 get the same axis), wider only beyond it,
    then nice-rounded; the limit 1.0 is always a tick."""
    def axis(values, cis=None):
        rows = [{"quantity": f"q{i}", "mean_norm": v, "std_norm": abs(v),
                 "mean_norm_ci": (cis[i] if cis else None), "std_norm_ci": None}
                for i, v in enumerate(values)]
        mean_ov, _, std_ov, _ = plots.validation_bars(rows)
        fig = hv.render(mean_ov, backend="bokeh")
        return (fig.y_range.start, fig.y_range.end), hv.render(std_ov, backend="bokeh")
    (lo_a, hi_a), std_a = axis([0.3, -0.6])
    (lo_b, hi_b), _ = axis([1.9, -0.2])
    assert (lo_a, hi_a) == (lo_b, hi_b) == (-2.0, 2.0)
    assert (std_a.y_range.start, std_a.y_range.end) == (0.0, 2.0)
    (lo_c, hi_c), _ = axis([0.5, 0.2], cis=[(0.1, 2.7), (0.0, 0.4)])  # an interval beyond ±2
    assert (lo_c, hi_c) == (-3.0, 3.0)  # 2.7 · 1.05 = 2.835 → next nice value 3
    assert norm_axis_top([4.3]) == 5.0 and norm_axis_top([9.8]) == 12.5  # 10.29 → step 2.5
    assert 1.0 in norm_ticks(12.5, False) and -1.0 in norm_ticks(12.5, True)
    assert norm_ticks(2.0, True) == [-2.0, -1.0, 0.0, 1.0, 2.0]
