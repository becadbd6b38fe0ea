"""UI state of the web app without a browser (app/state/).

The campaign is the demo folder of ``tests/factories`` imported into a fresh SQLite
database once per module (12 sections, 4 zones, 2 configurations).
"""

from __future__ import annotations

import itertools
import threading

import numpy as np
import pytest
import scipy.signal

from railval.app.state import (
    MEASURED,
    AppState,
    Backend,
    CampaignOverview,
    CompareState,
    ConfigInfo,
    DashboardState,
    DiagnoseState,
)
from railval.core.quantities import channel_for
from railval.core.types import SectionInfo


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory):
    from tests.browser_support import demo_database

    db = demo_database(tmp_path_factory.mktemp("appstate"))
    yield db
    db.dispose()


@pytest.fixture
def app(demo_db):
    return AppState(Backend(demo_db))


def test_app_state_selects_first_campaign_and_its_lists(app):
    assert app.campaign == "demo"
    assert app.param.configuration.objects[0] == "baseline"
    assert app.configuration == "baseline"
    assert len(app.param.section.objects) == 12
    assert app.section == app.param.section.objects[0]
    assert "Y_w1L" in app.param.channel.objects
    ov = app.overview
    assert sum(ov.zone_counts().values()) == 12
    assert ov.children()[None] == ["baseline"]  # the root of the lineage tree


def test_open_compare_switches_page_and_selection(app):
    target_section = app.param.section.objects[5]
    app.open_compare(target_section, "ay_cb_b2")
    assert (app.page, app.section, app.channel) == ("compare", target_section, "ay_cb_b2")


def _overview(zones: list[int], kinds: dict[str, int]) -> CampaignOverview:
    sections = [SectionInfo(f"S{i}", 500.0, 0.0, 80.0, z, 0.0, 100.0) for i, z in enumerate(zones)]
    channels = [{"name": f"{k}_{i}", "kind": k, "position": str(i), "unit": ""}
                for k, n in kinds.items() for i in range(n)]
    return CampaignOverview("c", "", {}, sections, channels,
                            [ConfigInfo("a", None), ConfigInfo("b", "a"), ConfigInfo("c", "a")])


def test_coverage_shortfalls_are_precise():
    # 11 sections, zone 3 with 2 sections and az_cb with one signal: three precise messages
    ov = _overview([1, 1, 1, 2, 2, 2, 3, 3, 4, 4, 4], {"Y": 8, "Q": 8, "ay_cb": 2, "az_cb": 1})
    assert ov.coverage_shortfalls() == [
        "11 sections, needs 12",
        "zone 3 has 2 sections, needs 3",
        "channel kind az_cb has 1 signal, needs 2",
    ]
    full = _overview([1, 2, 3, 4] * 3, {"Y": 2, "Q": 2, "ay_cb": 2, "az_cb": 2})
    assert full.coverage_shortfalls() == []
    assert full.children() == {None: ["a"], "a": ["b", "c"]}


@pytest.mark.parametrize(("quantity", "position", "expected"), [
    ("Y_qst", "w2R", "Y_w2R"),
    ("YQ_max", "w1L", "Y_w1L"),      # Y/Q is formed from Y and Q: Y is shown
    ("SumY_max", "ws1", "Y_w1L"),    # ΣY of wheelset 1: its left-wheel Y
    ("ay_rms", "b2", "ay_cb_b2"),
    ("az_max", "b1", "az_cb_b1"),
])
def test_channel_for_quantity_position_uses_the_registry(quantity, position, expected):
    chans = [f"{k}_w{n}{s}" for k in ("Y", "Q") for n in (1, 2) for s in "LR"] + \
            [f"{k}_{p}" for k in ("ay_cb", "az_cb") for p in ("b1", "b2")]
    assert channel_for(quantity, position, chans) == expected


def test_compare_series_measured_first_eval_range_and_filter(app):
    cmp = CompareState(app)
    app.section = app.param.section.objects[0]
    app.channel = "Y_w1L"
    cmp.configurations = ["baseline", "variant1"]
    sources = cmp.sources()
    assert [label for label, _ in sources] == [MEASURED, "baseline", "variant1"]
    raw = cmp.series("raw", sources=sources)
    en = cmp.series("EN-filtered", sources=sources)
    assert raw.traces[0].measured and not raw.traces[1].measured
    assert raw.x_label == "time (s)" and raw.y_label == "Y_w1L (kN)"
    # evaluated range on the time axis: the times at which the measured distance crosses it
    sec = app.overview.sections[0]
    ss = sources[0][1]
    t_start = np.interp(sec.eval_start_m, ss.distance_m, ss.time_s)
    assert raw.eval_range[0] == pytest.approx(t_start)
    # EN-filtered Y: scipy's zero-phase Butterworth low-pass 20 Hz, order 4 (independent path)
    sos = scipy.signal.butter(4, 20.0, fs=ss.fs, output="sos")
    expect = scipy.signal.sosfiltfilt(sos, ss.channels["Y_w1L"])
    np.testing.assert_allclose(en.traces[0].y, expect, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(raw.traces[0].y, ss.channels["Y_w1L"])
    cmp.axis = "distance"
    dist = cmp.series("raw", sources=sources)
    assert dist.x_label == "distance (m)"
    assert dist.eval_range == (sec.eval_start_m, sec.eval_end_m)


def test_compare_caches_sources_and_filtered_arrays_per_selection(app):
    cmp = CompareState(app)
    app.section = app.param.section.objects[0]
    app.channel = "Y_w1L"
    first = cmp.sources()
    again = cmp.sources()
    assert all(a[1] is b[1] for a, b in zip(first, again, strict=True))  # cached SignalSets
    en1 = cmp.series("EN-filtered", sources=first).traces[0].y
    assert cmp.series("EN-filtered", sources=again).traces[0].y is en1  # cached filter output
    app.channel = "Q_w1L"  # another channel: other signals, not the cached ones
    other = cmp.sources()
    assert other[0][1] is not first[0][1] and "Q_w1L" in other[0][1].channels
    app.channel = "Y_w1L"
    app.revision += 1  # the database changed: reload
    assert cmp.sources()[0][1] is not first[0][1]
    np.testing.assert_array_equal(cmp.series("EN-filtered").traces[0].y, en1)


def test_compare_psd_is_welch_of_the_evaluated_part(app):
    cmp = CompareState(app)
    app.channel = "az_cb_b1"
    sources = cmp.sources()
    psd = cmp.psd(sources=sources)
    assert psd.log_axes and psd.x_label == "frequency (Hz)"
    assert psd.y_label == "PSD (m/s²)²/Hz"
    ss = sources[0][1]
    sec = app.overview.sections[0]
    mask = (ss.distance_m >= sec.eval_start_m) & (ss.distance_m <= sec.eval_end_m)
    sos = scipy.signal.butter(4, [0.4, 10.0], btype="bandpass", fs=ss.fs, output="sos")
    y = scipy.signal.sosfiltfilt(sos, ss.channels["az_cb_b1"])[mask]
    f, p = scipy.signal.welch(y, fs=ss.fs, nperseg=round(10 * ss.fs), detrend="linear")
    np.testing.assert_allclose(psd.traces[0].x, f[1:])
    np.testing.assert_allclose(psd.traces[0].y, np.maximum(p[1:], 1e-30), rtol=1e-6)


def test_run_job_success_progress_and_result(app):
    seen = []
    app.run_job("job", lambda progress: (progress(0.5, "half"), 42)[1],
                on_done=seen.append, background=False)
    assert seen == [42]
    assert (app.busy, app.progress, app.status_level) == (False, 1.0, "success")


def test_run_job_error_lands_in_status(app):
    from railval.core.errors import InvalidParameter

    def fail(progress):
        raise InvalidParameter("bad parameter k = -1, must be > 0")
    app.run_job("calibration", fail, background=False)
    assert app.status_level == "error"
    assert "calibration failed: bad parameter k = -1, must be > 0" == app.status
    assert app.busy is False

    # an error that is not railval's own shows only its kind (details: server log)
    def crash(progress):
        raise ValueError("internal detail /srv/x.py SELECT secret FROM t")
    app.run_job("calibration", crash, background=False)
    assert app.status == ("calibration failed: internal error (ValueError); the details are "
                          "in the server log")


def test_run_job_in_thread_refuses_a_second_job(app):
    gate = threading.Event()
    t = app.run_job("long", lambda progress: gate.wait(5))
    assert app.busy
    assert app.run_job("other", lambda progress: 1) is None
    assert app.status_level == "warning" and "another job" in app.status
    gate.set()
    t.join(5)
    assert not app.busy and app.status_level == "success"


def test_dispatch_receives_every_state_change(app):
    calls = []

    def dispatch(fn):
        calls.append(fn)
        fn()
    app.run_job("job", lambda progress: progress(0.25, "quarter"), dispatch=dispatch, background=False)
    assert len(calls) == 2  # one progress update, one completion


def test_dashboard_summary_and_drilldown(app):
    dash = DashboardState(app)
    summary = dash.summary()
    qs = [r["quantity"] for r in summary.quantities]
    assert len(qs) == 12 and "Y_qst" in qs
    rows = dash.drilldown("Y_max")
    assert rows and all(abs(a["D_v"]) >= abs(b["D_v"]) for a, b in itertools.pairwise(rows))
    limit = next(r["std_limit"] for r in summary.quantities if r["quantity"] == "Y_max")
    assert rows[0]["norm"] == pytest.approx(rows[0]["D_v"] / limit)
    # D_v = (S_v − M_v)·sign(M_v) (Polach & Böttcher 2014 eq. 4)
    r = rows[0]
    assert r["D_v"] == pytest.approx((r["S_v"] - r["M_v"]) * np.sign(r["M_v"]))
    dash.open_row(r)
    assert app.page == "compare" and app.section == r["section"] and app.channel.startswith("Y_")


def test_dashboard_where_grid_is_the_mean_normalised_dv_per_quantity_and_zone(app):
    dash = DashboardState(app)
    dash.top_n = 200
    grid = dash.where()
    assert grid.cols == ["zone 1", "zone 2", "zone 3", "zone 4"] and grid.rows[0] == "Y_qst"
    assert len(grid.rows) == 12 and np.isfinite(grid.values).all()  # 12 quantities, every zone
    for q in ("Y_qst", "az_max"):  # by hand from the drill-down rows (D_v / std limit)
        rows = dash.drilldown(q)
        for j, zone in enumerate((1, 2, 3, 4)):
            norms = [r["norm"] for r in rows if r["zone"] == zone]
            assert grid.values[grid.rows.index(q), j] == pytest.approx(np.mean(norms))


def test_diagnose_suggested_name_is_unique(app):
    diag = DiagnoseState(app)
    diag.param.effect.objects = ["friction_damping"]
    diag.effect = "friction_damping"
    assert diag.suggested_name() == "baseline+friction_damping"
    app.param.configuration.objects = ["baseline", "variant1", "baseline+friction_damping"]
    assert diag.suggested_name() == "baseline+friction_damping-2"


def test_diagnose_new_name_follows_the_effect_until_typed(app):
    """The new configuration's name names the effect that is added: it follows the choice
    until the user types a name, and a name the user did not type is never stored with
    another effect."""
    diag = DiagnoseState(app)
    diag.param.effect.objects = ["friction_damping", "parasitic_yaw_stiffness"]
    diag.effect = "friction_damping"
    assert diag.new_name == "baseline+friction_damping" and not diag.name_edited
    diag.effect = "parasitic_yaw_stiffness"
    assert diag.new_name == "baseline+parasitic_yaw_stiffness"
    diag.new_name = "yaw-fit"  # typed by the user: kept when the effect changes
    assert diag.name_edited
    diag.effect = "friction_damping"
    assert diag.new_name == "yaw-fit"
    diag.new_name = ""  # cleared: follows the effect again
    diag.effect = "parasitic_yaw_stiffness"
    assert diag.new_name == "baseline+parasitic_yaw_stiffness"


def test_pages_are_built_on_first_view_and_refresh_when_shown(demo_db):
    """Only the page shown is built at session start (first-page speed); another page is
    built when opened, and a hidden page refreshes when shown after a selection changed."""
    from railval.app.main import build_app

    template = build_app(demo_db)
    app, pages = template.railval_state, template.railval_pages
    assert pages.built() == ["overview"]
    main = template.main[0]

    def shown() -> str:  # the page header of what the main area holds
        (view,) = main.objects
        return view.objects[0].object

    assert shown() == "## Campaign overview"
    overview_html = pages["overview"].body.objects  # sections table already filled
    assert any("rv-sections" in str(getattr(o, "object", "")) for o in overview_html)

    app.page = "dashboard"
    assert pages.built() == ["overview", "dashboard"]
    assert shown() == "## Validation dashboard"
    assert pages["dashboard"].state.quantity is not None  # refreshed before being shown

    # a change while the overview is hidden marks it stale; it refreshes on its next view
    overview = pages["overview"]
    other = app.param.configuration.objects[1]
    app.configuration = other
    assert overview._stale
    app.page = "overview"
    assert not overview._stale
    tree = overview.body.objects[1].object  # the pane below the description: lineage beside the zone chart
    assert f"<b class='rv-selected'>{other}</b>" in tree
    assert set(pages) == {"overview", "compare", "dashboard", "metrics", "diagnose", "report",
                          "signoff", "audit", "import"}
    assert pages.built() == ["overview", "dashboard"]


def test_dashboard_where_map_keeps_its_own_row_order_beside_the_bar_charts(demo_db):
    """The heat map's quantity axis is not linked to the bar charts' quantity axis (a shared
    FactorRange would turn the rows upside down): Y_qst on top, az_max at the bottom."""
    from bokeh.document import Document
    from bokeh.models import Plot

    from railval.app.main import build_app

    doc = Document()
    build_app(demo_db, page="dashboard").server_doc(doc)
    (heat,) = [m for m in doc.models if isinstance(m, Plot) and "mean D_v" in (m.title.text or "")]
    factors = [str(f) for f in heat.y_range.factors]  # Bokeh lists categories bottom → top
    assert factors[-1] == "Y_qst" and factors[0] == "az_max"


def test_compare_shows_derived_signals_yq_and_sumy(app):
    """Y/Q and ΣY are entries of the channel selector; EN-filtered they are formed from the
    low-pass filtered components exactly as the EN evaluation forms them."""
    from railval.core.en14363 import quantity_trace

    objs = app.param.channel.objects
    assert {"YQ_w1L", "SumY_ws1"} <= set(objs) and objs.index("YQ_w1L") >= len(app.overview.channels)
    cmp = CompareState(app)
    cmp.axis = "distance"
    sec = next(s for s in app.overview.sections if s.id == app.section)
    meas = app.backend.signals(app.campaign, None, app.section, ["Y_w1L", "Q_w1L", "Y_w1R"])
    for ch, quantity, pos in (("YQ_w1L", "YQ_qst", "w1L"), ("SumY_ws1", "SumY_qst", "ws1")):
        app.channel = ch
        data = cmp.series("EN-filtered")
        trace = next(t for t in data.traces if t.measured)
        expected = quantity_trace(meas, sec, quantity, pos)
        np.testing.assert_allclose(trace.y, expected.values, rtol=1e-10, atol=1e-12)
        assert data.y_label.startswith(ch)
    raw = cmp.series("raw")
    m = next(t for t in raw.traces if t.measured)
    np.testing.assert_allclose(m.y, np.asarray(meas.channels["Y_w1L"]) + np.asarray(meas.channels["Y_w1R"]))
    assert raw.y_label == "SumY_ws1 (kN)"
    # a Y/Q drill-down row opens the derived signal it is about
    DashboardState(app).open_row({"quantity": "YQ_max", "position": "w1L", "section": app.section})
    assert app.page == "compare" and app.channel == "YQ_w1L"


def test_a_page_error_is_logged_and_shown_as_a_plain_message(app, caplog):
    """Pages show errors one way (railval.app.security.plain_message): the traceback goes
    to the server log, the page and the status area get a plain sentence without the
    error's text; railval's own errors keep their message (it names the input at fault)."""
    from railval.app.pages._common import PageBase
    from railval.core.errors import NotFound

    class Broken(PageBase):
        name_ = "dashboard"
        error: Exception = ValueError("secret internals at /srv/x.py")

        def refresh(self):
            raise self.error

    page = Broken(app)
    with caplog.at_level("ERROR", logger="railval.app"):
        page.safe_refresh()
    shown = page.body.objects[0].object
    assert "internal error (ValueError)" in shown and "secret internals" not in shown
    assert app.status_level == "error" and "secret internals" not in app.status
    assert any(r.exc_info and "secret internals" in str(r.exc_info[1]) for r in caplog.records)
    Broken.error = NotFound("configuration 'x' not found in campaign 'demo'")
    page.safe_refresh()
    assert "is not available: configuration &#x27;x&#x27; not found in campaign" in page.body.objects[0].object
