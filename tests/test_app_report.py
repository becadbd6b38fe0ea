"""Report builder (app/report.py) and the ``railval report`` verb."""

from __future__ import annotations

import hashlib
import json
import os
import re

import pytest

from railval.app.report import (
    Report,
    ReportError,
    build_report,
    diverging_color,
    svg_bars,
    svg_lines,
    where_table,
)
from railval.app.state import Backend, nice_ticks
from tests.browser_support import browser_missing_reason


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory):
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("report"))
    yield db
    db.dispose()


@pytest.fixture(scope="module")
def report(demo_db):
    return build_report(Backend(demo_db), "demo", "baseline", worst_cases=2)


def test_nice_ticks_by_hand():
    assert nice_ticks(0.0, 1250.0) == [0.0, 250.0, 500.0, 750.0, 1000.0, 1250.0]
    assert nice_ticks(-1.0, 1.5) == pytest.approx([-1.0, -0.5, 0.0, 0.5, 1.0, 1.5])


def test_svg_bars_colours_escapes_and_limit_lines():
    svg = svg_bars(["a<b>", "ok", "gone"], [1.4, -0.3, None], title="T & U", ylabel="x / limit (–)",
                   limits=(1.0, -1.0))
    assert svg.count('fill="#c62828"') == 1 and svg.count('fill="#2e7d32"') == 1  # 1.4 > 1 fails
    assert "a&lt;b&gt;" in svg and "T &amp; U" in svg and "<b>" not in svg
    assert svg.count('stroke-dasharray="6,4"') == 2


def test_svg_bars_nice_ticks_with_the_limit_and_whole_error_bars():
    """Ticks are nice numbers including the limit 1.0 (not 0.93, 1.86); an error bar
    reaching beyond the bars stays inside the plot area."""
    import re

    svg = svg_bars(["a", "b"], [0.6, 1.5], title="T", ylabel="y", limits=(1.0,),
                   intervals=[(0.2, 1.1), (0.9, 2.6)])
    ticks = [float(t) for t in re.findall(r'class="tick">([^<]+)<', svg)]
    assert 1.0 in ticks and ticks == sorted(ticks) and ticks[0] == 0.0
    assert all(abs(t * 2 - round(t * 2)) < 1e-9 for t in ticks)  # multiples of 0.5: nice
    assert ticks[-1] >= 2.6
    ys = [float(v) for v in re.findall(r'<line x1="[\d.]+" x2="[\d.]+" y1="[\d.]+" y2="([\d.]+)" stroke="#000" '
                                       r'stroke-width="1.3"', svg)]
    top_px = 30  # the plot area's top margin
    assert len(ys) == 2 and min(ys) >= top_px  # the error bar's upper end is not clipped
    # the same fixed axis as the dashboard: values within ±2 → ticks up to 2
    small = svg_bars(["a"], [0.4], title="T", ylabel="y", limits=(1.0,))
    assert [float(t) for t in re.findall(r'class="tick">([^<]+)<', small)][-1] == 2.0


def test_svg_lines_measurement_first():
    import numpy as np

    x = np.linspace(0, 100, 50)
    svg = svg_lines([("measurement", x, np.sin(x), "#555555"), ("sim", x, np.cos(x), "#1f77b4")],
                    title="t", xlabel="distance (m)", ylabel="Y (kN)", shade=(20.0, 60.0))
    assert svg.index('stroke="#555555"') < svg.index('stroke="#1f77b4"')
    assert "distance (m)" in svg and "Y (kN)" in svg and 'fill="#f2c14e"' in svg


def test_report_holds_verdict_quantities_coverage_hashes_and_versions(demo_db, report):
    html = report.html
    backend = Backend(demo_db)
    result = backend.validation("demo", "baseline")
    assert report.validated == result.validated
    assert ("VALIDATED" in html) and ("NOT VALIDATED" in html) != result.validated
    for q in result.quantities:
        assert f">{q}</td>" in html
    assert "sample standard deviation" in html and "Coverage" in html
    assert "Where it fails: quantity × test zone" in html and html.count("class='where'") == 1
    assert html.count("class='worst'") == 2
    # the evidence digest, recomputed independently from the repository's hashes
    meas, sim = backend.hashes("demo", None), backend.hashes("demo", "baseline")
    h = hashlib.sha256()
    for sid in sorted(set(meas) | set(sim)):
        for ch in sorted(set(meas.get(sid, {})) | set(sim.get(sid, {}))):
            h.update(f"{sid}\t{ch}\t{meas.get(sid, {}).get(ch, '')}\t{sim.get(sid, {}).get(ch, '')}\n".encode())
    # … then the verdict and every quantity's values (a forged verdict changes the digest)
    d = result.to_dict()
    h.update(json.dumps({k: d.get(k) for k in ("validated", "coverage", "quantities")},
                        sort_keys=True, default=str).encode())
    assert report.digest == h.hexdigest() and report.digest in html
    n_signals = sum(len(v) for v in meas.values())
    assert len(re.findall(r"<td class='l'>[0-9a-f]{64}</td>", html)) == 2 * n_signals
    assert report.versions["numpy"] in html and "railval" in report.versions
    assert "<script" not in html  # self-contained, prints as displayed


def test_where_table_colours_on_the_fixed_scale():
    import numpy as np

    from railval.app.state import PatternGrid

    assert diverging_color(0.0) == "#f7f7f7"  # the palette's white middle class
    assert diverging_color(2.0) == diverging_color(9.0) == "#67001f"  # saturated dark red
    assert diverging_color(-2.0) == "#053061" and diverging_color(-1.0) == "#4393c3"  # index 2 of 11
    grid = PatternGrid(["Y_qst", "a<b"], ["zone 1", "zone 2"], np.array([[-1.6, 0.1], [np.nan, 0.0]]))
    html = where_table(grid)
    # −1.6 / 2 = −0.8 → class round((−0.8 + 1)/2 · 10) = 1 of 0…10; |−1.6| > 0.55·2: white text
    assert "background:#2166ac;color:#ffffff'>-1.60<" in html
    assert ">+0.10<" in html and "<td>–</td>" in html and "a&lt;b" in html


def test_report_write_rejects_unknown_extension(report, tmp_path):
    with pytest.raises(ReportError, match="must be .html or .pdf"):
        report.write(tmp_path / "r.docx")


def test_report_pdf_by_headless_chromium(report, tmp_path):
    reason = browser_missing_reason()
    if reason is not None:
        if os.environ.get("RAILVAL_REQUIRE_BROWSER") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    small = Report(report.campaign, report.configuration, "<html><body><h1>railval</h1></body></html>",
                   report.validated, report.generated_at, report.versions)
    path = small.write(tmp_path / "r.pdf")
    data = path.read_bytes()
    assert data.startswith(b"%PDF-") and len(data) > 500


def test_cli_report_html_and_errors(demo_db, tmp_path, capsys):
    from railval.app.cli import main

    out = tmp_path / "baseline.html"
    assert main(["--db", demo_db.url, "report", "demo", "--config", "baseline", "--out", str(out),
                 "--worst", "0", "--json"]) == 0
    doc = capsys.readouterr().out
    assert '"configuration": "baseline"' in doc and out.read_text().startswith("<!DOCTYPE html>")
    assert main(["--db", demo_db.url, "report", "demo", "--config", "nope", "--out", str(out)]) == 2
    assert "configuration 'nope' not found" in capsys.readouterr().err
    assert main(["--db", demo_db.url, "report", "demo", "--config", "baseline", "--out", "x.txt"]) == 2


def test_worst_case_plots_show_the_quantity_of_the_row(demo_db):
    """Y/Q, Y and ΣY rows at the same place plot three different signals: Y/Q formed from
    the filtered Y and Q, Y itself, the 2 m sliding means of ΣY per wheelset; each with its
    evaluated statistic marked for both sides."""
    import types

    import pandas as pd

    from railval.app.report import _worst_case_plots
    from railval.app.state import Backend

    backend = Backend(demo_db)
    ov = backend.overview("demo")
    sid = ov.sections[0].id
    pairs = pd.DataFrame([
        {"quantity": "YQ_qst", "position": "w1L", "section": sid, "zone": 1, "D_norm": 3.0},
        {"quantity": "Y_qst", "position": "w1L", "section": sid, "zone": 1, "D_norm": 2.0},
        {"quantity": "SumY_max", "position": "ws1", "section": sid, "zone": 1, "D_norm": 1.0}])
    out = _worst_case_plots(backend, "demo", "baseline", types.SimpleNamespace(pairs=pairs), ov, 3)
    assert len(out) == 3
    labels = [re.search(r'rotate\(-90\)" text-anchor="middle">([^<]+)<', svg).group(1) for svg in out]
    assert labels == ["Y/Q w1L (–)", "Y_w1L (kN)", "ΣY ws1 (2 m mean) (kN)"]
    assert "Y/Q sample-wise" in out[0] and "ΣY ws1 = Y_w1L + Y_w1R" in out[2]
    assert "2 m sliding mean every 0.5 m" in out[2] and "0.15 % / 99.85 % values" in out[2]
    polylines = [re.findall(r'<polyline[^>]*points="([^"]+)"', svg) for svg in out]
    assert polylines[0][0] != polylines[1][0]  # not the same Y trace twice
    assert out[0].count('class="mark"') == 2 and "50 % value" in out[0]  # median, both sides
    assert out[2].count('class="mark"') == 4 and "99.85 % value" in out[2] and "0.15 % value" in out[2]
