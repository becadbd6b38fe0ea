"""Plot builders (app/plots.py): units on axes, measurement beneath, fixed scaling,
server-side downsampling, limit lines and pass/fail colours."""

from __future__ import annotations

import holoviews as hv
import numpy as np
import pytest
from bokeh.models import GlyphRenderer, Span

from app import plots
from app.state import CompareData, Trace


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
    # the axis holds the largest bar or interval end (|−1.9|) with 10 % room: ±2.09
    assert fig.y_range.start == pytest.approx(-2.09) and fig.y_range.end == pytest.approx(2.09)
    verdicts = list(mean_bars.dimension_values("verdict"))
    assert verdicts == ["pass", "fail", "fail"]  # |−1.6| > 1; a missing value is not a pass
    fig_s = hv.render(std_ov, backend="bokeh")
    assert _spans(fig_s) == [1.0]
    assert fig_s.yaxis[0].axis_label == "std / limit (–)"


def test_zone_coverage_marks_short_zones_and_lineage_chart():
    ov = plots.zone_coverage({1: 3, 2: 4, 3: 2, 4: 3})
    bars = ov.get(0)
    assert list(bars.dimension_values("ok")) == ["ok", "ok", "short", "ok"]
    fig = hv.render(plots.lineage_chart([
        {"configuration": "baseline", "max_norm": 2.4, "validated": False},
        {"configuration": "baseline+fd", "max_norm": 0.7, "validated": True}]), backend="bokeh")
    assert fig.yaxis[0].axis_label == "largest normalised error (–)"
    assert _spans(fig) == [1.0]


def test_signature_chart_of_a_candidate():
    from app.pages.diagnose import signature_chart

    cand = {"effect": "friction_damping",
            "quantities": {"az_rms": {"before": 1.4, "after": 0.3}, "Y_qst": {"before": 0.2, "after": 0.25}}}
    chart = signature_chart(cand)
    assert list(chart.dimension_values("rms")) == [1.4, 0.3, 0.2, 0.25]
    fig = hv.render(chart, backend="bokeh")
    assert fig.yaxis[0].axis_label == "residual rms (normalised, –)"
    assert "friction_damping" in fig.title.text
    bars = next(r for r in fig.renderers if hasattr(r, "glyph"))
    mapper = bars.glyph.fill_color.transform  # colours follow "when", not the bar order
    assert bars.glyph.fill_color.field == "when"
    assert dict(zip(mapper.factors, mapper.palette, strict=True)) == {
        "before": plots.FAIL_COLOR, "after (fitted)": plots.PASS_COLOR}
