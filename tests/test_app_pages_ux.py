"""Page helpers a new user meets: bounded number inputs refuse out-of-range values with a
message, tables carry human headers from the registries and a coloured verdict, the
overview lists every channel."""

from __future__ import annotations

import param

from railval.app.pages._common import bounded_input
from railval.app.pages.dashboard import summary_frame, verdict_style
from railval.app.pages.metrics import metric_headers, metric_legend


class _Settings(param.Parameterized):
    segment = param.Number(default=10.0, bounds=(1.0, 60.0))
    count = param.Integer(default=3, bounds=(2, 9))


class _App:
    def __init__(self):
        self.status: list[tuple[str, str]] = []

    def set_status(self, message: str, level: str = "info") -> None:
        self.status.append((message, level))


def test_bounded_input_refuses_values_outside_with_a_message():
    st, app = _Settings(), _App()
    w = bounded_input(st.param.segment, "PSD segment (s)", app)
    for bad in (0.0, 500.0):
        w.value = bad
        assert st.segment == 10.0 and w.value == 10.0  # kept, and the field shows it again
    assert [lvl for _, lvl in app.status] == ["warning", "warning"]
    assert app.status[1][0] == "PSD segment (s): 500 is outside the allowed range 1 … 60; kept 10"
    w.value = 20.0
    assert st.segment == 20.0 and len(app.status) == 2
    st.segment = 30.0  # a change of the state shows in the field
    assert w.value == 30.0
    n = bounded_input(st.param.count, "Scan values per parameter", app)
    n.value = 1
    assert st.count == 3 and "1 is outside the allowed range 2 … 9" in app.status[-1][0]
    n.value = 5
    assert st.count == 5 and isinstance(st.count, int)


def test_summary_frame_has_human_headers_units_and_names():
    rows = [{"quantity": "Y_qst", "n": 24, "mean": 0.5, "std": 1.2, "mean_limit": 3.333, "std_limit": 5.0,
             "mean_norm": 0.15, "std_norm": 0.24, "pass": True},
            {"quantity": "az_max", "n": 24, "mean": 0.1, "std": 0.9, "mean_limit": 0.2, "std_limit": 0.3,
             "mean_norm": 0.5, "std_norm": 3.0, "pass": False}]
    df = summary_frame(rows)
    assert list(df.columns) == ["quantity", "what it is", "unit", "pairs", "mean D_v", "std D_v (n−1)",
                                "mean limit", "std limit", "mean / limit", "std / limit", "verdict"]
    assert df.loc[0, "what it is"] == "quasi-static guiding force" and df.loc[0, "unit"] == "kN"
    assert df.loc[1, "unit"] == "m/s²" and list(df["verdict"]) == ["pass", "FAIL"]
    assert "color: #b71c1c" in verdict_style("FAIL") and "b71c1c" not in verdict_style("pass")


def test_metric_headers_and_legend_come_from_the_metric_registry():
    cols = ["section", "channel", "unit", "sg_M", "sg_M_sync", "ks_p_eff", "area", "lag_s", "lag_reliable"]
    h = metric_headers(cols)
    assert h["sg_M"] == "Sprague–Geers M" and h["sg_M_sync"] == "Sprague–Geers M (sync)"
    assert h["ks_p_eff"] == "KS p-value (n_eff)" and h["area"] == "area validation metric [signal unit]"
    assert h["lag_s"] == "lag (s)" and "section" not in h
    legend = metric_legend(["sg_M", "area"]).object
    assert "magnitude error factor" in legend and "1-Wasserstein" in legend and "ks_p" not in legend
