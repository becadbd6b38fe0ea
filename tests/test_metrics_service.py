"""``railval.app.services.metrics`` and the ``railval metrics`` verb on a small demo campaign."""

import json

import numpy as np
import pytest

from railval.app.cli import main
from railval.app.services.metrics import metrics_for_configuration, summary
from railval.core.errors import NotFound
from railval.core.metrics import compare, lowpass


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory):
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    folder = tmp_path_factory.mktemp("metrics-demo")
    manifest = write_demo_campaign(folder / "camp", n_sections=4, fmt="csv", n_configs=1)
    url = f"sqlite:///{folder / 'metrics.db'}"
    db = connect(url)
    db.init()
    import_campaign(db, manifest.parent)
    yield db, url
    db.dispose()


def test_service_rows_match_direct_comparison(demo_db):
    from railval.db import repo

    db, _ = demo_db
    chans = ["Y_w1L", "ay_cb_b1"]
    with db.write_session(deferred=True) as s:
        df = metrics_for_configuration(s, "demo", "baseline", ["S02"], chans,
                                       families=["sprague_geers", "area"])
        meas = repo.load_signalsets(s, "demo", None, ["S02"], chans)["S02"]
        sim = repo.load_signalsets(s, "demo", "baseline", ["S02"], chans)["S02"]
    assert list(df["channel"]) == chans and set(df["section"]) == {"S02"}
    assert list(df["unit"]) == ["kN", "m/s^2"]
    m = lowpass(meas.channels["Y_w1L"], meas.fs, 20.0)[0]
    c = lowpass(sim.channels["Y_w1L"], sim.fs, 20.0)[0]
    direct = compare(m, c, meas.fs, fs_simulated=sim.fs, t0_measured=meas.time_s[0],
                     t0_simulated=sim.time_s[0], families=["sprague_geers", "area"])
    row = df.iloc[0]
    for name in ("sg_M", "sg_P", "sg_C", "area"):
        assert row[name] == pytest.approx(direct.raw[name], rel=1e-12)
        assert row[f"{name}_sync"] == pytest.approx(direct.synced[name], rel=1e-12)
    assert row["lag_s"] == pytest.approx(direct.lag_s)
    stats = summary(df)
    assert stats["sg_C"]["n"] == 2
    assert stats["sg_C"]["median"] == pytest.approx(float(np.median(df["sg_C"])))


def test_service_evaluated_part_is_shorter(demo_db):
    db, _ = demo_db
    with db.write_session(deferred=True) as s:
        whole = metrics_for_configuration(s, "demo", "baseline", ["S01"], ["Q_w1L"], families=["area"])
        part = metrics_for_configuration(s, "demo", "baseline", ["S01"], ["Q_w1L"], families=["area"],
                                         part="evaluated")
    assert 16 <= part.loc[0, "n"] < whole.loc[0, "n"]


def test_service_unknown_section(demo_db):
    db, _ = demo_db
    with db.write_session(deferred=True) as s, pytest.raises(NotFound, match="S99"):
        metrics_for_configuration(s, "demo", "baseline", ["S99"])


def test_cli_metrics_json_and_table(demo_db, capsys):
    _, url = demo_db
    args = ["--db", url, "metrics", "demo", "--config", "baseline", "--section", "S01",
            "--channel", "Y_w1L", "--family", "sprague_geers", "--family", "iso18571"]
    assert main(args + ["--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["channel"] for r in doc["rows"]] == ["Y_w1L"]
    assert {m["name"] for m in doc["metrics"]} >= {"sg_C", "iso_rating"}
    assert doc["rows"][0]["iso_grade"] in ("excellent", "good", "fair", "poor")
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "S01" in out and "Y_w1L" in out and "SG C" in out


def test_cli_metrics_list_and_errors(demo_db, capsys):
    _, url = demo_db
    assert main(["metrics", "--list", "--json"]) == 0
    names = {m["name"] for m in json.loads(capsys.readouterr().out)["metrics"]}
    assert "iso_rating" in names and "ks_p_eff" in names
    assert main(["--db", url, "metrics", "demo", "--config", "nope"]) == 2
    assert "nope" in capsys.readouterr().err


def test_metrics_table_shows_whether_the_lag_is_reliable():
    import pandas as pd

    from railval.app.state.metrics import MetricsState

    df = pd.DataFrame({"section": ["S01", "S02"], "channel": ["az_bg_b1", "Y_w1L"],
                       "lag_s": [1.92, 0.01], "lag_reliable": [False, True],
                       "sg_M": [0.1, 0.2], "sg_M_sync": [0.05, 0.2]})
    for view in ("synchronised", "raw and synchronised"):
        out = MetricsState(None, frame=df, view=view).table()
        assert list(out.columns[:4]) == ["section", "channel", "lag_s", "lag_reliable"]
        assert out["lag_reliable"].tolist() == [False, True]
    assert "lag_reliable" not in MetricsState(None, frame=df, view="raw").table().columns
